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


def _copy_study(source, target) -> None:
    import shutil

    shutil.copytree(source, target)


def test_a_study_folder_or_file_linking_outside_the_studies_folder_is_not_listed(
    app, studies, tmp_path
):
    outside = tmp_path / "outside"
    _copy_study(studies[0] / "energy", outside)
    linked = studies[0] / "linked"
    linked.symlink_to(outside, target_is_directory=True)  # the whole folder elsewhere
    leaky = studies[0] / "leaky"
    _copy_study(studies[0] / "energy", leaky)
    record = next((leaky / "records").iterdir())
    record.unlink()
    record.symlink_to(tmp_path / "secret.json")  # one file elsewhere
    (tmp_path / "secret.json").write_text("{}")
    try:
        app.logic.studies.refresh()
        assert app.state.design_studies == ["energy"]
        change(app, design_study="linked")
        assert app.state.design_message == "Choose a study from the list."
    finally:
        import shutil

        linked.unlink()
        shutil.rmtree(leaky)
        app.logic.studies.refresh()


def test_malformed_records_are_left_out_and_each_named_in_one_line(app, studies, caplog):
    import json

    folder = studies[0] / "damaged"
    _copy_study(studies[0] / "energy", folder)
    records = folder / "records"
    good = json.loads(next(iter(sorted(records.iterdir()))).read_text())
    (records / "a_list.json").write_text("[1, 2]")
    (records / "b_strings.json").write_text(json.dumps({**good, "margins": "big", "number": "7"}))
    (records / "c_counts.json").write_text(json.dumps({**good, "objectives": [1.0, 2.0]}))
    (records / "d_cut.json").write_text(json.dumps(good)[:40])
    try:
        app.logic.studies.refresh()
        change(app, design_study="damaged")
        message = app.state.design_message
        assert "\n" not in message and "Left out 4 malformed records: " in message
        assert "a_list.json: not an object but list" in message
        assert "b_strings.json: number, margins of the wrong kind" in message
        assert "2 costs" in message and "d_cut.json: not JSON" in message
        assert app.state.design_rows  # the good records are drawn
        assert not [r for r in caplog.records if r.exc_info]
    finally:
        import shutil

        shutil.rmtree(folder)
        app.logic.studies.refresh()
