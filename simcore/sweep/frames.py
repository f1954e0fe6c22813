"""One frame of a sweep, as a worker runs it: the scene through a Pipeline, its metrics."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..parallel import set_threads
from ..pipeline import Pipeline, Result
from ..pointcloud import PointCloud
from ..scene import Scene
from .spec import METRICS


@dataclass(frozen=True)
class FrameOutcome:
    """What a worker sends back: metrics or an error, the wall time, the cloud if asked."""

    metrics: dict[str, Any] | None
    error: str | None
    frame_s: float
    cloud: PointCloud | None = None
    target_line: str = ""


def frame_metrics(result: Result) -> dict[str, Any]:
    """The table's metric columns (METRICS) of one frame; None where a statistic has no sample.

    SNR quantiles are over the lit pixels (``result.receiver.snr``), range sigma quantiles over
    the detected target pixels (``result.detection.range_sigma_m``) [m]; the ``quality.*``
    columns are the summary's imaging-quality figures (``simcore.quality``).
    """
    s = result.summary()
    snr = _finite(result.receiver.snr)
    sigma = _finite(result.detection.range_sigma_m[result.detection.detected])
    return {
        **{k: int(s[k]) for k, t, _ in METRICS if t == "int64"},
        "n_false_expected": float(s["n_false_expected"]),
        "n_false_crossings_expected": float(s["n_false_crossings_expected"]),
        "p_detect_mean": s["p_detect_mean"],
        "snr_p10": _quantile(snr, 0.10),
        "snr_median": _quantile(snr, 0.50),
        "snr_p90": _quantile(snr, 0.90),
        "range_sigma_m_median": _quantile(sigma, 0.50),
        "range_sigma_m_p90": _quantile(sigma, 0.90),
        **{
            name: s["quality"][name.partition(".")[2]]
            for name, _, _ in METRICS
            if name.startswith("quality.")
        },
    }


def _finite(values) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    return v[np.isfinite(v)]


def _quantile(values: np.ndarray, q: float) -> float | None:
    return float(np.quantile(values, q)) if len(values) else None


def run_frame(scene: Scene, pipeline: Pipeline, want_cloud: bool = False) -> FrameOutcome:
    """Simulate one frame; never raises (an error becomes the outcome's ``error`` text)."""
    start = time.perf_counter()
    try:
        result = pipeline.run(scene)
        metrics = frame_metrics(result)
        cloud = result.cloud if want_cloud else None
        line = f"target {result.target.name}; {result.target.credit}"
        return FrameOutcome(metrics, None, time.perf_counter() - start, cloud, line)
    except Exception as exc:  # a failed frame is recorded; the sweep goes on
        pipeline.clear()  # a half-updated cache is not trusted
        return FrameOutcome(None, _error_text(exc), time.perf_counter() - start)


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


_LOCAL = threading.local()  # per worker thread: its Pipeline (the mesh and BVH load once)


def _worker_pipeline() -> Pipeline:
    pipe = getattr(_LOCAL, "pipeline", None)
    if pipe is None:
        _one_core_per_frame()
        pipe = _LOCAL.pipeline = Pipeline()
    return pipe


def _one_core_per_frame() -> None:
    """On a Dask worker the frames run side by side, one per core: turn off the core's own
    two-thread split of the ray cast and the echo features, which would oversubscribe the cores
    (measured on 2 cores: 2 workers x 2 threads take 1.6 x as long per frame as 2 x 1).
    Results do not depend on it."""
    set_threads(1)


def _frame_task(scene: Scene, want_cloud: bool) -> FrameOutcome:
    """The Dask task: one frame through this worker thread's Pipeline."""
    return run_frame(scene, _worker_pipeline(), want_cloud)


def warm_workers(client, scene: Scene) -> float:
    """Run ``scene`` once on every worker of ``client`` (loads the mesh and BVH there).

    For benchmarks that time the sweep alone. Returns the wall time [s].
    """
    start = time.perf_counter()
    futures = [
        client.submit(_frame_task, scene, False, workers=[w], pure=False, allow_other_workers=False)
        for w in client.scheduler_info()["workers"]
    ]
    client.gather(futures)
    return time.perf_counter() - start
