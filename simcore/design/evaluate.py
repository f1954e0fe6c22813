"""Evaluating designs over the envelope: each point a frame through a Pipeline kept for that point,
so that a design that changes only the TNR re-runs only detection and the cloud there; in this
process, or on Dask workers (each point sent to the same worker every time).

A study that tracks (``Study.tracks``, ``design.study``) has the trajectory's frames as its
points: each point's outcome brings its cloud back, and once a design's points are all in,
:meth:`Evaluator.track` registers each track's clouds in time order (``simcore.tracking.track``,
in this process: each frame is seeded by the one before) and adds the frame's track figures
(``TRACK_FIGURES``) to its figures, a lost frame's errors infinite."""

from __future__ import annotations

import dataclasses
import math
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..parallel import set_threads
from ..pipeline import STAGES, Pipeline
from ..scene import Scene, SceneError, with_overrides
from .study import Study, StudyError, Track

PROBE_PIXELS = 8  # the tiny frame that lists the figures a study may require
_MODELS_KEPT = 4  # targets whose model points a study that tracks keeps sampled
# a frame's figures of a pose track (a study that tracks): its errors against the truth
# (infinite where the frame is lost), whether it is lost (0 or 1), the share of its track's
# frames lost, and the registration's fitness
TRACK_FIGURES = (
    "track.rotation_error_deg",
    "track.translation_error_m",
    "track.lost",
    "track.lost_fraction",
    "track.fitness",
)


@dataclass(frozen=True)
class PointOutcome:
    """One envelope point of one design: its figures (flat, dotted names) or an error, which
    stages ran and which came from the point's cache, and the wall time [s]."""

    figures: dict[str, float] | None
    error: str | None
    computed: tuple[str, ...] = ()
    reused: tuple[str, ...] = ()
    frame_s: float = math.nan
    points_m: Any = None  # (n, 3) the cloud's points [m, sensor frame], for a track only


def flat_figures(summary: Mapping[str, Any], prefix: str = "") -> dict[str, float]:
    """The numeric figures of a summary, nested ones under dotted names (``quality.recall``);
    None becomes NaN; lists, strings, the scene and the timings are left out."""
    out: dict[str, float] = {}
    for key, value in summary.items():
        if key in ("scene", "timings_s", "target", "material_names"):
            continue
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flat_figures(value, f"{name}."))
        elif value is None:
            out[name] = math.nan
        elif isinstance(value, bool):
            out[name] = float(value)
        elif isinstance(value, (int, float)):
            out[name] = float(value)
    return out


def run_point(
    scene: Scene, pipeline: Pipeline, quality: bool, keep_cloud: bool = False
) -> PointOutcome:
    """One frame through ``pipeline``; never raises (an error becomes the outcome's text).
    ``keep_cloud``: the outcome holds the cloud's points (for a track)."""
    start = time.perf_counter()
    try:
        result = pipeline.run(scene)
        figures = flat_figures(result.summary(quality=quality))
    except Exception as exc:
        pipeline.clear()  # a half-updated cache is not trusted
        return PointOutcome(
            None, f"{type(exc).__name__}: {exc}", frame_s=time.perf_counter() - start
        )
    computed = tuple(s for s in STAGES if result.timings_s.get(s, 0.0) > 0.0)
    reused = tuple(s for s in STAGES if s not in computed)
    points = result.cloud.points if keep_cloud else None
    return PointOutcome(figures, None, computed, reused, time.perf_counter() - start, points)


_LOCAL = threading.local()  # per worker thread: one Pipeline per envelope point


def _point_pipeline(slot: int) -> Pipeline:
    pipes = getattr(_LOCAL, "pipelines", None)
    if pipes is None:
        set_threads(1)  # the workers run side by side, one frame per core (as a sweep's)
        pipes = _LOCAL.pipelines = {}
    if slot not in pipes:
        pipes[slot] = _new_pipeline(pipes)
    return pipes[slot]


def _new_pipeline(pipes: dict[int, Pipeline]) -> Pipeline:
    """A Pipeline for another envelope point, sharing the target (mesh and BVH) already loaded
    for the others of this thread."""
    pipe = Pipeline()
    if pipes:
        pipe.adopt(next(iter(pipes.values())), ("target", "rays"))
    return pipe


def _point_task(scene: Scene, slot: int, quality: bool, keep_cloud: bool = False) -> PointOutcome:
    """The Dask task: one envelope point through this worker's Pipeline for it."""
    return run_point(scene, _point_pipeline(slot), quality, keep_cloud)


@dataclass
class StageTally:
    """Stages computed and taken from the cache over a study, per stage."""

    computed: Counter = field(default_factory=Counter)
    reused: Counter = field(default_factory=Counter)

    def add(self, outcome: PointOutcome) -> None:
        self.computed.update(outcome.computed)
        self.reused.update(outcome.reused)

    def line(self) -> str:
        parts = [f"{s} {self.reused[s]}/{self.computed[s] + self.reused[s]}" for s in STAGES]
        return "stages reused from the cache (reused/frames): " + ", ".join(parts)

    def as_dict(self) -> dict[str, dict[str, int]]:
        return {s: {"computed": self.computed[s], "reused": self.reused[s]} for s in STAGES}


class Evaluator:
    """Runs envelope points: ``evaluate(jobs)`` with jobs (key, scene, point index) yields
    (key, point, PointOutcome) as they finish. In this process (``client`` None) or on Dask.
    ``track``: the outcomes keep their clouds, for :meth:`track`."""

    def __init__(self, client=None, quality: bool = True, track: bool = False):
        self.client = client
        self.quality = quality
        self.keep_clouds = track
        self._models: dict[str, tuple[Any, Any]] = {}  # target -> (TargetModel, ModelCloud)
        self._pipes: dict[int, Pipeline] = {}
        self._workers: list[str] = []
        if client is not None:
            self._workers = sorted(client.scheduler_info()["workers"])

    @property
    def n_workers(self) -> int:
        return len(self._workers)

    def evaluate(self, jobs: Sequence[tuple[Any, Scene, int]]) -> Iterator:
        if self.client is None:
            for key, scene, point in jobs:
                if point not in self._pipes:
                    self._pipes[point] = _new_pipeline(self._pipes)
                pipe = self._pipes[point]
                yield key, point, run_point(scene, pipe, self.quality, self.keep_clouds)
            return
        yield from self._dask(jobs)

    def track(
        self,
        study: Study,
        params: Mapping[str, Any],
        preset: str,
        outcomes: dict[int, PointOutcome],
    ) -> dict[int, PointOutcome]:
        """A design's outcomes (by envelope point) with each frame's TRACK_FIGURES added, its
        track registered as ``simcore.tracking.track`` registers a fly-around's clouds, and
        the registration's time added to the frame's; the clouds dropped. A track with a
        failed frame is left as it is (the failure fails the design)."""
        out = dict(outcomes)
        for tr in study.tracks:
            frames = [outcomes[p] for p in tr.points]
            if any(o.error is not None or o.points_m is None for o in frames):
                continue
            scene = study.scene(params, tr.points[0], preset)
            result = self._track_one(scene, tr, frames)
            lost_fraction = float(np.mean(result.lost))
            for k, (p, o) in enumerate(zip(tr.points, frames, strict=True)):
                lost = bool(result.lost[k])
                figures = {
                    **(o.figures or {}),
                    "track.rotation_error_deg": math.inf
                    if lost
                    else float(result.rotation_error_deg[k]),
                    "track.translation_error_m": math.inf
                    if lost
                    else float(result.translation_error_m[k]),
                    "track.lost": float(lost),
                    "track.lost_fraction": lost_fraction,
                    "track.fitness": float(result.fitness[k]),
                }
                out[p] = dataclasses.replace(
                    o,
                    figures=figures,
                    frame_s=o.frame_s + float(result.registration_s[k]),
                    points_m=None,
                )
        return {p: dataclasses.replace(o, points_m=None) for p, o in out.items()}

    def _track_one(self, scene: Scene, tr: Track, frames: Sequence[PointOutcome]):
        """The TrackResult of one track's frames: the truth as ``run_flyaround`` makes it
        (the condition's Sun at the frames' times), the model's points sampled once per
        target."""
        from .. import sun, tracking, trajectory  # noqa: PLC0415  (the registration library)
        from ..pointcloud import PointCloud  # noqa: PLC0415
        from ..target import load_target  # noqa: PLC0415

        key = repr(scene.target)
        if key not in self._models:
            if len(self._models) >= _MODELS_KEPT:  # a target variable: a few targets at a time
                self._models.pop(next(iter(self._models)))
            model = load_target(scene.target)
            self._models[key] = (model, tracking.model_points(model))
        model, cloud_model = self._models[key]
        suns = sun.orbit_sun_geometry(scene, tr.pose.t_s, j2=tr.j2)
        truth = trajectory.ground_truth(scene, tr.pose, np.array([g.direction_body for g in suns]))
        clouds = [PointCloud(points=np.asarray(o.points_m), attributes={}) for o in frames]
        return tracking.track(clouds, model, truth, cloud_model=cloud_model)

    def _dask(self, jobs):
        from distributed import as_completed  # noqa: PLC0415  (slow import)

        run = uuid.uuid4().hex[:8]
        by_key, futures = {}, []
        for i, (key, scene, point) in enumerate(jobs):
            fut = self.client.submit(
                _point_task,
                scene,
                point,
                self.quality,
                self.keep_clouds,
                key=f"lmapd-design-{run}-{i}",
                workers=[self._workers[point % len(self._workers)]],
                allow_other_workers=True,  # a lost worker's points go elsewhere
                pure=False,
            )
            by_key[fut.key] = (key, point)
            futures.append(fut)
        try:
            done = as_completed(
                futures, loop=self.client.loop, with_results=True, raise_errors=False
            )
            for fut, value in done:
                key, point = by_key.pop(fut.key)
                if not isinstance(value, PointOutcome):  # the task itself failed (worker lost)
                    exc = value[1] if isinstance(value, tuple) and len(value) == 3 else value
                    value = PointOutcome(None, f"{type(exc).__name__}: {exc}")
                fut.release()
                yield key, point, value
        finally:
            self.client.cancel(list(futures))


def known_figures(study: Study) -> set[str]:
    """The figures a summary of this study's designs holds: a tiny frame (PROBE_PIXELS) of the
    first envelope point for each receiver the study can select; a study that tracks adds
    TRACK_FIGURES."""
    kinds = {study.scene({}, 0).receiver.kind}
    for v in study.variables:
        if v.key == "receiver.kind":
            kinds.update(v.choices)
    names: set[str] = set()
    for kind in sorted(kinds):
        try:
            scene = with_overrides(
                study.scene({}, 0), {"receiver.kind": kind, "detector.pixels": PROBE_PIXELS}
            )
            names |= set(flat_figures(Pipeline().run(scene).summary(quality=True)))
        except SceneError as exc:
            raise StudyError(
                f"{study.source}: the base scene with receiver {kind}: {exc}"
            ) from None
    if study.tracks:
        names |= set(TRACK_FIGURES)
    return names


def check_tracks(study: Study) -> None:
    """Each track's trajectory stays outside its target (``trajectory.check_trajectory_target``,
    as ``lmapd flyaround`` refuses an approach into it): one StudyError before any trial."""
    from .. import trajectory  # noqa: PLC0415
    from ..target import load_target  # noqa: PLC0415

    for tr in study.tracks:
        scene = study.scene({}, tr.points[0])
        try:
            trajectory.check_trajectory_target(scene, load_target(scene.target).surface.radius_m)
        except SceneError as exc:
            raise StudyError(f"{study.source} [trajectory]: {exc}") from None


def check_figures(study: Study) -> None:
    """Every requirement names a figure the summary has: one StudyError naming the first one
    that is not, with the nearest names."""
    import difflib  # noqa: PLC0415

    check_tracks(study)
    names = known_figures(study)
    for req in study.requirements:
        if req.figure not in names:
            near = difflib.get_close_matches(req.figure, sorted(names), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(near)}?" if near else ""
            raise StudyError(
                f"{study.source} [requirements]: {req.figure!r} is not a summary figure{hint}"
            )
