"""Evaluating designs over the envelope: each point a frame through a Pipeline kept for that point,
so that a design that changes only the TNR re-runs only detection and the cloud there; in this
process, or on Dask workers (each point sent to the same worker every time)."""

from __future__ import annotations

import math
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..parallel import set_threads
from ..pipeline import STAGES, Pipeline
from ..scene import Scene, SceneError, with_overrides
from .study import Study, StudyError

PROBE_PIXELS = 8  # the tiny frame that lists the figures a study may require


@dataclass(frozen=True)
class PointOutcome:
    """One envelope point of one design: its figures (flat, dotted names) or an error, which
    stages ran and which came from the point's cache, and the wall time [s]."""

    figures: dict[str, float] | None
    error: str | None
    computed: tuple[str, ...] = ()
    reused: tuple[str, ...] = ()
    frame_s: float = math.nan


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


def run_point(scene: Scene, pipeline: Pipeline, quality: bool) -> PointOutcome:
    """One frame through ``pipeline``; never raises (an error becomes the outcome's text)."""
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
    return PointOutcome(figures, None, computed, reused, time.perf_counter() - start)


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


def _point_task(scene: Scene, slot: int, quality: bool) -> PointOutcome:
    """The Dask task: one envelope point through this worker's Pipeline for it."""
    return run_point(scene, _point_pipeline(slot), quality)


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
    (key, point, PointOutcome) as they finish. In this process (``client`` None) or on Dask."""

    def __init__(self, client=None, quality: bool = True):
        self.client = client
        self.quality = quality
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
                yield key, point, run_point(scene, pipe, self.quality)
            return
        yield from self._dask(jobs)

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
    first envelope point for each receiver the study can select."""
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
    return names


def check_figures(study: Study) -> None:
    """Every requirement names a figure the summary has: one StudyError naming the first one
    that is not, with the nearest names."""
    import difflib  # noqa: PLC0415

    names = known_figures(study)
    for req in study.requirements:
        if req.figure not in names:
            near = difflib.get_close_matches(req.figure, sorted(names), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(near)}?" if near else ""
            raise StudyError(
                f"{study.source} [requirements]: {req.figure!r} is not a summary figure{hint}"
            )
