"""The Design page (app.logic.studies) without a browser: the studies of the app's --studies
folder are listed, a chosen one draws its front and its designs, Open shows a design in the views
(its scene at its least favourable envelope point), and a page cannot name anything else."""

from __future__ import annotations

import pytest
from support.app_helpers import change, settle

import simcore
from app.engine import Engine
from app.main import LmapdApp, client_keys
from simcore import design

STUDY = {
    "name": "energy",
    "seed": 2,
    "trials": 4,
    "confirm": 1,
    "polish_steps": 2,
    "set": {"pixels": 16},
    "envelope": {"pose.distance_m": [400.0, 700.0]},
    "variables": {"laser.pulse_energy_j": {"low": 1e-4, "high": 1e-2, "log": True}},
    "requirements": {"n_target_points": ">= 40"},
    "objectives": {"minimize": ["laser.pulse_energy_j"]},
}


@pytest.fixture(scope="module")
def studies(tmp_path_factory):
    folder = tmp_path_factory.mktemp("studies")
    result = design.run(design.study_from_dict(STUDY), folder / "energy", workers=0, progress=False)
    (folder / "not-a-study").mkdir()
    return folder, result


@pytest.fixture(scope="module")
def app(studies):
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 16, "fidelity.subrays": 1})
    lmapd = LmapdApp(
        scene, engine=Engine(scene), flow_control=False, debounce_s=0.0, studies_dir=studies[0]
    )
    lmapd.state.ready()
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()


def test_the_studies_folder_lists_its_studies_only(app):
    assert app.state.design_studies == ["energy"]
    assert "design_study" in client_keys()


def test_a_refresh_lists_the_studies_written_since_the_app_was_built(app, studies):
    """A session forked from the app built at launch (app.server.zygote) lists the study
    folders again as it starts."""
    folder = studies[0] / "later"
    folder.mkdir()
    (folder / "study.toml").write_text((studies[0] / "energy" / "study.toml").read_text())
    try:
        assert app.state.design_studies == ["energy"]
        app.logic.studies.refresh()
        assert app.state.design_studies == ["energy", "later"]
    finally:
        (folder / "study.toml").unlink()
        folder.rmdir()
        app.logic.studies.refresh()
    assert app.state.design_studies == ["energy"]


def test_a_chosen_study_draws_its_front_and_designs_the_winner_first(app, studies):
    result = studies[1]
    change(app, design_study="energy")
    figure = app.state.design_front
    names = [trace["name"] for trace in figure["data"]]
    assert names[:3] == ["fails a requirement", "feasible", "front"]
    rows = app.state.design_rows
    assert rows and rows[0]["number"] == result.winner.of
    assert "screened" in app.state.design_message


def test_open_shows_the_design_at_its_least_favourable_point(app, studies):
    result = studies[1]
    change(app, design_study="energy")
    row = app.state.design_rows[0]
    app.server.controller.trigger_fn("open_design")(row["number"])
    settle(app)
    shown = app.logic.last_frame.result.scene
    rec = next(r for r in result.records if r.number == row["number"])
    want = result.study.scene(rec.params, row["point"], rec.preset)
    assert shown.laser.pulse_energy_j == pytest.approx(want.laser.pulse_energy_j)
    assert shown.pose.distance_m == want.pose.distance_m and shown.seed == want.seed
    # fewer points at its least favourable point than the requirement's bound plus its margin
    assert row["point"] == 1  # the farther distance gives fewer points
    assert app.state.design_message.startswith(f"Showing design {row['number']} of energy")


@pytest.mark.parametrize("name", ["../energy", "not-a-study", "/etc", 5, ["energy"]])
def test_a_page_cannot_name_a_folder_that_is_not_a_listed_study(app, name):
    change(app, wait_busy=False, design_study=name)
    assert app.state.design_front is None and app.state.design_rows == []
    assert app.state.design_message == "Choose a study from the list."
    app.server.controller.trigger_fn("open_design")(0)
    assert app.state.design_message == "Choose a design of the study drawn above."
