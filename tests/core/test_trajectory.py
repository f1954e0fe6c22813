"""Trajectories (docs/trajectories.md): closed forms of the tumble and the approach, the poses'
quaternions, the ground truth's transform chain, the tables written and the bad input refused.

The pose series are computed without imaging; one hold of 2 frames at 24 x 24 pixels checks the
chain against the imaged points."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

import simcore
from simcore import orbit, trajectory
from simcore.cli import main
from simcore.cli.flyaround import JSON_NAME, POSES_NAME
from simcore.flyaround import pose_series, run_flyaround
from simcore.scene import SceneError

AXIS = np.array([1.0, -2.0, 2.0]) / 3.0  # a unit axis off every body axis
RATE_DEG_S = 7.5
HOLD = {
    "trajectory.kind": "hold",
    "trajectory.start_range_m": 60.0,
    "trajectory.duration_s": 4.0,
    "trajectory.frame_rate_hz": 0.5,
    "trajectory.tumble_rate_deg_s": RATE_DEG_S,
    "trajectory.tumble_axis": (AXIS * 6.0).tolist(),  # any length: normalised
}


def scene(**keys):
    return simcore.with_overrides(
        simcore.Scene(), {k.replace("__", "."): v for k, v in keys.items()}
    )


def rodrigues(axis, angle_rad: float) -> np.ndarray:
    """The rotation by ``angle_rad`` about the unit ``axis``: I + sin K + (1 - cos) K^2."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1.0 - math.cos(angle_rad)) * k @ k


def quaternion_matrix(q) -> np.ndarray:
    """The rotation of the Hamilton unit quaternion (w, x, y, z), written out."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


# ----------------------------------------------------------------------------------------------
# closed forms
# ----------------------------------------------------------------------------------------------
def test_a_tumbling_targets_attitude_after_t_seconds_is_the_axis_angle_rotation_of_rate_times_t():
    s = simcore.with_overrides(simcore.Scene(), HOLD)
    t = np.array([0.0, 0.7, 3.0, 47.0])
    pose = pose_series(s, t)
    for i, ti in enumerate(t):
        expected = rodrigues(AXIS, math.radians(RATE_DEG_S * ti))
        np.testing.assert_allclose(pose.rotation[i], expected, atol=1e-12)
        np.testing.assert_allclose(quaternion_matrix(pose.quaternion_wxyz[i]), expected, atol=1e-12)
    np.testing.assert_array_equal(pose.distance_m, 60.0)


def test_a_tumble_on_the_orbit_turns_the_target_about_its_own_axis_after_its_initial_attitude():
    q0 = np.array([0.8, 0.2, -0.4, 0.4]) / np.linalg.norm([0.8, 0.2, -0.4, 0.4])
    s = simcore.with_overrides(
        simcore.Scene(),
        {
            "trajectory.initial_quaternion_wxyz": q0.tolist(),
            "trajectory.tumble_rate_deg_s": -3.0,
            "trajectory.tumble_axis": [0.0, 1.0, 0.0],
        },
    )
    t = np.array([0.0, 300.0, 1234.5])
    base = orbit.relative_pose_series(orbit.PAPER_TARGET, orbit.PAPER_IMAGING, t)
    pose = pose_series(s, t)
    for i, ti in enumerate(t):
        spin = rodrigues((0.0, 1.0, 0.0), math.radians(-3.0 * ti))
        expected = base.rotation[i] @ quaternion_matrix(q0) @ spin
        np.testing.assert_allclose(pose.rotation[i], expected, atol=1e-12)
    np.testing.assert_array_equal(pose.distance_m, base.distance_m)  # the orbit's ranges


def test_the_orbit_without_a_tumble_is_the_orbits_own_pose_series_bit_for_bit():
    t = np.array([0.0, 1500.0])
    base = orbit.relative_pose_series(orbit.PAPER_TARGET, orbit.PAPER_IMAGING, t)
    pose = pose_series(simcore.Scene(), t)
    np.testing.assert_array_equal(pose.quaternion_wxyz, base.quaternion_wxyz)


def test_an_approachs_frames_and_ranges_are_those_of_the_line():
    s = scene(
        trajectory__kind="approach",
        trajectory__start_range_m=2000.0,
        trajectory__end_range_m=20.0,
        trajectory__duration_s=99.0,
        trajectory__frame_rate_hz=0.25,
    )
    t = trajectory.frame_times(s)
    np.testing.assert_array_equal(t, 4.0 * np.arange(25))  # 0, 4, ..., 96 <= 99 s
    pose = pose_series(s, t)
    np.testing.assert_allclose(pose.distance_m, 2000.0 - 1980.0 * t / 99.0, rtol=1e-15)
    np.testing.assert_array_equal(pose.rotation, np.broadcast_to(np.eye(3), (25, 3, 3)))
    np.testing.assert_allclose(pose.relative_position_lvlh_m[:, 2], -pose.distance_m)
    # a duration that is a whole number of frames ends on the end range
    whole = scene(trajectory__kind="approach", trajectory__duration_s=60.0)
    assert trajectory.frame_times(whole)[-1] == 60.0
    assert pose_series(whole, [60.0]).distance_m[0] == pytest.approx(20.0, rel=1e-15)


def test_the_quaternions_are_unit_and_continuous_through_a_fast_tumble():
    s = scene(
        trajectory__kind="hold",
        trajectory__tumble_rate_deg_s=170.0,  # 170 deg a frame: the sign must stay continuous
        trajectory__tumble_axis=[0.3, 0.1, -1.0],
        trajectory__initial_quaternion_wxyz=[-0.5, 0.5, 0.5, 0.5],  # w < 0 given
    )
    q = pose_series(s, np.arange(40.0)).quaternion_wxyz
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert q[0, 0] >= 0.0
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) >= 0.0)


# ----------------------------------------------------------------------------------------------
# ground truth
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def held(tmp_path_factory):
    """A 2-frame hold at 60 m, tumbling, 24 x 24 pixels, 1 sub-ray, a manual Sun; the CLI's
    outputs too."""
    keys = {
        **HOLD,
        "pixels": 24,
        "fidelity.subrays": 1,
        "sun.mode": "manual",
        "sun.azimuth_deg": 40.0,
    }
    s = simcore.with_overrides(simcore.Scene(), keys)
    fly = run_flyaround(s, [0.0, 2.0], progress=False, keep_clouds=True)
    out = tmp_path_factory.mktemp("hold") / "out"
    argv = ["flyaround", "--out", str(out)]
    for k, v in keys.items():
        argv += ["--set", f"{k}={json.dumps(v)}"]
    assert main(argv) == 0
    return fly, out


def test_the_transform_chain_closes_a_mesh_face_mapped_to_the_sensor_holds_its_cloud_point(held):
    fly, _ = held
    model = fly.target_model
    body = model.vertices_m @ np.asarray(model.body_from_mesh).T  # the target frame
    for i, cloud in enumerate(fly.clouds):
        T = fly.truth.matrices[i]
        target = ~cloud.attributes["is_outlier"]
        assert target.sum() > 50
        face = cloud.attributes["facet_id"][target]
        corners = body[model.faces[face]] @ T[:3, :3].T + T[:3, 3]  # (n, 3, 3) sensor frame
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        points = cloud.points[target]
        off_plane_m = np.abs(np.einsum("ij,ij->i", points - corners[:, 0], normal))
        # along the line of sight the point is off its face by its range error; across, exact
        cos = np.abs(
            np.einsum("ij,ij->i", points / np.linalg.norm(points, axis=1)[:, None], normal)
        )
        # the ray caster intersects in single precision: a few float32 steps of the range
        float32_m = 4 * np.finfo(np.float32).eps * np.linalg.norm(points, axis=1)
        allowed_m = np.abs(cloud.attributes["range_error_m"][target]) * cos + float32_m
        assert np.all(off_plane_m <= allowed_m)


def test_the_sensor_in_target_pose_is_the_inverse_and_the_sun_one_vector_in_both_frames(held):
    fly, _ = held
    truth = fly.truth
    position, q_inv = truth.sensor_in_target()
    for i in range(len(truth.t_s)):
        inverse = np.eye(4)
        inverse[:3, :3] = quaternion_matrix(q_inv[i])
        inverse[:3, 3] = position[i]
        np.testing.assert_allclose(inverse @ truth.matrices[i], np.eye(4), atol=1e-12)
    rows = np.array([r[17:23] for r in truth.rows()])
    np.testing.assert_allclose(np.linalg.norm(rows[:, :3], axis=1), 1.0, atol=1e-12)
    manual = simcore.sun.direction_from_angles(40.0, 30.0)  # fixed in the body frame
    np.testing.assert_allclose(rows[:, 3:], np.tile(manual, (2, 1)), atol=1e-15)
    sensor = np.einsum("nij,nj->ni", truth.rotation, rows[:, 3:])
    np.testing.assert_allclose(rows[:, :3], sensor, atol=1e-15)


def test_poses_csv_and_the_json_record_hold_the_same_truth_with_its_conventions(held):
    fly, out = held
    with open(out / POSES_NAME, newline="") as fh:
        table = list(csv.reader(fh))
    assert tuple(table[0]) == trajectory.POSE_COLUMNS
    assert len(table) == 1 + 3  # 0, 2, 4 s at 0.5 Hz over 4 s
    data = json.loads((out / JSON_NAME).read_text())
    assert "Hamilton" in data["conventions"]["quaternion"]
    for row, frame in zip(table[1:], data["frames"], strict=True):
        for name, text in zip(trajectory.POSE_COLUMNS[1:], row[1:], strict=True):
            assert float(text) == frame["truth"][name]  # repr: the same float
    assert [float(r[1]) for r in table[1:3]] == fly.truth.t_s.tolist()


# ----------------------------------------------------------------------------------------------
# bad input: one line, before any work
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"trajectory.tumble_axis": [0.0, 0.0, 0.0]}, "trajectory.tumble_axis .*not all 0"),
        (
            {
                "trajectory.kind": "approach",
                "trajectory.frame_rate_hz": 1000.0,
                "trajectory.duration_s": 1000.0,
            },
            "makes 1000001 frames .at most 10000",
        ),
        ({"trajectory.tumble_rate_deg_s": 400.0}, "tumble_rate_deg_s = 400.0 is out of range"),
        ({"trajectory.initial_quaternion_wxyz": [0, 0, 0, 0]}, "initial_quaternion_wxyz"),
        ({"trajectory.tumble_rate_deg_s": 1.0, "sun.mode": "orbit"}, "sun.mode = orbit"),
    ],
)
def test_a_bad_trajectory_is_one_clear_scene_error(keys, message):
    with pytest.raises(SceneError, match=message) as caught:
        simcore.with_overrides(simcore.Scene(), keys)
    assert "\n" not in str(caught.value)


def test_an_approach_ending_inside_the_target_is_refused_before_the_first_frame(tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["flyaround", "--out", str(out), "--set", "trajectory.kind=approach"]
    argv += ["--set", "trajectory.end_range_m=3", "--set", "pixels=16"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "trajectory.end_range_m = 3 m ends inside the target" in err and "\n" not in err
    assert not out.exists()


def test_an_orbit_flag_is_refused_for_an_approach(tmp_path, capsys):
    argv = ["flyaround", "--out", str(tmp_path / "o"), "--set", "trajectory.kind=approach"]
    assert main([*argv, "--interval-s", "10"]) == 2
    assert "--interval-s is for trajectory.kind = orbit" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
