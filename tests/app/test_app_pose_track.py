"""The fly-around's pose track in the app, without a browser (issue 40, item 5): the shown frames
registered as ``simcore.tracking.track`` registers a fly-around (the same numbers), stale work
dropped when the time slider moves, the two triads (coinciding where the estimate is right) and
the error chart; then the "Track pose" switch on a running app."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support.app_helpers import change, settle

import simcore
from app.engine import Engine
from app.logic.flyaround import Player
from app.logic.pose_track import PoseTrack
from app.main import LmapdApp
from app.payloads import scene3d
from app.payloads import track as track_payload
from simcore import tracking
from simcore.pointcloud import PointCloud
from simcore.trajectory import GroundTruth


def pose_matrix(rotvec, translation_m) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = translation_m
    return out


BASE = pose_matrix([0.4, -1.1, 0.3], [0.3, -0.2, 60.0])  # T_sensor_target of frame 0
# three frames 1 s apart, the target spinning 4 deg a frame about its body y axis
POSES = [BASE @ pose_matrix([0.0, np.radians(4.0 * k), 0.0], [0.0, 0.0, 0.0]) for k in range(3)]


@pytest.fixture(scope="module")
def mro():
    return simcore.load_target(simcore.load_scene().target)


@pytest.fixture(scope="module")
def clouds(mro):
    """Each frame's seen side, noise-free: 4000 samples of another draw than the model's."""
    view = tracking.model_points(mro, 4000, seed=11)
    return [view.seen_from(p) @ p[:3, :3].T + p[:3, 3] for p in POSES]


@pytest.fixture(scope="module")
def truth():
    q = Rotation.from_matrix(np.array(POSES)[:, :3, :3]).as_quat(scalar_first=True)
    return GroundTruth(
        t_s=np.arange(3.0),
        range_m=np.linalg.norm(np.array(POSES)[:, :3, 3], axis=1),
        translation_m=np.array(POSES)[:, :3, 3],
        quaternion_wxyz=q,
        sun_target=np.tile([1.0, 0.0, 0.0], (3, 1)),
    )


@pytest.fixture(scope="module")
def direct(mro, clouds, truth):
    """The same frames through simcore.tracking.track."""
    return tracking.track([PointCloud(points=c, attributes={}) for c in clouds], mro, truth)


def test_frames_shown_in_order_are_tracked_as_the_library_tracks_them(mro, clouds, truth, direct):
    delivered = []
    track = PoseTrack(delivered.append, background=False)
    for k in range(3):  # scored against the same truth matrices as the library's
        track.submit(k, float(k), clouds[k], truth.matrices[k], "scene", mro)
    assert [e.index for e in delivered] == [0, 1, 2]
    assert [e.method for e in track.series()] == list(direct.methods)  # global, then seeded
    for k, e in enumerate(track.series()):
        np.testing.assert_array_equal(e.pose, direct.poses[k])
        assert e.rotation_error_deg == direct.rotation_error_deg[k]
        assert e.translation_error_m == direct.translation_error_m[k]
        assert not e.lost
    # a frame tracked already is delivered again, not registered anew
    track.submit(1, 1.0, clouds[1], POSES[1], "scene", mro)
    assert delivered[-1] is track.estimates[1]


def test_a_jump_along_the_track_starts_with_no_prior_and_another_scene_starts_again(mro, clouds):
    track = PoseTrack(lambda e: None, background=False)
    track.submit(0, 0.0, clouds[0], POSES[0], "scene", mro)
    track.submit(2, 2.0, clouds[2], POSES[2], "scene", mro)  # frame 1 never shown: a gap
    assert track.estimates[2].method == "global"
    track.submit(1, 1.0, clouds[1], POSES[1], "other pixels", mro)
    assert list(track.estimates) == [1] and track.estimates[1].method == "global"


def test_the_slider_moving_drops_the_frame_waiting_and_the_one_under_way(mro, clouds, monkeypatch):
    gate, started = threading.Event(), threading.Event()
    real = tracking.track_frame

    def held(*args, **kwargs):  # the real registration, once the test lets it go
        started.set()
        assert gate.wait(180)
        return real(*args, **kwargs)

    monkeypatch.setattr(tracking, "track_frame", held)
    delivered = []
    track = PoseTrack(delivered.append)
    try:
        track.submit(0, 0.0, clouds[0], POSES[0], "scene", mro)
        assert started.wait(180)  # frame 0 under way
        track.submit(1, 1.0, clouds[1], POSES[1], "scene", mro)  # waiting
        track.submit(2, 2.0, clouds[2], POSES[2], "scene", mro)  # replaces frame 1
        assert track.n_dropped == 1
        track.moved()  # frame 2 dropped; frame 0's result will be thrown away
        assert track.n_dropped == 2
        gate.set()
        wait_for(lambda: track.n_dropped >= 3)
        assert track.n_dropped == 3 and delivered == [] and track.estimates == {}
        track.submit(1, 1.0, clouds[1], POSES[1], "scene", mro)  # the frame now shown
        wait_for(lambda: bool(delivered))
        assert [e.index for e in delivered] == [1] and delivered[0].method == "global"
    finally:
        gate.set()
        track.close()


def test_the_triads_coincide_where_the_estimate_is_right_and_part_by_its_error(mro):
    frame = scene3d.display_frame(mro)
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 8})
    result = simcore.Pipeline().run(scene)
    hits_pose = result.hits.pose
    truth = track_payload.true_pose(hits_pose, mro.body_from_mesh)

    def points(mesh):
        m = mesh["mesh"]["points"]
        return np.frombuffer(m["bytes"], dtype=np.float32).reshape(m["shape"])

    right = track_payload.triads(frame, hits_pose, truth, truth)
    np.testing.assert_array_equal(
        points(right["fly_triad_true"]), points(right["fly_triad_estimate"])
    )
    true_d = points(right["fly_triad_true"])
    # the true target frame drawn at the target's centre (the display's origin), x longest
    np.testing.assert_allclose(true_d[0], 0.0, atol=1e-4)
    lengths = np.linalg.norm(true_d[1:] - true_d[0], axis=1)
    size = track_payload.TRIAD_SIZE * frame.radius_m
    np.testing.assert_allclose(lengths, size * np.array(track_payload.AXIS_LENGTHS), rtol=1e-5)
    # an estimate 0.25 m off along the boresight and turned 10 deg: its triad as far off
    off = pose_matrix([0.0, 0.0, np.radians(10.0)], [0.0, 0.0, 0.25]) @ truth
    wrong = track_payload.triads(frame, hits_pose, truth, off)
    est_d = points(wrong["fly_triad_estimate"])
    rot_err, tra_err = tracking.pose_errors(off, truth)
    assert np.linalg.norm(est_d[0] - true_d[0]) == pytest.approx(tra_err, rel=1e-5)
    assert track_payload.triads(frame, hits_pose, truth, None)["fly_triad_estimate"] is None


def test_the_error_chart_draws_the_track_so_far_and_a_lost_frame_as_a_cross():
    chart = track_payload.error_chart(
        [0.0, 300.0, 600.0], [0.5, 0.7, 90.0], [0.02, 0.03, 4.0], [False, False, True], 300.0
    )
    rotation, translation, lost = chart["data"]
    assert rotation["x"] == [0.0, 300.0] and rotation["y"] == [0.5, 0.7]
    assert translation["y"] == [0.02, 0.03] and translation["yaxis"] == "y2"
    assert lost["x"] == [600.0] and lost["marker"]["symbol"] == "x"
    assert chart["layout"]["shapes"][0]["x0"] == 300.0
    assert chart["layout"]["yaxis2"]["title"]["text"] == "translation error (m)"
    assert "annotations" in track_payload.error_chart([], [], [], [])["layout"]


@pytest.fixture
def app(mro):
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 32, "fidelity.subrays": 1})
    lmapd = LmapdApp(scene, engine=Engine(scene, model=mro), flow_control=False, debounce_s=0.0)
    lmapd.logic.flyaround.player = Player(min_interval_s=0.0)
    lmapd.state.ready()
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()
    lmapd.logic.flyaround.pose_track.close()


def wait_for(condition, timeout_s: float = 180.0) -> None:
    """Wait for ``condition`` (a registration takes seconds; a loaded machine, many more)."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert condition()


def test_the_track_pose_switch_tracks_the_frames_shown_and_play_waits_for_them(app, monkeypatch):
    fly, state = app.logic.flyaround, app.state
    change(app, mode="flyaround", fly_t_s=0)
    assert state.fly_triad_true is None  # off: nothing drawn
    change(app, fly_track=True)
    assert state.fly_triad_true is not None  # the true frame at once
    wait_for(lambda: state.fly_track_chart is not None)
    assert state.fly_triad_estimate is not None
    assert state.fly_track_text.startswith("Pose track:")
    first = fly.pose_track.estimates[0]
    assert first.method == "global" and first.t_s == 0.0
    assert state.fly_track_chart["data"][0]["x"] in ([0.0], [])  # one frame (or lost)
    # the truth it is scored against is the frame's own pose, in the body frame
    result = app.logic.last_frame.result
    np.testing.assert_allclose(
        first.truth, track_payload.true_pose(result.hits.pose, result.target.body_from_mesh)
    )
    # play: the next frame, seeded by the first, steps on once it is drawn AND tracked
    gate = threading.Event()
    real = tracking.track_frame

    def held(*args, **kwargs):
        assert gate.wait(180)
        return real(*args, **kwargs)

    monkeypatch.setattr(tracking, "track_frame", held)
    change(app, fly_playing=True)
    app.logic.on_frame_shown(state.frame_key)  # frame 0 drawn and tracked: a step
    assert state.fly_t_s == 300
    settle(app)
    app.logic.on_frame_shown(state.frame_key)  # frame 1 drawn, its registration held
    assert state.fly_t_s == 300 and not fly.frame_drawn()
    gate.set()
    wait_for(lambda: state.fly_t_s == 600)  # tracked: play goes on
    assert fly.pose_track.estimates[1].method != "global" or fly.pose_track.estimates[0].lost
    change(app, fly_playing=False)
    wait_for(lambda: 2 in fly.pose_track.estimates)  # the frame at 600 s tracked: idle
    change(app, fly_track=False)
    assert state.fly_track_chart is None and state.fly_triad_true is None
    assert fly.pose_track.estimates == {}
