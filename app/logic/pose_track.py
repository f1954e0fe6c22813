"""The fly-around's pose track in the app: each frame shown registered to the target's model in
the background, seeded by the estimates of the frames before it.

``PoseTrack`` is a plain object (tested without a server): ``submit`` hands it a shown frame
(its index along the fly-around, time, cloud points and true pose); one worker thread registers
it with ``simcore.tracking.track_frame``, seeded as ``simcore.tracking.track`` seeds a frame
(the one or two frames before it, when the track has them and they are not lost; else the
global registration, which does not use the truth), and scores it against the truth
(``simcore.tracking.pose_errors``). The track so far is ``estimates`` by frame index.

Stale work is dropped: a frame waiting for the worker is replaced by the next one submitted,
``moved`` (the time slider moved) drops the one waiting and marks the one under way stale, and a
stale registration's result is never kept nor delivered. A change of what the clouds depend on
(``context``: any control but the time) clears the track.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from simcore import tracking


@dataclass(frozen=True)
class FrameEstimate:
    """One tracked frame: its index and time [s], the estimated and true T_sensor_target
    (4, 4), the errors [deg], [m], whether the lost rule flags it, how it was registered and
    the registration's wall time [s]."""

    index: int
    t_s: float
    pose: np.ndarray
    truth: np.ndarray
    rotation_error_deg: float
    translation_error_m: float
    lost: bool
    method: str
    seconds: float


@dataclass(frozen=True)
class _Job:
    index: int
    t_s: float
    points_m: np.ndarray
    truth: np.ndarray
    context: Any
    model: Any
    generation: int


class PoseTrack:
    """The track of the frames shown (see the module docstring).

    ``deliver(estimate)`` is called with each kept estimate, from the worker thread (the app
    passes a callback that moves it onto its event loop). ``background=False`` registers in the
    caller's thread at ``submit`` (tests).
    """

    def __init__(self, deliver: Callable[[FrameEstimate], Any], background: bool = True):
        self.deliver = deliver
        self.background = background
        self.estimates: dict[int, FrameEstimate] = {}
        self.context: Any = None
        self.n_dropped = 0  # registrations dropped as stale (their result thrown away)
        self._sampled: tuple[Any, tracking.ModelCloud] | None = None  # (TargetModel, points)
        self._generation = 0
        self._waiting: _Job | None = None
        self._lock = threading.Condition()
        self._thread: threading.Thread | None = None
        self._closed = False

    # -- the UI thread ---------------------------------------------------------------------------
    def submit(
        self,
        index: int,
        t_s: float,
        points_m: np.ndarray,
        truth: np.ndarray,
        context: Any,
        model: Any,
    ) -> None:
        """Track frame ``index`` (at ``t_s`` [s]; its cloud's points (n, 3) [m, sensor frame];
        ``truth`` its true T_sensor_target (4, 4); ``model`` the TargetModel). A frame already
        tracked in this context is delivered again as it is, not registered anew."""
        with self._lock:
            if context != self.context:
                self.estimates.clear()
                self.context = context
            if index in self.estimates:
                known = self.estimates[index]
            else:
                known = None
                if self._waiting is not None:
                    self.n_dropped += 1
                self._waiting = _Job(
                    index, float(t_s), np.asarray(points_m), truth, context, model, self._generation
                )
                self._lock.notify()
        if known is not None:
            self.deliver(known)
            return
        if not self.background:
            self._run_waiting()
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="lmapd-pose-track", daemon=True)
            self._thread.start()

    def moved(self) -> None:
        """The time slider moved: the frame waiting is dropped, the one under way goes stale."""
        with self._lock:
            self._generation += 1
            if self._waiting is not None:
                self._waiting = None
                self.n_dropped += 1

    def clear(self) -> None:
        """Forget the track (the switch turned off, or another target)."""
        with self._lock:
            self._generation += 1
            self._waiting = None
            self.estimates.clear()
            self.context = None

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._waiting = None
            self._lock.notify()

    def series(self) -> list[FrameEstimate]:
        """The track so far, in frame order."""
        with self._lock:
            return [self.estimates[i] for i in sorted(self.estimates)]

    # -- the worker ------------------------------------------------------------------------------
    def _loop(self) -> None:
        while True:
            with self._lock:
                while self._waiting is None and not self._closed:
                    self._lock.wait()
                if self._closed:
                    return
            self._run_waiting()

    def _run_waiting(self) -> None:
        with self._lock:
            job, self._waiting = self._waiting, None
            if job is None:
                return
            previous = self._previous(job.index)
        model = self._model(job.model)
        reg = tracking.track_frame(job.points_m, model, previous, job.t_s)
        rot_deg, tra_m = tracking.pose_errors(reg.pose, job.truth)
        estimate = FrameEstimate(
            index=job.index,
            t_s=job.t_s,
            pose=reg.pose,
            truth=np.asarray(job.truth, dtype=np.float64),
            rotation_error_deg=rot_deg,
            translation_error_m=tra_m,
            lost=tracking.is_lost(reg),
            method=reg.method,
            seconds=reg.seconds,
        )
        with self._lock:
            if job.generation != self._generation or job.context != self.context:
                self.n_dropped += 1  # the slider moved meanwhile, or the scene changed
                return
            self.estimates[job.index] = estimate
        self.deliver(estimate)

    def _previous(self, index: int) -> list[tuple[float, np.ndarray]]:
        """The seed's frames: the one or two frames just before ``index``, tracked and not lost
        (as ``tracking.track`` keeps them), in time order; none: a global registration."""
        out = []
        for i in (index - 2, index - 1):
            e = self.estimates.get(i)
            if e is None or e.lost:
                out = []  # a gap or a lost frame: the track starts again after it
                continue
            out.append((e.t_s, e.pose))
        return out

    def _model(self, target_model: Any) -> tracking.ModelCloud:
        """The model's points of ``target_model``, sampled once (one target at a time: the
        model is held, so that it is this one, not another at its address)."""
        if self._sampled is None or self._sampled[0] is not target_model:
            self._sampled = (target_model, tracking.model_points(target_model))
        return self._sampled[1]
