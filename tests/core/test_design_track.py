"""Design studies that require a pose track's figures (issue 40, item 5): the envelope's points
are the trajectory's frames, each track registered as ``simcore.tracking.track`` registers a
fly-around's clouds (the same numbers), a lost frame an infinite error, and a study with no
trajectory or too many frames refused in one line before any work."""

from __future__ import annotations

import math

import numpy as np
import pytest

import simcore
from simcore import design, io
from simcore.design.evaluate import PointOutcome
from simcore.design.search import Record, load_records
from simcore.flyaround import run_flyaround

# a short approach (3 frames, 400 m to 300 m) at 24 x 24 pixels: the whole MRO in view, about
# 200-280 points a frame, tracked within a few cm
APPROACH = {
    "trajectory.kind": "approach",
    "trajectory.start_range_m": 400.0,
    "trajectory.end_range_m": 300.0,
    "trajectory.duration_s": 2.0,
    "trajectory.frame_rate_hz": 1.0,
    "detector.pixels": 24,
}
ENERGY_J = 5e-3


def track_study(bound: str, **changes) -> dict:
    return {
        "name": "approach-track",
        "seed": 1,
        "trials": 1,
        "confirm": 0,
        "polish_steps": 0,
        "set": APPROACH,
        "envelope": {},
        "variables": {"laser.pulse_energy_j": {"choices": [ENERGY_J]}},
        "requirements": {"track.translation_error_m": bound},
        "objectives": {"minimize": ["laser.pulse_energy_j"]},
        **changes,
    }


@pytest.fixture(scope="module")
def direct():
    """The same frames by the direct API: the fly-around of the design's scene, tracked."""
    study = design.study_from_dict(track_study("<= 1.0 at median"))
    scene = simcore.with_overrides(
        study.base, {"preset": study.preset, **study.fixed, "laser.pulse_energy_j": ENERGY_J}
    )
    fly = run_flyaround(scene, progress=False, keep_clouds=True)
    return fly, fly.track()


@pytest.fixture(scope="module")
def generous(tmp_path_factory, direct):
    out = tmp_path_factory.mktemp("generous") / "out"
    study = design.study_from_dict(track_study("<= 1.0 at median"))
    return design.run(study, out, workers=0, progress=False), out


def test_the_envelope_of_a_study_that_tracks_is_the_trajectorys_frames():
    study = design.study_from_dict(track_study("<= 1.0", envelope={"seed": [1, 2]}))
    # 3 frames x 2 seeds: one track per seed, its frames in time order
    assert [t.points for t in study.tracks] == [(0, 1, 2), (3, 4, 5)]
    scene = simcore.with_overrides(study.base, study.fixed)
    fly_t = simcore.trajectory.frame_times(scene)
    for track in study.tracks:
        points = [study.envelope[p] for p in track.points]
        assert [p["orbit.time_s"] for p in points] == fly_t.tolist()
        assert [p["pose.distance_m"] for p in points] == [400.0, 350.0, 300.0]
    assert [study.envelope[p]["seed"] for p in (0, 2, 3, 5)] == [1, 1, 2, 2]


def test_a_generous_median_translation_bound_is_met_with_the_direct_apis_figures(generous, direct):
    result, out = generous
    fly, track = direct
    assert not track.lost.any()  # the frames this test reads are tracked, not lost
    screened = [r for r in result.records if r.stage == "screen"]
    assert len(screened) == 1 and result.winner is not None
    rec = screened[0]
    assert rec.error is None and rec.feasible
    # each envelope point's track figures are the direct API's for the same frame
    for k, figures in enumerate(rec.points):
        assert figures["track.translation_error_m"] == track.translation_error_m[k]
        assert figures["track.rotation_error_deg"] == track.rotation_error_deg[k]
        assert figures["track.fitness"] == track.fitness[k]
        assert figures["track.lost"] == 0.0 and figures["track.lost_fraction"] == 0.0
        assert figures["n_points"] == fly.records[k]["n_points"]
    assert rec.values == [float(np.median(track.translation_error_m))]
    report = (out / "report.md").read_text()
    assert "The binding requirement is **track.translation_error_m <= 1 at median**" in report
    assert "the 3 frames of 1 trajectory" in report


def test_a_tiny_median_translation_bound_is_infeasible_and_the_report_names_it(tmp_path, direct):
    _, track = direct
    best = float(np.median(track.translation_error_m))
    study = design.study_from_dict(track_study("<= 0.0001 at median"))
    result = design.run(study, tmp_path / "out", workers=0, progress=False)
    assert result.winner is None
    (rec,) = [r for r in result.records if r.stage == "screen"]
    assert rec.values == [best] and rec.margins == [pytest.approx(1e-4 - best)]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "**track.translation_error_m <= 0.0001 at median** fails" in report
    assert "**Binding requirement**: track.translation_error_m <= 0.0001 at median" in report


def test_a_lost_frame_counts_as_an_infinite_error(direct):
    fly, track = direct
    study = design.study_from_dict(track_study("<= 1.0 at median"))
    few = fly.clouds[2].points[: simcore.tracking.MIN_POINTS - 1]  # the last frame: too few
    clouds = [fly.clouds[0].points, fly.clouds[1].points, few]
    outcomes = {p: PointOutcome({}, None, points_m=c) for p, c in enumerate(clouds)}
    evaluator = design.evaluate.Evaluator(track=True)
    tracked = evaluator.track(study, {"laser.pulse_energy_j": ENERGY_J}, study.preset, outcomes)
    figures = [tracked[p].figures for p in range(3)]
    assert [f["track.lost"] for f in figures] == [0.0, 0.0, 1.0]
    assert all(f["track.lost_fraction"] == pytest.approx(1 / 3) for f in figures)
    assert figures[2]["track.translation_error_m"] == math.inf
    assert figures[2]["track.rotation_error_deg"] == math.inf
    # the frames before it are the direct API's (the lost one comes after them)
    assert figures[1]["track.translation_error_m"] == track.translation_error_m[1]
    assert all(tracked[p].points_m is None for p in range(3))  # the clouds are not kept
    at_median = study.requirements[0]
    values = [f["track.translation_error_m"] for f in figures]
    assert at_median.aggregate(values) == max(values[:2])  # met: 1 of 3 lost
    assert design.Requirement("track.translation_error_m", "<=", 1.0).aggregate(values) == math.inf


def test_infinite_errors_aggregate_as_infinite_not_undefined():
    at_median = design.Requirement("e", "<=", 1.0, "median")
    assert at_median.aggregate([0.1, math.inf, 0.2]) == 0.2
    assert at_median.aggregate([math.inf, math.inf, 0.1]) == math.inf
    assert at_median.aggregate([math.inf, 0.1]) == math.inf  # halfway to an infinity
    p50 = design.Requirement("e", "<=", 1.0, "p50")
    assert p50.aggregate([0.1, 0.3, math.inf, math.inf]) == math.inf
    assert p50.aggregate([0.1, 0.3, 0.5, math.inf]) == pytest.approx(0.4)  # numpy's, finite
    assert at_median.margin(math.inf) == -math.inf and at_median.violation(math.inf) == 1e12


def test_a_record_with_infinite_errors_reads_back_as_it_was_written(tmp_path):
    rec = Record(
        number=0, stage="screen", preset="interactive", params={"laser.pulse_energy_j": 1e-3},
        points=[{"track.translation_error_m": math.inf, "quality.recall": math.nan}],
        values=[math.inf], margins=[-math.inf], objectives=[1e-3], feasible=False,
    )  # fmt: skip
    (tmp_path / "records").mkdir()
    io.write_json(tmp_path / "records" / "screen_00000.json", rec.to_json())
    (back,) = load_records(tmp_path)  # not left out: a resumed study does not run it again
    assert back.values == [math.inf] and back.margins == [-math.inf]
    assert back.points[0]["track.translation_error_m"] == math.inf
    assert math.isnan(back.points[0]["quality.recall"])


BAD = [
    (
        {"set": {"detector.pixels": 24}},  # the orbit, and no times along it
        "a pose track needs a trajectory",
    ),
    (
        {"set": {**APPROACH, "trajectory.frame_rate_hz": 100.0}},  # 201 frames x 2 seeds
        "402 points (201 trajectory frames x 2 conditions), more than 256",
    ),
    ({"envelope": {"pose.distance_m": [300.0]}}, "the trajectory sets each frame's pose"),
    (
        {"variables": {"trajectory.tumble_rate_deg_s": {"low": 0.0, "high": 2.0}}},
        "takes its frames from the trajectory",
    ),
    ({"set": {**APPROACH, "trajectory.end_range_m": 3.0}}, "ends inside the target"),
]


@pytest.mark.parametrize(("change", "message"), BAD, ids=[m for _, m in BAD])
def test_a_study_that_cannot_track_is_refused_in_one_line_before_any_work(
    tmp_path, change, message
):
    spec = track_study("<= 1.0", **change)
    if "frame_rate_hz" in str(change):
        spec["envelope"] = {"seed": [1, 2]}
    with pytest.raises(design.StudyError, match=message.replace("(", r"\(").replace(")", r"\)")):
        design.run(design.study_from_dict(spec), tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out").exists()


def test_a_fly_around_of_the_orbits_is_a_trajectory_to_track():
    spec = track_study("<= 1.0", set={"detector.pixels": 24})
    spec["envelope"] = {"flyaround": {"times_s": [0.0, 300.0]}}
    study = design.study_from_dict(spec)
    assert [t.points for t in study.tracks] == [(0, 1)]
    fly = simcore.flyaround.pose_series(simcore.with_overrides(study.base, study.fixed), [0, 300])
    assert [study.envelope[p]["pose.distance_m"] for p in (0, 1)] == fly.distance_m.tolist()
