"""Design studies (simcore.design): validated against closed forms first (the least pulse energy
that detects every pixel of a plate with P_d 0.99, Eqs. 27 and 30 inverted; the least aperture
falling as the inverse square root of the energy), then the machinery: a seeded search repeats,
an interrupted study resumes without losing a design, bad study files are refused before any
trial, and the outputs are written."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import optimize, special

import simcore
from simcore import design, echo
from simcore.design.search import RECORDS_DIR
from simcore.receivers.lm_apd.apd import receiver_model
from simcore.scene import Scene, load_scene, with_overrides

DISTANCE_M = 1000.0
FOV_RAD = 0.01
PLATE = {  # a Lambertian plate filling the field of view, every pixel lit alike (a square beam)
    "target.mesh": "plate",
    "target.size_m": 20.0,
    "detector.pixels": 8,
    "receive.fov_rad": FOV_RAD,
    "transmit.illumination": "square",
    "laser.divergence_rad": 1.001 * FOV_RAD,
    "transmit.beam_expansion_ratio": 1.0,
    "timing.range_gate_m": 10.0,  # noise stops before the echo: 2e-5 of them
    "paper_forms": ["unfiltered_peak"],  # the SNR of Eq. 14's unfiltered peak: Eq. 30's
}


def plate_study(variables, set_=None, trials=12, polish_steps=12, minimize=None) -> dict:
    return {
        "name": "plate",
        "seed": 3,
        "trials": trials,
        "confirm": 0,
        "polish_steps": polish_steps,
        "set": {**PLATE, **(set_ or {})},
        "envelope": {"pose.distance_m": [DISTANCE_M]},
        "variables": variables,
        "requirements": {"p_detect_min": ">= 0.99"},
        "objectives": {"minimize": minimize or list(variables)},
    }


def least_energy_j(aperture_m: float) -> float:
    """The pulse energy at which the plate's weakest pixel (a corner: the longest range, the
    most oblique) is detected with P_d = 0.99, from Eq. 30 (the lidar equation of a resolved
    Lambertian plate under a square beam) and Eq. 27 (ours: the peak's shot noise in sigma_pk)."""
    scene = with_overrides(Scene(), {**PLATE, "receive.aperture_diameter_m": aperture_m})
    rx = receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    n = scene.detector.pixels
    pitch = 2 * math.tan(FOV_RAD / 2) / n
    corner = (n - 1) / 2 * pitch  # the corner pixel's centre, both tangents
    cos_a = 1 / math.sqrt(1 + 2 * corner**2)
    range_m = DISTANCE_M / cos_a
    theta = scene.illumination_angle_rad
    p_max_per_j = echo.A_FWHM / (math.e * scene.laser.pulse_width_s)  # Eq. 1's peak, per joule
    irradiance = scene.transmit.transmittance * p_max_per_j / (theta**2 * range_m**2)  # square
    area_r = math.pi * aperture_m**2 / 4
    footprint = (range_m * scene.ifov_rad) ** 2
    peak_per_j = (
        irradiance
        * (1 / math.pi)
        * cos_a
        * footprint
        * (scene.receive.transmittance * area_r / range_m**2)
    )
    v_t = scene.timing.tnr * rx.sigma_n_a

    def shortfall(i_a):
        return 0.5 * special.erfc(-(i_a - v_t) / (math.sqrt(2) * rx.sigma_peak_a(i_a))) - 0.99

    i_a = optimize.brentq(shortfall, v_t, 100 * v_t, xtol=1e-15, rtol=1e-12)
    return i_a / (rx.responsivity_a_w * peak_per_j)


def test_the_least_energy_for_pd_099_on_every_plate_pixel_inverts_eqs_27_and_30(tmp_path):
    study = design.study_from_dict(
        plate_study({"laser.pulse_energy_j": {"low": 1e-10, "high": 1e-4, "log": True}})
    )
    result = design.run(study, tmp_path / "out", workers=0, progress=False)
    assert result.winner is not None
    want = least_energy_j(0.5)
    assert result.winner.params["laser.pulse_energy_j"] == pytest.approx(want, rel=0.05)


def test_the_least_aperture_falls_as_the_inverse_square_root_of_the_energy(tmp_path):
    e0 = least_energy_j(0.5)
    energies = e0 * np.array([1.0, 10**0.5, 10.0])  # a decade
    apertures = []
    for k, energy in enumerate(energies):
        spec = plate_study(
            {"receive.aperture_diameter_m": {"low": 0.05, "high": 1.0, "log": True}},
            set_={"laser.pulse_energy_j": float(energy)},
        )
        result = design.run(
            design.study_from_dict(spec), tmp_path / f"a{k}", workers=0, progress=False
        )
        apertures.append(result.winner.params["receive.aperture_diameter_m"])
    slope = np.polyfit(np.log(energies), np.log(apertures), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.05)


def test_a_two_objective_front_lies_on_the_closed_form_energy_aperture_curve(tmp_path):
    """Energy and aperture both minimised: the plate's least energy at aperture D is
    least_energy_j(D) (Eqs. 27 and 30; it falls as 1 / D^2), so every front design must sit on
    that curve, not above it (a screened design lies up to 40 times above it here): each is
    bisected onto it (12 steps over six decades of energy: 0.34 %; over one of aperture: 0.06 %,
    0.11 % in energy), within 2 %: that, and the 0.2-1.3 % between the simulated corner pixel's
    P_d and Eq. 27's closed form seen for the one-objective least energy."""
    spec = plate_study(
        {
            "laser.pulse_energy_j": {"low": 1e-10, "high": 1e-4, "log": True},
            "receive.aperture_diameter_m": {"low": 0.1, "high": 1.0, "log": True},
        },
        trials=60,  # NSGA-II's front of 30 trials here is one design; of 60, four
    )
    result = design.run(design.study_from_dict(spec), tmp_path / "out", workers=0, progress=False)
    front = result.front
    assert len(front) >= 3  # a front, not one point
    apertures = [r.params["receive.aperture_diameter_m"] for r in front]
    assert max(apertures) / min(apertures) > 1.5  # spread along it
    for r in front:
        energy = r.params["laser.pulse_energy_j"]
        aperture = r.params["receive.aperture_diameter_m"]
        assert r.stage == "polish"
        assert energy == pytest.approx(least_energy_j(aperture), rel=0.02), (energy, aperture)


SMALL = {
    "name": "small",
    "seed": 5,
    "trials": 6,
    "confirm": 1,
    "polish_steps": 2,
    "set": {"detector.pixels": 16},
    "envelope": {"pose.distance_m": [400.0, 600.0], "pose.pitch_deg": [0.0]},
    "variables": {
        "laser.pulse_energy_j": {"low": 1e-4, "high": 1e-2, "log": True},
        "timing.tnr": {"low": 4.5, "high": 5.5},  # three gross-error tables (TNR 4.5, 5, 5.5)
    },
    "requirements": {
        "quality.precision": ">= 0.3",  # 16 x 16 pixels: wide footprints, mixed pixels
        "n_target_points": ">= 30",
        "n_outliers": "<= 20 at p50",
    },
    "objectives": {"minimize": ["laser.pulse_energy_j"]},
}


def screened(result) -> list[dict]:
    return [r.params for r in result.records if r.stage == "screen"]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """SMALL run once, uninterrupted, into its folder (several tests read it)."""
    out = tmp_path_factory.mktemp("small") / "out"
    return design.run(design.study_from_dict(SMALL), out, workers=0, progress=False), out


def test_the_same_study_and_seed_screen_the_same_designs(tmp_path, small):
    a = small[0]
    b = design.run(design.study_from_dict(SMALL), tmp_path / "b", workers=0, progress=False)
    assert screened(a) == screened(b) and len(screened(a)) == 6
    other = design.run(
        design.study_from_dict({**SMALL, "seed": 6}), tmp_path / "c", workers=0, progress=False
    )
    assert screened(other) != screened(a)


def test_an_interrupted_study_keeps_every_finished_design_and_resumes(tmp_path, monkeypatch, small):
    study = design.study_from_dict(SMALL)
    out = tmp_path / "out"
    calls = {"n": 0}
    real = design.evaluate.run_point

    def dies_on_the_ninth(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 9:  # the fifth design's first point: four designs finished
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(design.evaluate, "run_point", dies_on_the_ninth)
    with pytest.raises(KeyboardInterrupt):
        design.run(study, out, workers=0, progress=False)
    monkeypatch.undo()
    kept = sorted((out / RECORDS_DIR).glob("screen_*.json"))
    assert len(kept) == 4
    first = [json.loads(p.read_text())["params"] for p in kept]
    with pytest.raises(design.StudyError, match="--resume"):
        design.run(study, out, workers=0, progress=False)  # nothing is overwritten
    resumed = design.run(study, out, workers=0, progress=False, resume=True)
    assert screened(resumed)[:4] == first and len(screened(resumed)) == 6
    # the same designs as a study never interrupted
    assert screened(resumed) == screened(small[0])
    assert resumed.n_reused == 0 and resumed.n_run == 6 - 4 + len(resumed.records) - 6
    changed = design.study_from_dict({**SMALL, "seed": 99})
    with pytest.raises(design.StudyError, match="another study"):
        design.run(changed, out, workers=0, progress=False, resume=True)


def test_a_study_writes_its_table_front_best_scene_figures_and_report(small):
    result, out = small
    table = pq.read_table(out / "trials.parquet")
    assert table.num_rows == sum(len(r.points) for r in result.records)
    assert {"quality.precision", "n_outliers", "var.timing.tnr", "env.pose.distance_m"} <= set(
        table.column_names
    )
    for name in ("front.csv", "front.png", "margins.png", "effects.png", "report.md"):
        assert (out / name).stat().st_size > 0, name
    assert result.winner is not None and result.winner.stage == "confirm"
    best = load_scene(out / "best.toml")
    assert best.laser.pulse_energy_j == result.winner.params["laser.pulse_energy_j"]
    assert best.preset == "reference" and best.detector.pixels == 16
    assert len(list((out / "best").glob("point_*.toml"))) == 2
    report = (out / "report.md").read_text()
    assert "The binding requirement is" in report and "stages reused" in report
    # a design that changes only the TNR and energy re-runs neither the ray cast nor the echoes
    assert result.tally.reused["hits"] > 0 and result.tally.reused["echo"] > 0
    # the envelope points' pipelines share one target (mesh and BVH): loaded once
    assert result.tally.computed["target"] == 1


def test_a_study_no_design_can_meet_says_which_requirement_fails_and_by_how_much(tmp_path):
    spec = {**SMALL, "requirements": {"n_target_points": ">= 100000"}, "trials": 3}
    result = design.run(design.study_from_dict(spec), tmp_path / "out", workers=0, progress=False)
    assert result.winner is None
    report = (tmp_path / "out" / "report.md").read_text()
    assert "No design meets every requirement" in report
    assert "**n_target_points >= 100000** fails" in report and "short" in report


BAD = [
    ({"colour": 1}, "unknown study key 'colour'"),
    ({"variables": {"laser.pulse_energy": {"low": 1e-3, "high": 1e-2}}}, "not a scene key"),
    (
        {"variables": {"laser.pulse_energy_j": {"low": 1e-3, "high": 200.0}}},
        "leave the key's range",
    ),
    ({"variables": {"laser.pulse_energy_j": {"low": 1e-2, "high": 1e-3}}}, "must be below"),
    ({"envelope": {}}, "envelope] is empty"),
    ({"envelope": {"pose.distance_m": []}}, "empty list"),
    ({"requirements": {"quality.recall": ">= 1.5"}}, "no design can meet it"),
    ({"requirements": {"quality.recall": "at least 0.8"}}, "write"),
    ({"objectives": {"minimize": ["laser.colour"]}}, "neither a numeric scene key"),
    ({"variables": {}}, "at least one key"),
]


@pytest.mark.parametrize(("change", "message"), BAD, ids=[m for _, m in BAD])
def test_a_bad_study_is_refused_with_one_message_before_any_trial(tmp_path, change, message):
    with pytest.raises(design.StudyError, match=message.replace("[", r"\[").replace("]", r"\]")):
        study = design.study_from_dict({**SMALL, **change})
        design.run(study, tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out").exists()


def test_an_unknown_figure_is_refused_with_the_nearest_names(tmp_path):
    study = design.study_from_dict({**SMALL, "requirements": {"quality.recal": ">= 0.5"}})
    with pytest.raises(design.StudyError, match="did you mean quality.recall"):
        design.run(study, tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out").exists()


def test_the_worked_example_study_is_valid():
    study = design.load_study(simcore.scene.SCENES_DIR.parent / "studies" / "mro_approach.toml")
    assert len(study.envelope) == 8 and study.trials == 200
    design.evaluate.check_figures(study)


def test_requirements_aggregate_over_the_envelope_as_they_say():
    at_least = design.Requirement("f", ">=", 0.5)
    assert at_least.aggregate([0.9, 0.4, 0.7]) == 0.4  # the worst point
    assert design.Requirement("f", ">=", 0.5, "p50").aggregate([0.9, 0.4, 0.7]) == 0.7
    at_most = design.Requirement("g", "<=", 3.0, "p90")
    assert at_most.aggregate(np.arange(11.0)) == pytest.approx(9.0)
    assert math.isnan(at_least.aggregate([0.9, math.nan])) and at_least.margin(math.nan) < 0


def test_a_study_runs_on_dask_workers_each_envelope_point_on_its_own_worker(tmp_path):
    spec = {**SMALL, "trials": 2, "confirm": 0, "polish_steps": 0}
    result = design.run(design.study_from_dict(spec), tmp_path / "out", workers=2, progress=False)
    screens = [r for r in result.records if r.stage == "screen"]
    assert len(screens) == 2 and all(len(r.points) == 2 for r in screens)
    assert all(r.error is None for r in screens)
    # each point's worker keeps its pipeline: the later designs reuse its ray cast
    assert result.tally.reused["hits"] >= 2 * (2 - 1)


def test_a_fly_around_envelope_holds_the_poses_lmapd_flyaround_images():
    from simcore.flyaround import run_flyaround

    spec = {
        **SMALL,
        "envelope": {"flyaround": {"times_s": [0.0, 300.0, 600.0]}, "seed": [1, 2]},
    }
    study = design.study_from_dict(spec)
    assert len(study.envelope) == 6  # 3 frames x 2 seeds
    small = simcore.with_overrides(simcore.Scene(), {"pixels": 16})
    fly = run_flyaround(small, [0.0, 300.0, 600.0], progress=False)
    for record, point in zip(fly.records, study.envelope[::2], strict=True):
        assert point["pose.distance_m"] == record["distance_m"]
        assert point["pose.quaternion_wxyz"] == record["quaternion_wxyz"]
        assert point["orbit.time_s"] == record["t_s"]
    with pytest.raises(design.StudyError, match="envelope.flyaround"):
        design.study_from_dict({**SMALL, "envelope": {"flyaround": {"every_s": 300}}})


# ----------------------------------------------------------------------------------------------
# issue 43, item 5: design reports that say why
# ----------------------------------------------------------------------------------------------
def _record_at(study, values, number=3):
    """A feasible record whose first requirement takes ``values`` at the envelope points."""
    from simcore.design.search import Record

    req = study.requirements[0]
    value = req.aggregate(values)
    return Record(
        number=number, stage="screen", preset=study.preset, params={"laser.pulse_energy_j": 1e-3},
        points=[{req.figure: v} for v in values], values=[value], margins=[req.margin(value)],
        objectives=[1e-3], feasible=req.margin(value) >= 0,
    )  # fmt: skip


def test_best_toml_is_written_at_the_envelope_point_that_decides_a_median_requirement(tmp_path):
    spec = {
        **SMALL,
        "envelope": {"pose.pitch_deg": [0.0, 10.0, 20.0]},
        "requirements": {"quality.recall": ">= 0.5 at median"},
    }
    study = design.study_from_dict(spec)
    rec = _record_at(study, [0.41, 0.6, 0.9])  # met at median (0.6), failed at pitch 0
    design.report.write_best(study, rec, tmp_path)
    head = (tmp_path / "best.toml").read_text().splitlines()[0]
    assert "envelope point 1" in head and "quality.recall >= 0.5 at median binds" in head
    assert load_scene(tmp_path / "best.toml").pose.pitch_deg == 10.0


def test_a_worst_point_requirement_still_binds_where_it_is_met_least(tmp_path):
    spec = {**SMALL, "envelope": {"pose.pitch_deg": [0.0, 10.0, 20.0]},
            "requirements": {"quality.recall": ">= 0.3"}}  # fmt: skip
    study = design.study_from_dict(spec)
    assert design.report.binding_point(study, _record_at(study, [0.6, 0.41, 0.9]), 0) == 1


def test_a_fresh_study_folder_takes_nothing_from_it_and_the_report_numbers_match_front_csv(small):
    result, out = small
    assert "taken from" not in result.describe()
    report = (out / "report.md").read_text()
    rows = (out / "front.csv").read_text().splitlines()
    number = design.report.design_number(result.winner)
    assert f"Design {number} (record {number} of `front.csv`" in report
    assert any(row.split(",")[0] == str(number) for row in rows[1:])


def test_a_cost_spread_over_decades_or_a_log_variable_is_drawn_on_a_log_axis():
    study = design.study_from_dict(SMALL)
    assert design.report._log_axis(study, [2e-4, 3e-4], "laser.pulse_energy_j")  # a log variable
    assert design.report._log_axis(study, [1.0, 50.0], "frame_s")
    assert not design.report._log_axis(study, [1.0, 5.0], "frame_s")
    assert not design.report._log_axis(study, [0.0, 5.0], "frame_s")


def test_an_infeasible_study_names_its_binding_requirement_best_value_and_cause(tmp_path):
    spec = {**SMALL, "requirements": {"n_target_points": ">= 100000"}, "trials": 3}
    design.run(design.study_from_dict(spec), tmp_path / "out", workers=0, progress=False)
    report = (tmp_path / "out" / "report.md").read_text()
    # 16 x 16 pixels hold at most 256 target points whatever the energy: a cap of the scene
    assert (
        "**Binding requirement**: n_target_points >= 100000; the best any design reached" in report
    )
    assert "**Cause**: it hardly moves with the design variables" in report
