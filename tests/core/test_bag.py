"""The fly-around as a ROS 2 bag (simcore.bag): written with rosbags, read back with rosbags' own
reader, every frame's points and transforms bit for bit; ``lmapd flyaround --track --bag``."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

import simcore
from simcore import bag
from simcore.cli import main
from simcore.cli.flyaround import JSON_NAME, TRACK_CSV_NAME, TRACK_PNG_NAME
from simcore.flyaround import run_flyaround
from simcore.tracking import TRACK_COLUMNS, TrackResult

HOLD = {
    "pixels": 20,
    "fidelity.subrays": 1,
    "trajectory.kind": "hold",
    "trajectory.start_range_m": 60.0,
    "trajectory.duration_s": 2.0,
    "trajectory.frame_rate_hz": 1.0,
    "trajectory.tumble_rate_deg_s": 3.0,
}


@pytest.fixture(scope="module")
def fly():
    scene = simcore.with_overrides(simcore.Scene(), HOLD)
    return run_flyaround(scene, progress=False, keep_clouds=True)


def fake_track(fly) -> TrackResult:
    """A TrackResult whose estimates are the truth moved by 1 cm (the bag only carries them)."""
    poses = fly.truth.matrices.copy()
    poses[:, 0, 3] += 0.01
    n = len(poses)
    zeros = np.zeros(n)
    return TrackResult(
        t_s=fly.truth.t_s,
        range_m=fly.truth.range_m,
        poses=poses,
        rotation_error_deg=zeros,
        translation_error_m=zeros + 0.01,
        fitness=zeros + 1.0,
        points_used=np.full(n, 10),
        lost=np.zeros(n, bool),
        methods=("tracked",) * n,
        registration_s=zeros,
    )


def read(path):
    """Every message of the bag: topic -> [(timestamp_ns, message)], in time order."""
    out: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, stamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (stamp, reader.deserialize(raw, connection.msgtype))
            )
    return out


def test_the_bag_holds_every_frames_points_bit_for_bit_and_the_true_transforms(fly, tmp_path):
    path = bag.write_bag(tmp_path / "run.mcap", fly, fake_track(fly))
    assert [p.name for p in tmp_path.iterdir()] == ["run.mcap"]  # one file, no staging left
    messages = read(path)
    assert set(messages) == {bag.POINTS_TOPIC, bag.TF_TOPIC, bag.POSE_TOPIC}
    stamps = bag.frame_stamps_ns(fly.scene.orbit.epoch_utc, fly.truth.t_s)
    assert len(stamps) == 3 and stamps[1] - stamps[0] == 10**9
    for i, (stamp, msg) in enumerate(messages[bag.POINTS_TOPIC]):
        cloud = fly.clouds[i]
        assert stamp == stamps[i] and msg.header.frame_id == "lidar"
        assert [f.name for f in msg.fields] == list(bag.FIELDS)
        assert msg.width == len(cloud) and msg.height == 1 and not msg.is_bigendian
        rows = np.frombuffer(msg.data.tobytes(), dtype=bag.cloud_array(cloud).dtype)
        for k, axis in enumerate("xyz"):
            assert rows[axis].tobytes() == cloud.points[:, k].tobytes()
        for name, attribute in bag.FIELDS.items():
            if attribute is not None:
                expected = np.asarray(cloud.attributes[attribute])
                assert rows[name].tobytes() == expected.astype(rows[name].dtype).tobytes()
                assert np.array_equal(rows[name], expected, equal_nan=expected.dtype.kind == "f")
    for i, (stamp, msg) in enumerate(messages[bag.TF_TOPIC]):
        (tf,) = msg.transforms
        assert stamp == stamps[i]
        assert (tf.header.frame_id, tf.child_frame_id) == ("lidar", "target")
        t, r = tf.transform.translation, tf.transform.rotation
        assert [t.x, t.y, t.z] == fly.truth.translation_m[i].tolist()
        assert [r.w, r.x, r.y, r.z] == fly.truth.quaternion_wxyz[i].tolist()
    for i, (_, msg) in enumerate(messages[bag.POSE_TOPIC]):
        p = msg.pose.position
        assert p.x == fly.truth.translation_m[i, 0] + 0.01


def test_without_a_track_the_bag_has_no_pose_topic(fly, tmp_path):
    assert set(read(bag.write_bag(tmp_path / "b.mcap", fly))) == {bag.POINTS_TOPIC, bag.TF_TOPIC}


@pytest.mark.slow
def test_cli_track_and_bag_write_the_table_the_figure_the_summary_and_the_bag(tmp_path, capsys):
    out, path = tmp_path / "run", tmp_path / "run.mcap"
    argv = ["flyaround", "--out", str(out), "--track", "--bag", str(path)]
    for key, value in HOLD.items():
        argv += ["--set", f"{key}={json.dumps(value)}"]
    assert main(argv) == 0
    with open(out / TRACK_CSV_NAME, newline="") as fh:
        table = list(csv.reader(fh))
    assert tuple(table[0]) == TRACK_COLUMNS and len(table) == 1 + 3
    assert (out / TRACK_PNG_NAME).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((out / JSON_NAME).read_text())["tracking"]
    assert summary["n_frames"] == 3 and "fewer than" in summary["lost_rule"]
    assert len(read(path)[bag.POSE_TOPIC]) == 3
    assert "track:" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("name", "message"),
    [("x.bag", "ending in .mcap"), ("missing/x.mcap", "does not exist")],
)
def test_cli_refuses_a_bad_bag_name_before_any_frame(tmp_path, capsys, name, message):
    out = tmp_path / "out"
    assert main(["flyaround", "--out", str(out), "--bag", str(tmp_path / name)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
