"""One attitude of an atlas, as a worker runs it: the frame and its quality figures, one row."""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

import numpy as np

from ..pipeline import Pipeline, Result
from ..scene import Scene
from ..sweep.frames import FrameOutcome, _error_text, _worker_pipeline
from ..sweep.spec import METRICS as SWEEP_METRICS

# The figures a map can show: name -> (column, label with its unit, which way is better:
# "high", "low" or "small": the smaller magnitude). The columns hold None where the figure
# has no sample (no target point, nothing seen).
METRICS: dict[str, tuple[str, str, str]] = {
    "f_score": ("quality.f_score", "F-score at tau [-]", "high"),
    "precision": ("quality.precision", "precision at tau [-]", "high"),
    "recall": ("quality.recall", "recall at tau [-]", "high"),
    "recall_projected": ("quality.recall_projected", "projected-area recall at tau [-]", "high"),
    "recall_cap": ("quality.recall_cap", "recall cap of an ideal lidar at tau [-]", "high"),
    "range_bias_m": ("quality.range_bias_m", "median range error [m]", "small"),
    "range_rmse_m": ("quality.range_rmse_m", "RMS range error [m]", "low"),
    "n_points": ("n_points", "points of the cloud [-]", "high"),
    "n_target_points": ("n_target_points", "target points [-]", "high"),
    "seen_area_m2": ("seen_area_m2", "seen area [m^2]", "high"),
    "n_lit_pixels": ("n_lit_pixels", "lit pixels [-]", "high"),
    "point_density_per_m2": (
        "quality.point_density_per_m2",
        "target points per m^2 [1/m^2]",
        "high",
    ),
}
DEFAULT_METRIC = "f_score"

# the row's figures: name, Arrow type, meaning (units in the names)
COLUMNS = (
    # n_pixels, n_hit_pixels, n_lit_pixels, n_points, n_target_points, n_outliers: a sweep's
    *SWEEP_METRICS[:6],
    (
        "quality.precision",
        "float64",
        "share of target points within tau of the mesh; none if no point",
    ),
    (
        "quality.recall",
        "float64",
        "share of the seen surface within tau of a point; none if none seen",
    ),
    ("quality.f_score", "float64", "harmonic mean of precision and recall (0 if seen, no point)"),
    ("quality.recall_projected", "float64", "recall weighted by projected area (|cos incidence|)"),
    ("quality.recall_cap", "float64", "recall of an ideal lidar with these pixels (its ceiling)"),
    ("quality.range_bias_m", "float64", "median signed range error of the target points [m]"),
    ("quality.range_rmse_m", "float64", "RMS range error of the target points [m]"),
    ("quality.range_error_p95_m", "float64", "95th percentile of |range error| [m]"),
    ("quality.point_density_per_m2", "float64", "target points per m^2 of seen surface"),
    ("seen_area_m2", "float64", "area of the target the lidar sees (in view, not hidden) [m^2]"),
    ("snr_median", "float64", "median SNR of the lit pixels"),
    ("range_sigma_m_median", "float64", "median range sigma of the detected pixels [m]"),
    ("view_x", "float64", "unit direction from the target to the lidar, body frame, x"),
    ("view_y", "float64", "unit direction from the target to the lidar, body frame, y"),
    ("view_z", "float64", "unit direction from the target to the lidar, body frame, z"),
    ("dominant_part", "string", "the part that gives the most target points (none: no point)"),
    ("dominant_material", "string", "the material that gives the most target points"),
)


def metric_values(table, metric: str) -> np.ndarray:
    """(n,) float64 values of ``metric`` in an atlas table (NaN where it has none, or the
    attitude failed or is not done)."""
    column = METRICS[metric][0]
    return np.array([np.nan if v is None else float(v) for v in table.column(column).to_pylist()])


def attitude_row(result: Result) -> dict[str, Any]:
    """The atlas row of one frame (COLUMNS); None where a figure has no sample."""
    s = result.summary()
    q = s["quality"]
    seen = q["n_surface_samples"] > 0
    has_points = s["n_target_points"] > 0
    row: dict[str, Any] = {k: int(s[k]) for k, t, _ in COLUMNS if t == "int64"}
    row["quality.precision"] = q["precision"] if has_points else None
    row["quality.recall"] = q["recall"] if seen else None
    row["quality.f_score"] = q["f_score"] if seen else None
    row["quality.recall_projected"] = q["recall_projected"] if seen else None
    row["quality.recall_cap"] = q.get("recall_cap") if seen else None
    for name in ("range_bias_m", "range_rmse_m", "range_error_p95_m"):
        row[f"quality.{name}"] = q[name]
    row["quality.point_density_per_m2"] = q["point_density_per_m2"] if seen else None
    row["seen_area_m2"] = q["seen_area_m2"]
    row["snr_median"] = s["snr_median"]
    row["range_sigma_m_median"] = s["range_sigma_m_median"]
    row.update(zip(("view_x", "view_y", "view_z"), view_direction_body(result), strict=True))
    row["dominant_part"], row["dominant_material"] = _dominant(result)
    return row


def view_direction_body(result: Result) -> tuple[float, float, float]:
    """The unit direction from the target's origin to the lidar in the target's body frame."""
    pose = result.hits.pose
    to_lidar_mesh = -pose.rotation.T @ pose.translation_m
    to_lidar_body = np.asarray(result.target.body_from_mesh) @ to_lidar_mesh
    unit = to_lidar_body / np.linalg.norm(to_lidar_body)
    return float(unit[0]), float(unit[1]), float(unit[2])


def _dominant(result: Result) -> tuple[str | None, str | None]:
    """The part and the material that give the most target points (None, None: no point)."""
    attrs = result.cloud.attributes
    target = ~np.asarray(attrs["is_outlier"], dtype=bool)
    parts = np.asarray(attrs["part_id"])[target]
    if not len(parts):
        return None, None
    model = result.target
    counts = np.bincount(parts, minlength=len(model.part_names))
    by_material: Counter[str] = Counter()
    for p, n in enumerate(counts):
        by_material[model.part_materials[p]] += int(n)
    return model.part_names[int(np.argmax(counts))], by_material.most_common(1)[0][0]


def run_attitude(scene: Scene, pipeline: Pipeline, want_cloud: bool = False) -> FrameOutcome:
    """Simulate one attitude; never raises (an error becomes the outcome's ``error`` text)."""
    start = time.perf_counter()
    try:
        row = attitude_row(pipeline.run(scene))
        return FrameOutcome(row, None, time.perf_counter() - start)
    except Exception as exc:  # a failed attitude is recorded; the atlas goes on
        pipeline.clear()  # a half-updated cache is not trusted
        return FrameOutcome(None, _error_text(exc), time.perf_counter() - start)


def _attitude_task(scene: Scene, want_cloud: bool = False) -> FrameOutcome:
    """The Dask task: one attitude through this worker thread's Pipeline (the target and its BVH
    loaded once per worker)."""
    return run_attitude(scene, _worker_pipeline())
