"""The "Attitudes" panel: a map of imaging quality over every attitude of the current scene,
computed coarse to fine at a light preset off the UI thread, a child of the app's logic.

The map is ``simcore.atlas.map_levels`` of the scene at the light preset (``light_scene``: at
most ``LIGHT_PIXELS`` pixels a side and the interactive fidelity preset, the scene's other
settings as they are) over the nested grids ``LEVELS_DEG``; each level goes to the page as soon
as it is done. It runs in a runner of its own (``app.runner.Runner``: one worker thread, the
newest request wins), through a Pipeline that takes the engine's loaded target (its mesh and
ray-casting structure, read-only). The map does not depend on the pitch and azimuth: moving
them (a click on a cell does) keeps the map and moves its mark; any other change makes a new
scene, which stops the map under way (its ``should_stop``) and clears the one shown: a map is
never shown for another scene than its own.

Within the session's frame budget: the light scene's frame must fit the engine's memory budget
(``app.engine.check_memory``), the first attitude's records the receiver's (``check_budget``),
and that first frame must take at most ``MAX_FRAME_S``; otherwise the map is refused with a
message that says why (the command line's ``lmapd atlas`` has no such limit).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import simcore
from app.engine import FrameRefused, check_budget, check_memory
from app.payloads.attitudes import MAP_METRICS, attitude_figure
from app.runner import Outcome, Runner, StaleRequest
from simcore.atlas import AtlasError, Level, map_levels
from simcore.stage import Cancelled

LIGHT_PIXELS = 32  # [px] the light preset's largest array side
LIGHT_PRESET = "interactive"  # its fidelity preset
LEVELS_DEG = (90.0, 45.0, 22.5, 11.25)  # [deg] 6, then 26, 114 and 482 attitudes
MAX_FRAME_S = 1.0  # [s] one attitude's frame at the light preset, at most (482 of them)
DEFAULT_METRIC = "n_target_points"
STATE_KEYS = ("attitudes_metric",)  # what a page may set (and ``attitudes_message``, cleared)


def light_scene(scene: simcore.Scene) -> simcore.Scene:
    """``scene`` at the map's light preset, its attitude at pitch and azimuth 0 (the map's key:
    two scenes that differ only in their attitude have the same map)."""
    return simcore.with_overrides(
        scene,
        {
            "pixels": min(scene.detector.pixels, LIGHT_PIXELS),
            "preset": LIGHT_PRESET,
            "pitch_deg": 0.0,
            "azimuth_deg": 0.0,
        },
    )


@dataclass(frozen=True)
class MapRequest:
    """One map to compute: the scene at the light preset, and its epoch (see AttitudeMap)."""

    scene: simcore.Scene
    epoch: int


@dataclass(frozen=True)
class MapDone:
    """A map finished: its epoch, attitudes and seconds."""

    epoch: int
    n_attitudes: int
    seconds: float


class AttitudeMap:
    """The panel on a trame state (keys ``attitudes_*``) and its triggers.

    The parent hands in the engine (a callable: it changes with the target), a way to run a call
    on the UI thread, and calls :meth:`scene_changed` with every scene it submits; a click on a
    cell writes the pitch and azimuth to the state, whose change handlers compute the frame.
    """

    def __init__(
        self,
        server,
        engine_of: Callable[[], Any],
        on_ui_thread: Callable[..., None],
        levels_deg: tuple[float, ...] = LEVELS_DEG,
        max_frame_s: float = MAX_FRAME_S,
    ):
        self.state = server.state
        self.engine_of = engine_of
        self.on_ui_thread = on_ui_thread
        self.levels_deg = tuple(levels_deg)
        self.max_frame_s = max_frame_s
        self.scene: simcore.Scene | None = None  # the newest scene the frames were asked for
        self.epoch = 0  # advanced by every start and every new scene: older maps stop
        self.map_scene: simcore.Scene | None = None  # the light scene of the map shown
        self.level: Level | None = None
        self.first_level_s: float | None = None  # seconds from the click to the first level
        self._started_s = 0.0
        self._generation = 0  # the runner's generation of the newest map
        self._pipeline = simcore.Pipeline()  # the worker thread's only
        self.runner: Runner[MapRequest, MapDone] = Runner(
            self._compute,
            self._deliver,
            debounce_s=0.0,
            name="lmapd-attitudes",
            refusals=(FrameRefused, AtlasError, simcore.SceneError),
        )
        self.state.update(
            {
                "attitudes_metric": DEFAULT_METRIC,
                "attitudes_metrics": [{"title": t, "value": k} for k, t in MAP_METRICS.items()],
                "attitudes_map": None,
                "attitudes_busy": False,
                "attitudes_status": "",
                "attitudes_message": "",
            }
        )
        self.state.change("attitudes_metric")(self.on_metric_change)
        server.trigger("attitudes_compute")(self.compute)
        server.trigger("attitudes_stop")(self.stop)
        server.trigger("attitudes_click")(self.on_cell_click)
        server.controller.on_server_exited.add(lambda **_: self.runner.close())

    # -- the parent's calls ----------------------------------------------------------------------
    def scene_changed(self, scene: simcore.Scene) -> None:
        """A new scene for the frames: the mark follows its attitude; a scene with another map
        stops the map under way and clears the one shown."""
        self.scene = scene
        key = self._key(scene)
        if self.map_scene is not None and key != self.map_scene:
            self._drop("The map was of the scene before this one: compute it again for this one.")
        elif self.level is not None:
            self._draw()

    # -- triggers --------------------------------------------------------------------------------
    def compute(self, *_: Any, **__: Any) -> None:
        """The panel's button: map the current scene, coarse to fine (the page sees each level
        as it is done)."""
        if self.scene is None:
            self.state.attitudes_message = "Attitudes: no scene yet"
            return
        if self.scene.pose.quaternion_wxyz:
            self.state.attitudes_message = (
                "Attitudes: the map is over pitch and azimuth; the fly-around sets its attitude "
                "from the orbit. Switch to Single frame to map the scene."
            )
            return
        key = self._key(self.scene)
        self.epoch += 1
        self.map_scene = key
        self.level = None
        self.first_level_s = None
        self._started_s = time.perf_counter()
        with self.state:
            self.state.update(
                {
                    "attitudes_map": None,
                    "attitudes_busy": True,
                    "attitudes_message": "",
                    "attitudes_status": f"Computing the {self.levels_deg[0]:g}° grid…",
                }
            )
        self._generation = self.runner.submit(MapRequest(key, self.epoch))

    def compute_for_lesson(self) -> None:
        """A lesson's map: the current scene's, in target points (what its card describes)."""
        self.state.attitudes_metric = DEFAULT_METRIC
        self.compute()

    def stop(self, *_: Any, **__: Any) -> None:
        """Stop the map under way; the levels done stay on the page."""
        if not self.state.attitudes_busy:
            return
        self.epoch += 1
        with self.state:
            self.state.attitudes_busy = False
            self.state.attitudes_status = self._status(done=False, stopped=True)

    def on_cell_click(self, *args: Any, **__: Any) -> None:
        """A click on a cell (its (pitch_deg, azimuth_deg): -90 to 90, -180 to 360): the pose
        sliders go there (their change handlers compute the frame). Anything else is ignored."""
        cell = args[0] if len(args) == 1 and isinstance(args[0], list | tuple) else args
        if len(cell) != 2 or not all(_is_number(x) for x in cell):
            return
        pitch, azimuth = (float(x) for x in cell)
        if abs(pitch) > 90.0 or not -180.0 <= azimuth <= 360.0:
            return
        azimuth = azimuth - 360.0 if azimuth > 180.0 else azimuth
        with self.state:
            self.state.update({"pitch_deg": pitch, "azimuth_deg": azimuth})

    def on_metric_change(self, **_: Any) -> None:
        """The chooser: the map drawn in another metric (one of MAP_METRICS; else the default)."""
        metric = self.state.attitudes_metric
        if not isinstance(metric, str) or metric not in MAP_METRICS:
            self.state.attitudes_metric = DEFAULT_METRIC
            return
        self._draw()

    # -- the map ---------------------------------------------------------------------------------
    def _key(self, scene: simcore.Scene) -> simcore.Scene:
        return light_scene(scene)

    def _compute(self, request: MapRequest) -> MapDone:
        """In the map's worker thread: every level of ``request``'s map, each posted to the UI
        thread as it is done; stops (StaleRequest) once its epoch is not the newest."""
        pipe = self._pipeline
        pipe.adopt(self.engine_of().pipeline, stages=("target",), scene=request.scene)
        start = time.perf_counter()

        def stale() -> bool:
            return request.epoch != self.epoch

        self._preflight(request.scene, stale)
        n = 0
        try:
            for level in map_levels(request.scene, self.levels_deg, pipe, should_stop=stale):
                n = len(level.grid)
                self.on_ui_thread(self._show_level, request.epoch, level)
        except Cancelled:
            raise StaleRequest from None
        return MapDone(request.epoch, n, time.perf_counter() - start)

    def _preflight(self, scene: simcore.Scene, stale: Callable[[], bool]) -> None:
        """The map's poles first (every grid has them; map_levels finds the last one cached),
        within the session's budget: memory, the receiver's records, and ``max_frame_s`` (the
        north pole's frame is timed only when the south pole's took longer: a process's first
        frame at the light preset may include compiling its kernels)."""
        engine = self.engine_of()
        for pitch in (-90.0, 90.0):
            frame = simcore.with_overrides(scene, pitch_deg=pitch, azimuth_deg=0.0)
            check_memory(frame, engine.frame_budget_bytes)

            def should_stop(frame: simcore.Scene = frame) -> bool:
                check_budget(self._pipeline, frame)
                return stale()

            t0, cpu0 = time.perf_counter(), time.process_time()
            try:
                self._pipeline.run(frame, should_stop=should_stop)
            except Cancelled:
                raise StaleRequest from None
            # its cost: the wall time, or the process's CPU time where other processes slowed
            # it (a busy machine must not refuse a light scene)
            took_s = min(time.perf_counter() - t0, time.process_time() - cpu0)
            if took_s <= self.max_frame_s:
                return
        raise FrameRefused(
            f"one attitude of this scene takes {took_s:.1f} s at the map's light preset "
            f"(at most {self.max_frame_s:g} s here; the finest grid has hundreds): lower "
            "the settings that make a frame heavy, or map it with lmapd atlas"
        )

    def _deliver(self, outcome: Outcome[MapDone]) -> None:
        self.on_ui_thread(self._finish, outcome)

    def _show_level(self, epoch: int, level: Level) -> None:
        """On the UI thread: draw a level of the newest map (an older map's is dropped)."""
        if epoch != self.epoch:
            return
        if self.first_level_s is None:
            self.first_level_s = time.perf_counter() - self._started_s
        self.level = level
        with self.state:
            self._draw()
            self.state.attitudes_status = self._status(done=False)

    def _finish(self, outcome: Outcome[MapDone]) -> None:
        """On the UI thread: the map is done, or refused, or failed (its message, no trace)."""
        if outcome.generation != self._generation or not self.state.attitudes_busy:
            return  # an older map's, or one stopped or dropped meanwhile
        if outcome.value is not None and outcome.value.epoch != self.epoch:
            return
        with self.state:
            self.state.attitudes_busy = False
            if outcome.ok:
                self.state.attitudes_status = self._status(done=True)
                return
            error = outcome.error
            self.map_scene = None if self.level is None else self.map_scene
            if isinstance(error, ValueError):  # refused: FrameRefused, AtlasError, SceneError
                self.state.attitudes_message = f"Attitudes refused: {error}"
            else:
                name = type(error).__name__
                self.state.attitudes_message = f"Attitudes: the map failed ({name}: {error})"
            self.state.attitudes_status = self._status(done=False, stopped=True)

    def _drop(self, message: str) -> None:
        """Stop the map under way and clear the one shown."""
        self.epoch += 1
        self.map_scene = None
        self.level = None
        with self.state:
            self.state.update(
                {
                    "attitudes_map": None,
                    "attitudes_busy": False,
                    "attitudes_status": "",
                    "attitudes_message": message,
                }
            )

    def _draw(self) -> None:
        if self.level is None:
            return
        current = None
        if self.scene is not None and not self.scene.pose.quaternion_wxyz:
            current = (self.scene.pose.pitch_deg, self.scene.pose.azimuth_deg)
        self.state.attitudes_map = attitude_figure(
            self.level.grid, self.level.rows, self.state.attitudes_metric, current
        )

    def _status(self, done: bool, stopped: bool = False) -> str:
        """What the panel says of the map: its grid, the cells' solid angle, what comes next."""
        level = self.level
        if level is None:
            return "Stopped before the first grid." if stopped else ""
        grid = level.grid
        pixels = self.map_scene.detector.pixels if self.map_scene is not None else LIGHT_PIXELS
        text = (
            f"{grid.step_deg:g}° grid, {len(grid)} attitudes at {pixels} × {pixels} px "
            f"({LIGHT_PRESET} preset); a cell at the equator spans "
            f"{grid.solid_angle_sr(0.0):.3g} sr"
        )
        if self.first_level_s is not None:
            text += f"; first grid in {self.first_level_s:.1f} s"
        if done:
            return text + "."
        if stopped:
            return text + "; stopped."
        finer = [s for s in self.levels_deg if s < grid.step_deg]
        return text + (f"; refining to {finer[0]:g}°…" if finer else ".")


def _is_number(value: Any) -> bool:
    """A finite int or float (not a bool, not a string)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an int too large for a float
        return False
