"""The point cloud's payload: points in the display frame, coloured by range, SNR, kind, range
error against the ground truth, or the target part each came from."""

from __future__ import annotations

import numpy as np

import simcore
from app.payloads import encode
from app.payloads.scene3d import DisplayFrame
from app.payloads.style import (
    ERROR_CMAP,
    OUTLIER_COLOR,
    PART_CMAP,
    PINNED_POINT_COLOR,
    RANGE_CMAP,
    SNR_CMAP,
    TARGET_POINT_COLOR,
    colorbar,
)


def points_mesh(points_d: np.ndarray, rgb: np.ndarray) -> dict:
    """vtk.js mesh state of coloured points, one vertex cell per point.

    An empty set becomes one point at the origin: the view hides it (see ``views3d``).
    """
    if len(points_d) == 0:
        points_d, rgb = np.zeros((1, 3)), np.zeros((1, 3), np.uint8)
    n = len(points_d)
    verts = encode.compact_indices(np.concatenate([[n], np.arange(n)]))
    return {
        "mesh": {
            "points": encode.typed_array(np.asarray(points_d, dtype=np.float32)),
            "verts": encode.typed_array(verts),
        },
        "field": encode.rgb_field(rgb),
    }


def point_colors(result: simcore.Result, target: np.ndarray, color_by: str):
    """(n_target, 3) uint8 colours of the target points and the colour bar describing them."""
    attrs = result.attributes
    n = int(target.sum())
    if color_by == "outlier" or n == 0:
        rgb = np.tile(np.array(encode.rgb_of(TARGET_POINT_COLOR), np.uint8), (n, 1))
        return rgb, None
    if color_by == "range_error":
        return _error_colors(attrs["range_error_m"][target])
    if color_by == "part":
        return _part_colors(result, attrs["part_id"][target])
    if color_by == "snr":
        values = np.log10(np.maximum(attrs["snr"][target], 1e-12))
        lo, hi = float(values.min()), float(values.max())
        bar = colorbar("SNR", SNR_CMAP, f"{10**lo:.3g}", f"{10**hi:.3g}")
        return encode.colors_of(encode.normalized(values, lo, hi), SNR_CMAP), bar
    values = attrs["range_m"][target]
    lo, hi = float(values.min()), float(values.max())
    bar = colorbar("Range", RANGE_CMAP, f"{lo:.2f} m", f"{hi:.2f} m")
    return encode.colors_of(encode.normalized(values, lo, hi), RANGE_CMAP), bar


def _error_colors(error_m: np.ndarray):
    """Colours of the points' range errors (measured minus true) on a diverging map symmetric
    about zero, spanning the 95th percentile of |error| (at least 1 mm)."""
    finite = np.abs(error_m[np.isfinite(error_m)])
    span_m = max(float(np.percentile(finite, 95.0)) if len(finite) else 0.0, 1e-3)
    bar = colorbar(
        "Range error (measured - true)",
        ERROR_CMAP,
        f"-{1e3 * span_m:.3g} mm",
        f"+{1e3 * span_m:.3g} mm",
    )
    return encode.colors_of(encode.normalized(error_m, -span_m, span_m), ERROR_CMAP), bar


def _part_colors(result: simcore.Result, part_id: np.ndarray):
    """Colours of the points' target parts, one of PART_CMAP's 20 each; the bar names how many
    parts the points come from (the materials panel names them)."""
    lut = encode.colormap_lut(PART_CMAP)
    slot = (np.maximum(part_id, 0) % 20) * 256 // 20 + 6  # the middle of each of the 20 colours
    n_parts = len(np.unique(part_id[part_id >= 0]))
    names = result.target.part_names
    bar = colorbar("Part", PART_CMAP, f"{n_parts} of {len(names)} parts", "(one colour each)")
    return lut[slot], bar


def cloud_view(result: simcore.Result, frame: DisplayFrame, color_by: str) -> dict:
    """Everything the point cloud view draws: target points, outliers, colour bar, counts."""
    pose = result.hits.pose
    points_d = frame.from_sensor(result.points, pose.rotation, pose.translation_m)
    outlier = np.asarray(result.attributes["is_outlier"], dtype=bool)
    target = ~outlier
    rgb, bar = point_colors(result, target, color_by)
    red = np.array(encode.rgb_of(OUTLIER_COLOR), np.uint8)
    return {
        "points": points_mesh(points_d[target], rgb),
        "outliers": points_mesh(points_d[outlier], np.tile(red, (int(outlier.sum()), 1))),
        "n_target": int(target.sum()),
        "n_outliers": int(outlier.sum()),
        "colorbar": bar,
    }


def pinned_cloud(result: simcore.Result, frame: DisplayFrame) -> dict:
    """Every point of ``result`` (target points and outliers), (n, 3) in the display frame [m],
    in one pale colour: a pinned frame's cloud, which the view draws faintly under the new one."""
    pose = result.hits.pose
    points_d = frame.from_sensor(result.points, pose.rotation, pose.translation_m)
    rgb = np.tile(np.array(encode.rgb_of(PINNED_POINT_COLOR), np.uint8), (len(points_d), 1))
    return points_mesh(points_d, rgb)
