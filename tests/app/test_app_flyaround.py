"""Fly-around mode without a browser: the orbit's frames, state -> scene in fly-around mode, the
play/pause stepping (with a fake clock: one step per drawn frame, never queued) and stale frames
dropped."""

from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.app_helpers import ANYTHING, change, settle

import simcore
from app.engine import Engine
from app.logic.flyaround import (
    MODES,
    FlyaroundControls,
    FlyaroundPoses,
    Player,
    sanitize_flyaround,
)
from app.main import LmapdApp
from simcore import orbit

SMALL = {"pixels": 32, "fidelity.subrays": 1}


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def poses():
    return FlyaroundPoses()


@pytest.fixture(scope="module")
def model():
    return simcore.load_target(simcore.load_scene().target)


@pytest.fixture
def app(model):
    """An app at 32 x 32 pixels with a fake-clock player, frames applied at once."""
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    lmapd = LmapdApp(scene, engine=Engine(scene, model=model), flow_control=False, debounce_s=0.0)
    lmapd.logic.flyaround.player = Player(min_interval_s=0.5, clock=FakeClock())
    lmapd.state.ready()
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()


def frame_scene(app: LmapdApp) -> simcore.Scene:
    return app.logic.last_frame.result.scene


# -- the frames of the orbit ------------------------------------------------------------------
def test_the_default_fly_around_is_0_to_5700_s_in_300_s_steps_at_about_200_m(poses):
    assert poses.times_s[0] == 0 and poses.t_max_s == 5700 and poses.interval_s == 300
    assert len(poses.times_s) == 20
    reference = orbit.relative_pose_series(
        orbit.PAPER_TARGET, orbit.PAPER_IMAGING, orbit.flyaround_times(), j2=False
    )
    keys = poses.overrides(1200, j2=False)
    assert keys["pose.quaternion_wxyz"] == pytest.approx(reference.quaternion_wxyz[4].tolist())
    assert keys["distance_m"] == pytest.approx(reference.distance_m[4])
    assert 150 < keys["distance_m"] < 300
    readout = poses.readout(1200, False, 0.03)
    assert readout["t"].startswith("1200 s") and readout["distance"].endswith(" m")
    assert readout["fov"] == f"{reference.distance_m[4] * 0.03:.1f} m"


def test_times_snap_to_frames_and_bad_values_are_refused(poses):
    previous = FlyaroundControls(mode="flyaround", t_s=600.0)
    controls, messages = sanitize_flyaround({"t_s": 1000}, previous, poses)
    assert controls.t_s == 900 and messages == []
    controls, messages = sanitize_flyaround({"t_s": "1e9"}, previous, poses)
    assert controls.t_s == 5700 and "outside 0 to 5700 s; set to 5700 s" in messages[0]
    raw = {"t_s": "soon", "mode": "orbit", "j2": "yes"}
    controls, messages = sanitize_flyaround(raw, previous, poses)
    assert controls == previous and len(messages) == 3
    assert messages[0].startswith("Mode: 'orbit' is not one of single, flyaround")


# -- state -> scene -----------------------------------------------------------------------------
def test_fly_around_mode_sets_the_orbits_pose_and_keeps_the_other_controls(app, poses):
    change(app, mode="flyaround", fly_t_s=1200)
    scene = frame_scene(app)
    keys = poses.overrides(1200, j2=False)
    assert list(scene.pose.quaternion_wxyz) == pytest.approx(keys["pose.quaternion_wxyz"])
    assert scene.pose.distance_m == pytest.approx(keys["distance_m"])
    assert app.state.fly_readout["t"].startswith("1200 s")
    assert app.state.error_message == "" and app.state.n_points > 0
    change(app, tnr=7, pixels=48, preset="interactive")  # the other controls still apply
    scene = frame_scene(app)
    assert (scene.timing.tnr, scene.detector.pixels, scene.fidelity.refine_subrays) == (7, 48, 64)
    assert scene.pose.distance_m == pytest.approx(keys["distance_m"])
    rotation = app.logic.last_frame.result.hits.pose.rotation.copy()
    change(app, pitch_deg=40, distance_m=900)  # the pose sliders do not move the orbit's pose
    assert np.allclose(app.logic.last_frame.result.hits.pose.rotation, rotation)
    assert frame_scene(app).pose.distance_m == pytest.approx(keys["distance_m"])
    change(app, mode="single")
    scene = frame_scene(app)
    assert scene.pose.quaternion_wxyz == () and scene.pose.distance_m == 900
    assert scene.pose.pitch_deg == 40


def test_j2_changes_the_pose_late_in_the_orbit(app, poses):
    change(app, mode="flyaround", fly_t_s=5700)
    without = frame_scene(app).pose.distance_m
    change(app, fly_j2=True)
    assert frame_scene(app).pose.distance_m == pytest.approx(poses.pose(True).distance_m[-1])
    assert frame_scene(app).pose.distance_m != pytest.approx(without, abs=1e-6)


def test_a_time_from_the_websocket_outside_the_orbit_is_clamped_with_a_message(app):
    change(app, mode="flyaround", fly_t_s=-50)
    assert app.state.fly_t_s == 0 and "Time -50 s is outside 0 to 5700 s" in app.state.input_message


def test_the_time_slider_does_not_recompute_in_single_frame_mode(app):
    pushed = app.logic.n_frames_pushed
    change(app, fly_t_s=600)  # single-frame mode: the time does not matter
    assert app.logic.n_frames_pushed == pushed


# -- play / pause -------------------------------------------------------------------------------
def test_the_player_steps_only_after_a_drawn_frame_and_at_most_every_interval():
    clock = FakeClock()
    player = Player(min_interval_s=0.5, clock=clock)
    assert player.wait_s(frame_drawn=True) is None  # paused
    player.play()
    assert player.wait_s(frame_drawn=False) is None  # the current frame is not drawn yet
    assert player.wait_s(frame_drawn=True) == 0.0
    assert player.step(0, 20) == 1
    assert player.wait_s(frame_drawn=True) == pytest.approx(0.5)  # drawn fast: wait
    clock.now += 0.2
    assert player.wait_s(frame_drawn=True) == pytest.approx(0.3)
    clock.now += 0.3
    assert player.wait_s(frame_drawn=True) == 0.0
    assert player.step(19, 20) == 0  # after the last frame: the first again
    player.pause()
    assert player.wait_s(frame_drawn=True) is None


def test_play_steps_through_the_frames_one_drawn_frame_at_a_time(app):
    fly, state = app.logic.flyaround, app.state
    clock = fly.player.clock
    change(app, mode="flyaround", fly_t_s=0)
    change(app, fly_playing=True)
    assert state.fly_t_s == 0  # the page has not reported the frame drawn yet
    app.logic.on_frame_shown(state.frame_key)  # drawn: step to the next time
    assert state.fly_t_s == 300
    computing_key = state.frame_key
    app.logic.on_frame_shown(computing_key)  # a report of the old frame again: no step
    app.logic.on_frame_shown("g999")  # nor of a frame that does not exist
    assert state.fly_t_s == 300
    settle(app)
    assert frame_scene(app).pose.distance_m == pytest.approx(fly.poses.pose(False).distance_m[1])
    app.logic.on_frame_shown(state.frame_key)  # drawn, but too soon after the last step
    assert state.fly_t_s == 300
    clock.now += 0.5
    fly.tick()  # the play timer
    assert state.fly_t_s == 600 and fly.player.n_steps == 2
    settle(app)
    change(app, fly_playing=False)
    clock.now += 1
    app.logic.on_frame_shown(state.frame_key)
    assert state.fly_t_s == 600  # paused


def test_leaving_fly_around_mode_stops_playing_and_a_failed_frame_pauses(app, monkeypatch):
    fly, state = app.logic.flyaround, app.state
    change(app, mode="flyaround", fly_playing=True)
    change(app, mode="single")
    assert state.fly_playing is False and not fly.player.playing
    change(app, mode="flyaround", fly_playing=True)
    monkeypatch.setattr(app.logic.runner, "_compute", lambda request: 1 / 0)
    change(app, fly_t_s=900)
    assert state.error_message.startswith("Simulation failed")
    fly.player.clock.now += 10
    app.logic.on_frame_shown(state.frame_key)
    assert state.fly_playing is False and state.fly_t_s == 900


def test_a_frame_overtaken_while_computing_is_dropped_not_shown(app, monkeypatch):
    change(app, mode="flyaround", fly_t_s=0)
    entered, release = threading.Event(), threading.Event()
    chain = simcore.pipeline.CHAIN
    hits = next(stage for stage in chain if stage.name == "hits")

    def slow_hits(*args):
        entered.set()
        release.wait(10)
        return hits.compute(*args)

    slow = dataclasses.replace(hits, compute=slow_hits)
    monkeypatch.setattr(simcore.pipeline, "CHAIN", tuple(slow if s is hits else s for s in chain))
    pushed, dropped = app.logic.n_frames_pushed, app.logic.runner.n_dropped
    with app.state:
        app.state.fly_t_s = 300
    assert entered.wait(10)
    with app.state:
        app.state.fly_t_s = 600  # the user drags on while t = 300 s is computing
    release.set()
    settle(app)
    assert app.logic.n_frames_pushed == pushed + 1  # only the newest frame is shown
    assert app.logic.runner.n_dropped == dropped + 1
    distance = app.logic.flyaround.poses.pose(False).distance_m[2]
    assert frame_scene(app).pose.distance_m == pytest.approx(distance)


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(raw=st.fixed_dictionaries({"mode": ANYTHING, "t_s": ANYTHING, "j2": ANYTHING}))
def test_any_websocket_values_give_valid_fly_around_controls(poses, raw):
    controls, _ = sanitize_flyaround(raw, FlyaroundControls(), poses)
    assert controls.mode in MODES and isinstance(controls.j2, bool)
    assert controls.t_s in poses.times_s.tolist()
