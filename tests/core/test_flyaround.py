"""The fly-around (docs/physics.md#flyaround): frames follow the orbits, outputs and CLI contract.

A short fly-around (3 frames, 32 x 32 pixels, 1 sub-ray) keeps the file fast; the frames are far
apart in time (1500 s, a quarter orbit) so that distance and attitude differ between them.
"""

from __future__ import annotations

import argparse
import json
import struct

import numpy as np
import pytest
from plyfile import PlyData

import simcore
from simcore import io, orbit
from simcore.cli import CliError
from simcore.cli.flyaround import (
    JSON_NAME,
    PNG_NAME,
    POSES_NAME,
    add_parser,
    plot_flyaround,
    run_cli,
)
from simcore.flyaround import frame_filename, run_flyaround

FAST = {"pixels": 32, "fidelity.subrays": 1}
TIMES_S = np.array([0.0, 1500.0, 3000.0])
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FRAME_KEYS = {
    "t_s",
    "distance_m",
    "quaternion_wxyz",
    "angles_deg",
    "n_points",
    "n_outliers",
    "n_dropped",
    "n_hit_pixels",
    "snr_median",
    "range_sigma_m_median",
    "frame_s",
}
# A Gaussian range error beyond 6 sigma has probability 2e-9: over the ~1000 points of a 32 x 32
# frame, 2e-6 to see one at all (and the draws are seeded).
NOISE_SIGMAS = 6.0


@pytest.fixture(scope="module")
def fast_scene():
    return simcore.with_overrides(simcore.load_scene(), FAST)


@pytest.fixture(scope="module")
def pipeline():
    return simcore.Pipeline()


@pytest.fixture(scope="module")
def flown(fast_scene, pipeline, tmp_path_factory):
    out = tmp_path_factory.mktemp("fly") / "frames"  # not there yet: run_flyaround creates it
    result = run_flyaround(fast_scene, TIMES_S, out_dir=out, progress=False, pipeline=pipeline)
    return result, out


def parse_cli(argv: list[str]) -> argparse.Namespace:
    """Parse ``argv`` with a parser that has only the flyaround subcommand (as cli.py will)."""
    parser = argparse.ArgumentParser(prog="lmapd")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(argv)


# ----------------------------------------------------------------------------------------------
# run_flyaround
# ----------------------------------------------------------------------------------------------
def test_each_frame_is_imaged_at_the_orbits_distance_and_attitude(flown):
    result, _ = flown
    pose = orbit.relative_pose_series(orbit.PAPER_TARGET, orbit.PAPER_IMAGING, TIMES_S)
    records = result.records
    assert [r["t_s"] for r in records] == TIMES_S.tolist()
    np.testing.assert_array_equal([r["distance_m"] for r in records], pose.distance_m)
    np.testing.assert_array_equal([r["quaternion_wxyz"] for r in records], pose.quaternion_wxyz)
    np.testing.assert_array_equal([r["angles_deg"] for r in records], pose.angles_deg)
    assert all(FRAME_KEYS <= set(r) for r in records)


def test_the_target_is_seen_in_every_frame_and_the_poses_differ(flown):
    result, _ = flown
    assert all(r["n_hit_pixels"] > 0 and r["n_points"] > r["n_outliers"] for r in result.records)
    # a quarter orbit apart the target shows another side: the hit pixels are not all the same
    assert len({r["n_hit_pixels"] for r in result.records}) == len(TIMES_S)


def test_a_frame_is_the_same_flash_as_simulate_with_its_recorded_pose(flown, fast_scene, pipeline):
    result, out = flown
    for i, rec in enumerate(result.records):
        scene = simcore.with_overrides(
            fast_scene,
            {"pose.quaternion_wxyz": rec["quaternion_wxyz"], "distance_m": rec["distance_m"]},
        )
        flash = pipeline.run(scene)
        cloud = io.read_ply(out / frame_filename(i, rec["t_s"]))
        assert len(cloud) == rec["n_points"] == len(flash.cloud)
        np.testing.assert_array_equal(cloud.points, flash.points)

        # target points lie within the target's bounding sphere about its origin, which sits on
        # the boresight at distance_m; with 1 sub-ray a pixel's true range is its hit's range,
        # so only the range noise (sigma of Eq. 24, per pixel) can take a point outside
        target = ~cloud.attributes["is_outlier"]
        det = flash.detection
        sigma_max_m = float(det.range_sigma_m[det.detected].max())
        bound_m = flash.target.radius_m + NOISE_SIGMAS * sigma_max_m
        offset_m = np.abs(cloud.attributes["range_m"][target] - rec["distance_m"])
        assert offset_m.max() <= bound_m


def test_ply_comments_name_the_scene_the_time_and_the_model_credit(flown):
    result, out = flown
    rec = result.records[1]
    comments = " | ".join(PlyData.read(str(out / rec["ply"])).comments)
    assert f"scene {result.scene.name}" in comments
    assert f"t_s {rec['t_s']:.3f}" in comments
    assert result.target_credit and result.target_credit in comments


def test_json_record_has_the_settings_the_frames_and_the_distance_figures(flown, tmp_path):
    result, _ = flown
    io.write_json(tmp_path / "f.json", result.to_json())
    data = json.loads((tmp_path / "f.json").read_text())
    assert {"scene", "j2", "interval_s", "frames", "distance_stats"} <= set(data)
    assert data["j2"] is False and data["interval_s"] == 1500.0
    assert data["scene"]["detector"]["pixels"] == 32
    assert len(data["frames"]) == len(TIMES_S)
    assert all(FRAME_KEYS <= set(f) for f in data["frames"])
    stats = orbit.distance_stats(orbit.PAPER_TARGET, orbit.PAPER_IMAGING)
    assert data["distance_stats"] == pytest.approx(stats, rel=1e-12)
    # frames sample the orbit, so their distances lie inside its min/max
    d = [f["distance_m"] for f in data["frames"]]
    assert stats["min_m"] <= min(d) and max(d) <= stats["max_m"]


def test_plot_is_a_png_of_a_real_figure(flown, tmp_path):
    result, _ = flown
    path = tmp_path / "fig.png"
    plot_flyaround(result, path)
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    width, height = struct.unpack(">II", data[16:24])  # IHDR
    assert width >= 600 and height >= 600
    assert len(data) > 20_000  # three panels of curves and text; a blank canvas is ~5 KB
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]  # no temporary file left


def test_a_failed_frame_leaves_no_file_and_the_earlier_frames_whole(fast_scene, pipeline, tmp_path):
    class FailsOnSecondFrame:
        calls = 0

        def run(self, scene):
            self.calls += 1
            if self.calls == 2:
                raise RuntimeError("disk on fire")
            return pipeline.run(scene)

    with pytest.raises(RuntimeError, match="disk on fire"):
        run_flyaround(
            fast_scene, TIMES_S, out_dir=tmp_path, progress=False, pipeline=FailsOnSecondFrame()
        )
    assert sorted(p.name for p in tmp_path.iterdir()) == [frame_filename(0, 0.0)]
    assert len(io.read_ply(tmp_path / frame_filename(0, 0.0))) > 0


def test_empty_times_are_an_orbit_error(fast_scene):
    with pytest.raises(orbit.OrbitError, match="t_s is empty"):
        run_flyaround(fast_scene, [], progress=False)


# ----------------------------------------------------------------------------------------------
# lmapd flyaround
# ----------------------------------------------------------------------------------------------
def test_cli_writes_a_ply_per_frame_the_json_and_the_png(tmp_path, capsys):
    out = tmp_path / "new" / "run"
    argv = ["flyaround", "--out", str(out), "--j2", "--duration-s", "600"]
    argv += ["--set", "pixels=32", "--set", "fidelity.subrays=1"]
    assert run_cli(parse_cli(argv)) == 0
    times = [0.0, 300.0, 600.0]  # default --interval-s 300, end point included
    names = {frame_filename(i, t) for i, t in enumerate(times)} | {JSON_NAME, PNG_NAME, POSES_NAME}
    assert {p.name for p in out.iterdir()} == names
    data = json.loads((out / JSON_NAME).read_text())
    assert data["j2"] is True and data["interval_s"] == 300.0
    pose = orbit.relative_pose_series(orbit.PAPER_TARGET, orbit.PAPER_IMAGING, times, j2=True)
    np.testing.assert_array_equal([f["distance_m"] for f in data["frames"]], pose.distance_m)
    assert (out / PNG_NAME).read_bytes()[:8] == PNG_MAGIC
    line = capsys.readouterr().out.strip()
    assert line.startswith("3 frames") and "points" in line and "\n" not in line


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--duration-s", "0"], "--duration-s must be a finite number of seconds > 0"),
        (["--duration-s", "nan"], "--duration-s"),
        (["--interval-s", "-300"], "--interval-s must be a finite number of seconds > 0"),
        (["--interval-s", "1e-6"], "frames .at most"),
        (["--duration-s", "1e308", "--interval-s", "1e-308"], "frames .at most"),
        (["--set", "distance_m=300"], "--set distance_m: the fly-around takes the pose"),
        (["--set", "pose.pitch_deg=10"], "--set pose.pitch_deg"),
    ],
)
def test_cli_rejects_bad_input_before_writing_anything(tmp_path, argv, message):
    out = tmp_path / "out"
    with pytest.raises(CliError, match=message):
        run_cli(parse_cli(["flyaround", "--out", str(out), *argv]))
    assert not out.exists()


def test_cli_bad_scene_key_is_a_scene_error_and_writes_nothing(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(simcore.SceneError, match="pixels"):
        run_cli(parse_cli(["flyaround", "--out", str(out), "--set", "pixels=-1"]))
    assert not out.exists()


def test_cli_out_that_cannot_be_created_is_a_clear_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(CliError, match="--out .*a_file"):
        run_cli(parse_cli(["flyaround", "--out", str(blocker)]))
    with pytest.raises(CliError, match="cannot create the folder"):
        run_cli(parse_cli(["flyaround", "--out", str(blocker / "sub")]))


def test_cli_removes_the_folder_it_created_when_the_target_fails(tmp_path):
    out = tmp_path / "made" / "here"
    argv = ["flyaround", "--out", str(out), "--set", f"target.mesh={tmp_path / 'missing.obj'}"]
    with pytest.raises((simcore.TargetError, FileNotFoundError)):
        run_cli(parse_cli(argv))
    assert list(tmp_path.iterdir()) == []
