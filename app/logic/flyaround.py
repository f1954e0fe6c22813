"""Fly-around mode: the target imaged along the two orbits of Table 3, one frame per time step.

In this mode the pose of each frame comes from ``simcore.orbit.relative_pose_series`` (distance
and attitude quaternion at time t; the quaternion replaces pitch/azimuth), every other control
(pixels, energy, TNR, fidelity, materials) still applies. The time slider picks a frame; play
steps through the frames, one computed result at a time: the next time is set only once the
newest request's frame has been drawn by the page, and at most every ``min_interval_s``.

``FlyaroundPoses`` and ``Player`` are plain objects (tested with a fake clock);
``FlyaroundLogic`` binds them to the trame state and to ``AppLogic``.

The "Track pose" switch (``fly_track``) registers each frame shown to the target's model in the
background (``app.logic.pose_track``, seeded by the frames before it), draws the true and the
estimated target frames as two triads in the 3D view and the errors along the track so far
(``app.payloads.track``). While it is on, play steps only once the frame shown is tracked, so
that each frame is seeded by the one before.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

import simcore
from app.logic.pose_track import FrameEstimate, PoseTrack
from app.payloads import track as track_payload
from app.payloads.orbits import OrbitMap
from simcore import orbit

MODES = ("single", "flyaround")
INTERVAL_S = 300.0  # the paper's imaging interval
MIN_STEP_INTERVAL_S = 0.6  # play: at most one step this often, even when frames are fast

# the trame state of the mode (everything else is in app.state.Controls)
STATE_KEYS = ("mode", "fly_t_s", "fly_j2")


@dataclass(frozen=True)
class FlyaroundControls:
    """The fly-around's own controls: the mode, the frame time [s] and the J2 switch."""

    mode: str = "single"
    t_s: float = 0.0
    j2: bool = False


class FlyaroundPoses:
    """The imaging times and the relative pose at each (with and without J2, computed once)."""

    def __init__(
        self,
        interval_s: float = INTERVAL_S,
        duration_s: float = orbit.PAPER_PERIOD_S,
        target: orbit.Elements = orbit.PAPER_TARGET,
        imaging: orbit.Elements = orbit.PAPER_IMAGING,
    ):
        self.interval_s = float(interval_s)
        self.duration_s = float(duration_s)
        self.times_s = orbit.flyaround_times(interval_s, duration_s)
        self._orbits = (target, imaging)
        self._poses: dict[bool, orbit.RelativePose] = {}

    @property
    def t_max_s(self) -> float:
        return float(self.times_s[-1])

    @property
    def orbits(self) -> tuple[orbit.Elements, orbit.Elements]:
        """The target's and the lidar's orbits."""
        return self._orbits

    def pose(self, j2: bool) -> orbit.RelativePose:
        if j2 not in self._poses:
            self._poses[j2] = orbit.relative_pose_series(*self._orbits, self.times_s, j2=j2)
        return self._poses[j2]

    def index_of(self, t_s: float) -> int:
        """The frame nearest ``t_s``."""
        return int(np.argmin(np.abs(self.times_s - float(t_s))))

    def overrides(self, t_s: float, j2: bool) -> dict[str, Any]:
        """The ``simcore.with_overrides`` keys of the frame at ``t_s``: attitude, distance and
        the orbit's time (the Sun and the Earth's shadow follow it with ``sun.mode = orbit``),
        as ``lmapd flyaround`` sets them."""
        pose, i = self.pose(j2), self.index_of(t_s)
        return {
            "pose.quaternion_wxyz": [float(q) for q in pose.quaternion_wxyz[i]],
            "distance_m": float(pose.distance_m[i]),
            "orbit.time_s": float(self.times_s[i]),
            "orbit.j2": bool(j2),
        }

    def readout(self, t_s: float, j2: bool, fov_rad: float) -> dict[str, str]:
        """What the page shows of the frame at ``t_s``: time, distance, attitude, field of view."""
        pose, i = self.pose(j2), self.index_of(t_s)
        distance = float(pose.distance_m[i])
        a0, a1, a2 = (float(a) for a in pose.angles_deg[i])
        return {
            "t": f"{float(self.times_s[i]):.0f} s (frame {i + 1} of {len(self.times_s)})",
            "distance": f"{distance:.1f} m",
            "angles": f"{a0:.1f}°, {a1:.1f}°, {a2:.1f}°",
            "fov": f"{distance * fov_rad:.1f} m",
        }


def sanitize_flyaround(
    raw: dict[str, Any], previous: FlyaroundControls, poses: FlyaroundPoses
) -> tuple[FlyaroundControls, list[str]]:
    """Valid fly-around controls from page/websocket values and a message for each value changed:
    the time snaps to the nearest frame (clamped into the fly-around); a mode that is not one of
    MODES, a time that is no number or a J2 flag that is no boolean is refused. Never raises."""
    messages: list[str] = []
    mode = raw.get("mode", previous.mode)
    if mode not in MODES:
        messages.append(f"Mode: {str(mode)[:40]!r} is not one of {', '.join(MODES)}; kept")
        mode = previous.mode
    value = raw.get("t_s", previous.t_s)
    try:
        if isinstance(value, bool) or value is None or value == "":
            raise ValueError
        t_s = float(value)
        if math.isnan(t_s):
            raise ValueError
    except (TypeError, ValueError, OverflowError):
        messages.append(f"Time: {str(value)[:40]!r} is not a number; kept {previous.t_s:g} s")
        t_s = previous.t_s
    snapped = float(poses.times_s[poses.index_of(min(max(t_s, 0.0), poses.t_max_s))])
    if t_s < 0.0 or t_s > poses.t_max_s:
        messages.append(f"Time {t_s:g} s is outside 0 to {poses.t_max_s:g} s; set to {snapped:g} s")
    j2 = raw.get("j2", previous.j2)
    if not isinstance(j2, bool):
        messages.append(f"J2: {str(j2)[:40]!r} is not true or false; kept {previous.j2}")
        j2 = previous.j2
    return FlyaroundControls(mode=str(mode), t_s=snapped, j2=j2), messages


class Player:
    """Play/pause stepping: when may the next frame time be set?

    Never queues: the next step waits until the frame of the current step has been drawn, and
    steps are at least ``min_interval_s`` apart (so fast frames can still be seen).
    """

    def __init__(
        self,
        min_interval_s: float = MIN_STEP_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.min_interval_s = min_interval_s
        self.clock = clock
        self.playing = False
        self.n_steps = 0
        self._last_step_s = -math.inf

    def play(self) -> None:
        self.playing = True

    def pause(self) -> None:
        self.playing = False

    def wait_s(self, frame_drawn: bool) -> float | None:
        """None if no step is due (paused, or the current frame is not drawn yet); else the
        seconds until the next step may go (0: now)."""
        if not self.playing or not frame_drawn:
            return None
        return max(0.0, self._last_step_s + self.min_interval_s - self.clock())

    def step(self, index: int, n_frames: int) -> int:
        """Record a step now; the frame after ``index`` (after the last: the first again)."""
        self._last_step_s = self.clock()
        self.n_steps += 1
        return (index + 1) % max(n_frames, 1)


class FlyaroundLogic:
    """The fly-around mode on a trame state: a child of the app's logic, which it never calls.

    The parent calls ``apply`` on every scene it builds and ``on_frame_shown`` when the page
    reports a frame drawn; everything else (state, handlers, play timer) lives here. What the
    child needs of the parent comes in as arguments: the trame state, the array's field of view,
    the runner (is a frame computing, which generation is newest) and ``resubmit``, the callback
    that makes the parent compute the scene again.
    """

    def __init__(
        self,
        state,
        fov_rad: float,
        runner,
        resubmit: Callable[[], Any],
        poses: FlyaroundPoses | None = None,
        player: Player | None = None,
        on_ui_thread: Callable[..., Any] | None = None,
        track_in_background: bool = True,
    ):
        self.state = state
        self.fov_rad = fov_rad
        self.runner = runner
        self.resubmit = resubmit
        self.poses = poses or FlyaroundPoses()
        self.player = player or Player()
        self.controls = FlyaroundControls()
        self.map = OrbitMap(self.poses.duration_s, *self.poses.orbits)
        self._drawn_key = ""
        self._timer: asyncio.TimerHandle | None = None
        # the pose track: the worker's estimates come back through on_ui_thread
        self._on_ui_thread = on_ui_thread or (lambda call, *args: call(*args))
        self.pose_track = PoseTrack(
            lambda e: self._on_ui_thread(self.on_estimate, e), background=track_in_background
        )
        self._shown: tuple[int, Any, np.ndarray, Any] | None = None  # index, pose, truth, frame
        self.state.update(
            {
                "mode": self.controls.mode,
                "fly_t_s": self.controls.t_s,
                "fly_j2": self.controls.j2,
                "fly_playing": False,
                "fly_t_max_s": self.poses.t_max_s,
                "fly_interval_s": self.poses.interval_s,
                "fly_readout": self._readout(),
                "fly_map": None,  # the orbits' map: drawn in fly-around mode only
                "fly_track": False,
                "fly_track_chart": None,
                "fly_track_text": "",
                "fly_triad_true": None,
                "fly_triad_estimate": None,
            }
        )
        self.state.change(*STATE_KEYS)(self.on_change)
        self.state.change("fly_playing")(self.on_playing_change)
        self.state.change("fly_track")(self.on_track_change)

    # -- scene -----------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        return self.controls.mode == "flyaround"

    def apply(self, scene: simcore.Scene) -> simcore.Scene:
        """``scene`` with the orbit's pose at the current time in fly-around mode (else as is)."""
        if not self.active:
            return scene
        return simcore.with_overrides(
            scene, self.poses.overrides(self.controls.t_s, self.controls.j2)
        )

    def _readout(self) -> dict[str, str]:
        return self.poses.readout(self.controls.t_s, self.controls.j2, self.fov_rad)

    def _map(self) -> dict | None:
        """The orbits' map at the frame's time (None outside fly-around mode: not drawn)."""
        if not self.active:
            return None
        t_s = float(self.poses.times_s[self.poses.index_of(self.controls.t_s)])
        return self.map.figure(t_s, self.controls.j2)

    # -- state handlers --------------------------------------------------------------------------
    def on_change(self, **_: Any) -> None:
        """Mode, time or J2 changed: sanitise, write back corrections, resubmit if it matters."""
        raw = {"mode": self.state.mode, "t_s": self.state.fly_t_s, "j2": self.state.fly_j2}
        controls, messages = sanitize_flyaround(raw, self.controls, self.poses)
        if messages:
            self.state.input_message = "; ".join(messages)
        fixed: dict[str, Any] = {}
        if raw["mode"] != controls.mode:
            fixed["mode"] = controls.mode
        t_raw = raw["t_s"]
        if isinstance(t_raw, bool) or not isinstance(t_raw, int | float) or t_raw != controls.t_s:
            fixed["fly_t_s"] = controls.t_s
        if raw["j2"] is not controls.j2:
            fixed["fly_j2"] = controls.j2
        if controls == self.controls and not fixed:
            return  # e.g. the first call at server start: the parent submits the first frame
        changed = controls != self.controls
        was_active = self.active
        moved = controls.t_s != self.controls.t_s
        self.controls = controls
        fixed["fly_readout"] = self._readout()
        fixed["fly_map"] = self._map()
        if not self.active and self.state.fly_playing:
            self.player.pause()
            fixed["fly_playing"] = False
        if moved:
            self.pose_track.moved()  # the frame under way is not the one to show any more
        if not self.active:
            fixed |= self._no_track()
        self.state.update(fixed)
        if changed and (self.active or was_active):
            self.resubmit()

    def on_playing_change(self, fly_playing: Any = False, **_: Any) -> None:
        """The play/pause button."""
        if fly_playing is True and self.active:
            self.player.play()
            self.tick()
        else:
            self.player.pause()
            self._cancel_timer()
            if fly_playing is not False:
                self.state.fly_playing = False

    def on_frame_shown(self, key: Any) -> None:
        """From the controller: the page drew frame ``key``."""
        if isinstance(key, str):
            self._drawn_key = key
        self.tick()

    # -- the pose track --------------------------------------------------------------------------
    def on_track_change(self, fly_track: Any = False, **_: Any) -> None:
        """The "Track pose" switch: on, the frame shown is tracked now; off, the track is
        forgotten and its drawings go."""
        if fly_track is not True:
            self.pose_track.clear()
            if fly_track is not False:
                self.state.fly_track = False
            self.state.update(self._no_track())
            return
        if self._shown is not None and self.active:
            self._submit_shown()

    def frame_pushed(self, result: simcore.Result, display_frame: Any) -> None:
        """From the parent: a computed frame is on the page. In fly-around mode with the switch
        on, its true triad is drawn now and its cloud goes to the pose track."""
        if not self.active:
            self._shown = None
            return
        index = self.poses.index_of(result.scene.orbit.time_s)
        truth = track_payload.true_pose(result.hits.pose, result.target.body_from_mesh)
        self._shown = (index, result, truth, display_frame)
        if self.state.fly_track is True:
            self._submit_shown()

    def _submit_shown(self) -> None:
        assert self._shown is not None
        index, result, truth, display_frame = self._shown
        context = self._context(result)
        same = context == self.pose_track.context
        estimate = self.pose_track.estimates.get(index) if same else None
        self.state.update(
            track_payload.triads(
                display_frame,
                result.hits.pose,
                truth,
                None if estimate is None else estimate.pose,
            )
        )
        self.pose_track.submit(
            index,
            float(self.poses.times_s[index]),
            result.cloud.points,
            truth,
            context,
            result.target,
        )

    @staticmethod
    def _context(result: simcore.Result) -> str:
        """What a frame's cloud depends on but its time: the scene without its pose and time
        (another pixel count, energy or target starts the track again)."""
        import json  # noqa: PLC0415

        scene = result.scene.to_dict()
        scene.pop("pose", None)
        scene.get("orbit", {}).pop("time_s", None)
        return json.dumps(scene, sort_keys=True, default=str)

    def on_estimate(self, estimate: FrameEstimate) -> None:
        """On the UI thread: a frame tracked. The chart of the track so far; the estimated
        triad and the readout if it is the frame shown; play may step on."""
        if self.state.fly_track is not True or not self.active:
            return
        if self.pose_track.estimates.get(estimate.index) is not estimate:
            return  # the track was cleared since (the switch, another scene)
        series = self.pose_track.series()
        now = float(self.poses.times_s[self.poses.index_of(self.controls.t_s)])
        update: dict[str, Any] = {
            "fly_track_chart": track_payload.error_chart(
                [e.t_s for e in series],
                [e.rotation_error_deg for e in series],
                [e.translation_error_m for e in series],
                [e.lost for e in series],
                now_s=now,
            )
        }
        shown = self._shown
        if shown is not None and shown[0] == estimate.index:
            _, result, truth, display_frame = shown
            update |= track_payload.triads(display_frame, result.hits.pose, truth, estimate.pose)
            update["fly_track_text"] = track_text(estimate)
        with self.state:
            self.state.update(update)
        self.tick()

    def track_ready(self) -> bool:
        """The frame shown is tracked (always, with the switch off)."""
        if self.state.fly_track is not True:
            return True
        shown = self._shown
        return shown is not None and shown[0] in self.pose_track.estimates

    def _no_track(self) -> dict[str, Any]:
        return {
            "fly_track_chart": None,
            "fly_track_text": "",
            "fly_triad_true": None,
            "fly_triad_estimate": None,
        }

    # -- playing ---------------------------------------------------------------------------------
    def frame_drawn(self) -> bool:
        """The frame of the newest request is on the page and drawn (nothing newer computing),
        and tracked when the pose is tracked."""
        runner = self.runner
        return (
            not runner.busy
            and self.state.frame_generation == runner.generation
            and bool(self._drawn_key)
            and self._drawn_key == self.state.frame_key
            and self.track_ready()
        )

    def tick(self) -> None:
        """Step to the next frame time if one is due; else schedule the next check."""
        if not (self.player.playing and self.active):
            return
        if not self.runner.busy and self.state.error_message:
            self.player.pause()  # the frame failed: stop rather than skip over it
            self.state.fly_playing = False
            return
        wait = self.player.wait_s(self.frame_drawn())
        if wait is None:
            return  # on_frame_shown calls again
        if wait > 0:
            self._schedule(wait)
            return
        index = self.player.step(self.poses.index_of(self.controls.t_s), len(self.poses.times_s))
        with self.state:
            self.state.fly_t_s = float(self.poses.times_s[index])

    def _schedule(self, delay_s: float) -> None:
        self._cancel_timer()
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no event loop (tests): the caller ticks
            return
        if loop.is_running():
            self._timer = loop.call_later(delay_s, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        self.tick()

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None


def track_text(estimate: FrameEstimate) -> str:
    """The readout of a tracked frame: its errors and how it was registered, or lost."""
    if estimate.lost:
        return f"Pose track: lost at this frame ({estimate.method}); the next starts again"
    return (
        f"Pose track: rotation error {estimate.rotation_error_deg:.2f}°, translation error "
        f"{100 * estimate.translation_error_m:.1f} cm ({estimate.method}, "
        f"{estimate.seconds:.2f} s)"
    )
