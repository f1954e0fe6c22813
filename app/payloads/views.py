"""From a simcore Result to what each view draws: vtk.js meshes, the array image, the waveform
chart, the stats. Pure functions of numpy arrays; they run in the worker thread.

Both 3D views share one display frame fixed to the target: the target frame rotated so that the
zero pose (pitch = azimuth = 0) looks along the display's -Z with image-up along +Y. The target
stays put when the pose changes; the lidar's frustum and the points move around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import simcore
from app.payloads import encode
from simcore.constants import C as C_M_S
from simcore.geometry import front_view_rotation

# Material colours of the 3D scene (library names); hidden facets are grey.
MATERIAL_COLORS = {
    "ideal_diffuse": "#80deea",
    "ideal_specular": "#ce93d8",
    "solar_panel": "#3d5afe",
    "coating_1": "#ffb300",
    "coating_2": "#eceff1",
    "lambertian": "#66bb6a",
}
OTHER_MATERIAL_COLOR = "#ff8a65"
HIDDEN_COLOR = "#4a4d55"
TARGET_POINT_COLOR = "#4fc3f7"
OUTLIER_COLOR = "#ff1744"
RANGE_CMAP = "viridis"
SNR_CMAP = "viridis"
POWER_CMAP = "inferno"
NO_ECHO_RGB = (30, 30, 36)
SNR_FLOOR = 1e-2  # the SNR histogram starts here
# One colour per selected pixel: waveform traces and the markers on the array image.
SELECTION_COLORS = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#17becf",
)
# Flip of the sensor axes (x right, y down, z boresight) to the display's (x right, y up, -z view).
FLIP = np.diag([1.0, -1.0, -1.0])


# ----------------------------------------------------------------------------------------------
# the display frame and cameras
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DisplayFrame:
    """rotation : (3, 3) target frame -> display frame; radius_m : target bounding radius."""

    rotation: np.ndarray
    radius_m: float

    def from_target(self, points_t: np.ndarray) -> np.ndarray:
        """(n, 3) target-frame points [m] in the display frame."""
        return np.asarray(points_t, dtype=np.float64) @ self.rotation.T

    def from_sensor(self, points_s: np.ndarray, rotation: np.ndarray, translation_m) -> np.ndarray:
        """(n, 3) sensor-frame points [m] in the display frame, for the pose
        p_sensor = rotation @ p_target + translation_m."""
        p = np.asarray(points_s, dtype=np.float64) - np.asarray(translation_m)[None, :]
        return self.from_target(p @ rotation)


def display_frame(model: simcore.TargetModel) -> DisplayFrame:
    """The shared display frame of a target (see the module docstring)."""
    return DisplayFrame(FLIP @ front_view_rotation(model.mesh.extents), model.radius_m)


def home_camera(
    radius_m: float, azimuth_deg: float = 35.0, elevation_deg: float = 22.0
) -> dict[str, list[float]]:
    """A vtk.js camera that frames the target obliquely from the lidar's side (+Z)."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    direction = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    distance = 1.15 * radius_m / math.sin(math.radians(15.0))  # vtk.js view angle 30 deg
    return {
        "position": (direction * distance).tolist(),
        "focalPoint": [0.0, 0.0, 0.0],
        "viewUp": [0.0, 1.0, 0.0],
        "viewAngle": 30.0,
        "centerOfRotation": [0.0, 0.0, 0.0],
    }


# ----------------------------------------------------------------------------------------------
# the 3D scene: target mesh, facet colours, frustum, legend
# ----------------------------------------------------------------------------------------------
def target_geometry(model: simcore.TargetModel, frame: DisplayFrame) -> dict:
    """vtk.js points and triangle cells of the target mesh in the display frame (sent once)."""
    points = frame.from_target(model.mesh.vertices).astype(np.float32)
    return {
        "points": encode.typed_array(points),
        "polys": encode.typed_array(encode.triangle_cells(model.mesh.faces)),
    }


def material_color(name: str) -> str:
    return MATERIAL_COLORS.get(name, OTHER_MATERIAL_COLOR)


def facet_colors(model: simcore.TargetModel, faces: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 material colour of each of the given facets."""
    palette = np.array([encode.rgb_of(material_color(n)) for n in simcore.MATERIAL_NAMES], np.uint8)
    return palette[model.face_material_library[np.asarray(faces, dtype=np.int64)]]


def seen_facets_mesh(
    model: simcore.TargetModel, vertices_d: np.ndarray, visible_faces: np.ndarray
) -> dict:
    """vtk.js mesh state of the facets seen this frame, in their material colours.

    The whole target is drawn once, grey; these facets (with their own vertices, taken from the
    display-frame vertices ``vertices_d`` (n_vertices, 3)) are drawn over it, so a new frame
    sends only the few thousand facets seen, never the whole mesh.
    """
    faces = np.asarray(visible_faces, dtype=np.int64)
    if len(faces) == 0:
        faces = np.zeros(1, np.int64)  # one facet keeps the arrays non-empty; the view hides it
    used, corners = np.unique(model.mesh.faces[faces], return_inverse=True)
    return {
        "mesh": {
            "points": encode.typed_array(vertices_d[used].astype(np.float32)),
            "polys": encode.typed_array(encode.triangle_cells(corners.reshape(-1, 3))),
        },
        "field": encode.rgb_field(facet_colors(model, faces), location="CellData"),
    }


def material_legend(model: simcore.TargetModel, visible_faces: np.ndarray) -> list[dict]:
    """One entry per material the target uses: colour, label, facets seen / facets in all."""
    lib = model.face_material_library
    seen = np.bincount(lib[np.asarray(visible_faces, np.int64)], minlength=len(simcore.MATERIALS))
    total = np.bincount(lib, minlength=len(simcore.MATERIALS))
    rows = []
    for i, name in enumerate(simcore.MATERIAL_NAMES):
        if total[i]:
            label = simcore.MATERIALS[name].label or name
            rows.append(
                {
                    "name": name,
                    "label": label,
                    "color": material_color(name),
                    "seen": int(seen[i]),
                    "total": int(total[i]),
                }
            )
    n_hidden = int(len(lib) - len(visible_faces))
    rows.append(
        {
            "name": "hidden",
            "label": "not seen this frame",
            "color": HIDDEN_COLOR,
            "seen": n_hidden,
            "total": int(len(lib)),
        }
    )
    return rows


def frustum_sensor(
    fov_rad: float, distance_m: float, radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The field-of-view frustum around the target, in the sensor frame.

    Returns points (k, 3) [m] and segments (s, 2) int: the four edges from the lidar (or, if it
    is more than 2.5 target radii away, from a plane there) to a plane behind the target, the
    footprint rectangle at the target distance, and the boresight.
    """
    half = math.tan(fov_rad / 2.0)
    near = max(0.0, distance_m - 2.5 * radius_m)
    far = distance_m + 1.2 * radius_m
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)

    def rect(z: float) -> np.ndarray:
        return np.column_stack([square * half * z, np.full(4, z)])

    points = np.vstack([rect(near), rect(far), rect(distance_m), [[0, 0, near], [0, 0, far]]])
    ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    edges = np.column_stack([np.arange(4), np.arange(4) + 4])
    return points, np.vstack([edges, ring + 8, [[12, 13]]])


def footprint_text(scene: simcore.Scene) -> str:
    """The field of view's footprint at the target distance, e.g. '15.0 m × 15.0 m at 500 m'."""
    distance = scene.pose.distance_m
    side = 2.0 * distance * math.tan(scene.receive.fov_rad / 2.0)
    return f"{side:.3g} m × {side:.3g} m at {distance:g} m"


def frustum_mesh(result: simcore.Result, frame: DisplayFrame) -> dict:
    """vtk.js mesh state of the frustum lines in the display frame."""
    scene = result.scene
    points_s, segments = frustum_sensor(
        scene.receive.fov_rad, scene.pose.distance_m, frame.radius_m
    )
    pose = result.hits.pose
    points_d = frame.from_sensor(points_s, pose.rotation, pose.translation_m)
    return {
        "mesh": {
            "points": encode.typed_array(points_d.astype(np.float32)),
            "lines": encode.typed_array(encode.polyline_cells(segments)),
        }
    }


# ----------------------------------------------------------------------------------------------
# the point cloud
# ----------------------------------------------------------------------------------------------
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


def _colorbar(title: str, cmap: str, lo_text: str, hi_text: str) -> dict:
    return {
        "title": title,
        "gradient": encode.css_gradient(cmap),
        "lo": lo_text,
        "hi": hi_text,
    }


def point_colors(result: simcore.Result, target: np.ndarray, color_by: str):
    """(n_target, 3) uint8 colours of the target points and the colour bar describing them."""
    attrs = result.attributes
    n = int(target.sum())
    if color_by == "outlier" or n == 0:
        rgb = np.tile(np.array(encode.rgb_of(TARGET_POINT_COLOR), np.uint8), (n, 1))
        return rgb, None
    if color_by == "snr":
        values = np.log10(np.maximum(attrs["snr"][target], 1e-12))
        lo, hi = float(values.min()), float(values.max())
        bar = _colorbar("SNR", SNR_CMAP, f"{10**lo:.3g}", f"{10**hi:.3g}")
        return encode.colors_of(encode.normalized(values, lo, hi), SNR_CMAP), bar
    values = attrs["range_m"][target]
    lo, hi = float(values.min()), float(values.max())
    bar = _colorbar("Range", RANGE_CMAP, f"{lo:.2f} m", f"{hi:.2f} m")
    return encode.colors_of(encode.normalized(values, lo, hi), RANGE_CMAP), bar


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


# ----------------------------------------------------------------------------------------------
# the detector array image
# ----------------------------------------------------------------------------------------------
def array_image(result: simcore.Result, kind: str) -> dict:
    """The n x n array as a PNG (row 0 at the top) with its colour bar: measured range [m] or
    band-limited peak power (log scale, from the 2nd percentile up, weaker echoes saturate at
    the bottom colour) per pixel; pixels without a value are dark."""
    if kind == "peak_power":
        values = np.asarray(result.peak_power_image_w, dtype=np.float64)
        valid = values > 0
        logs = np.log10(np.where(valid, values, 1.0))
        lo, hi = _finite_range(logs[valid])
        if valid.sum() > 50:  # a few grazing echoes decades below the rest would wash it out
            lo = float(np.percentile(logs[valid], 2.0))
        unit = encode.normalized(logs, lo, hi)
        bar = _colorbar(
            "Peak power (log)",
            POWER_CMAP,
            encode.si_text(10**lo, "W"),
            encode.si_text(10**hi, "W"),
        )
        cmap = POWER_CMAP
    else:
        values = np.asarray(result.range_image_m, dtype=np.float64)
        valid = np.isfinite(values)
        lo, hi = _finite_range(values[valid])
        unit = encode.normalized(np.where(valid, values, lo), lo, hi)
        bar = _colorbar("Range", RANGE_CMAP, f"{lo:.2f} m", f"{hi:.2f} m")
        cmap = RANGE_CMAP
    rgb = encode.colors_of(unit.ravel(), cmap).reshape(*values.shape, 3)
    rgb[~valid] = NO_ECHO_RGB
    return {"src": encode.png_data_url(rgb), "colorbar": bar, "pixels": int(values.shape[0])}


def _finite_range(values: np.ndarray) -> tuple[float, float]:
    if values.size == 0:
        return 0.0, 1.0
    return float(values.min()), float(values.max())


# ----------------------------------------------------------------------------------------------
# pixel selection and the waveform chart
# ----------------------------------------------------------------------------------------------
def default_pixel(result: simcore.Result) -> list[int] | None:
    """The detected target pixel nearest the array centre (None if nothing was detected)."""
    attrs = result.attributes
    target = ~np.asarray(attrs["is_outlier"], dtype=bool)
    if not target.any():
        return None
    rows, cols = attrs["row"][target], attrs["col"][target]
    centre = (result.pixels - 1) / 2.0
    i = int(np.argmin((rows - centre) ** 2 + (cols - centre) ** 2))
    return [int(rows[i]), int(cols[i])]


def rescale_selection(pixels: list, n_from: int, n_to: int) -> list[list[int]]:
    """Selected (row, col) pixels of an n_from array mapped to the same spots of an n_to array."""
    if n_from == n_to:
        return [[int(r), int(c)] for r, c in pixels]
    out: list[list[int]] = []
    for r, c in pixels:
        rc = [
            min(n_to - 1, int((r + 0.5) * n_to / n_from)),
            min(n_to - 1, int((c + 0.5) * n_to / n_from)),
        ]
        if rc not in out:
            out.append(rc)
    return out


def toggle_pixel(selection: list, pixel: list[int], add: bool, limit: int) -> list[list[int]]:
    """The new selection after a click: ``add`` (shift-click) toggles ``pixel`` in the selection
    (dropping the oldest beyond ``limit``); a plain click selects ``pixel`` alone."""
    pixel = [int(pixel[0]), int(pixel[1])]
    if not add:
        return [pixel]
    current = [[int(r), int(c)] for r, c in selection]
    if pixel in current:
        current.remove(pixel)
        return current
    return (current + [pixel])[-limit:]


def _axis(title: str, **extra) -> dict:
    return {
        "title": {"text": title},
        "gridcolor": "#e6e6e6",
        "zeroline": False,
        "showline": True,
        "linecolor": "#9e9e9e",
        "ticks": "outside",
        **extra,
    }


def base_layout(x_title: str, y_title: str, **extra) -> dict:
    """A compact, light plotly layout shared by the charts."""
    return {
        "margin": {"l": 60, "r": 12, "t": 8, "b": 42},
        "paper_bgcolor": "rgba(0,0,0,0)",
        "plot_bgcolor": "#ffffff",
        "font": {"family": "Roboto, sans-serif", "size": 11},
        "xaxis": _axis(x_title),
        "yaxis": _axis(y_title),
        **extra,
    }


MAX_CHART_POINTS = 400  # per trace: more is invisible at chart size and costs transfer time


def _chart_xy(t_s: np.ndarray, power_w: np.ndarray, delay_s: float, scale_w: float):
    """Chart coordinates: time [ns] rounded to 1 ps and power in chart units rounded to 5
    significant digits, thinned to at most MAX_CHART_POINTS samples."""
    step = max(1, math.ceil(len(t_s) / MAX_CHART_POINTS))
    t_ns = np.round((t_s[::step] + delay_s) * 1e9, 3)
    y = power_w[::step] / scale_w
    peak = float(np.max(np.abs(y))) if len(y) else 0.0
    digits = 5 - math.ceil(math.log10(peak)) if peak > 0 else 5
    return t_ns.tolist(), np.round(y, max(digits, 0)).tolist()


def _waveform_traces(w: simcore.Waveform, color: str, scale: float) -> list[dict]:
    """Filtered and raw echo, the delayed emitted pulse and the half-maximum mark of one pixel."""
    name = f"({w.row}, {w.col})"
    if w.detected and math.isfinite(w.range_m):
        name += f" R = {w.range_m:.3f} m"
    else:
        name += f" not detected (P_d = {w.p_detect:.2f})"
    group = f"px{w.row}_{w.col}"
    t_ns, filtered = _chart_xy(w.t_s, w.filtered_w, 0.0, scale)
    _, raw = _chart_xy(w.t_s, w.power_w, 0.0, scale)
    traces = [
        {
            "type": "scatter",
            "mode": "lines",
            "x": t_ns,
            "y": filtered,
            "name": name,
            "legendgroup": group,
            "line": {"color": color, "width": 2},
            "hovertemplate": "%{x:.2f} ns<br>%{y:.4g}<extra>received (band-limited)</extra>",
        },
        {
            "type": "scatter",
            "mode": "lines",
            "x": t_ns,
            "y": raw,
            "name": "received, unfiltered",
            "legendgroup": group,
            "showlegend": False,
            "line": {"color": color, "width": 1, "dash": "dot"},
            "hovertemplate": "%{x:.2f} ns<br>%{y:.4g}<extra>received (unfiltered)</extra>",
        },
    ]
    reference_m = w.range_true_m if math.isfinite(w.range_true_m) else w.range_m
    if len(w.emitted_t_s) and math.isfinite(reference_m):
        t_emitted, emitted = _chart_xy(w.emitted_t_s, w.emitted_w, 2.0 * reference_m / C_M_S, scale)
        traces.append(
            {
                "type": "scatter",
                "mode": "lines",
                "x": t_emitted,
                "y": emitted,
                "name": "emitted pulse (delayed by 2R/c)",
                "legendgroup": group,
                "showlegend": False,
                "opacity": 0.55,
                "line": {"color": color, "width": 1.5, "dash": "dash"},
                "hovertemplate": "%{x:.2f} ns<br>%{y:.4g}<extra>emitted, delayed 2R/c</extra>",
            }
        )
    if math.isfinite(w.t_half_s) and len(w.filtered_w):
        half = float(np.max(w.filtered_w)) / 2.0
        traces.append(
            {
                "type": "scatter",
                "mode": "markers",
                "x": [w.t_half_s * 1e9],
                "y": [half / scale],
                "name": "half-maximum time",
                "legendgroup": group,
                "showlegend": False,
                "marker": {"symbol": "diamond", "size": 9, "color": color, "line": {"width": 1}},
                "hovertemplate": "t½ = %{x:.3f} ns<extra>half maximum</extra>",
            }
        )
    return traces


def _detected_time_ns(w: simcore.Waveform) -> float | None:
    """The time of the measured range on the chart's axis: the half-maximum time shifted by the
    range noise (measured minus noise-free range)."""
    if not (w.detected and math.isfinite(w.range_m) and math.isfinite(w.t_half_s)):
        return None
    return (w.t_half_s + 2.0 * (w.range_m - w.range_true_m) / C_M_S) * 1e9


def waveform_figure(result: simcore.Result, selection: list) -> dict:
    """The plotly figure of the selected pixels' echoes (several pixels overlaid): received power
    vs time since emission, the emitted pulse for reference, the half-maximum marks, the
    threshold and the detected ranges."""
    waves = [result.waveform(int(r), int(c)) for r, c in selection]
    peak = max([float(np.max(w.power_w)) for w in waves if len(w.power_w)] + [0.0])
    threshold_w = waves[0].threshold_w if waves else float("nan")
    scale, prefix = encode.si_prefix(max(peak, threshold_w if math.isfinite(threshold_w) else 0))
    data: list[dict] = []
    shapes: list[dict] = []
    annotations: list[dict] = []
    for i, w in enumerate(waves):
        color = SELECTION_COLORS[i % len(SELECTION_COLORS)]
        if not len(w.t_s):
            data.append(_no_echo_trace(w, color))
            continue
        data += _waveform_traces(w, color, scale)
        t_det = _detected_time_ns(w)
        if t_det is not None:
            shapes.append(_vline(t_det, color))
    times = [t for w in waves for t in (w.t_s[:1].tolist() + w.t_s[-1:].tolist())]
    if math.isfinite(threshold_w) and times:
        data.append(
            {
                "type": "scatter",
                "mode": "lines",
                "x": [min(times) * 1e9, max(times) * 1e9],
                "y": [threshold_w / scale] * 2,
                "name": f"threshold (TNR × σn) = {encode.si_text(threshold_w, 'W')}",
                "line": {"color": "#616161", "width": 1.5, "dash": "dashdot"},
                "hovertemplate": "%{y:.4g}<extra>threshold</extra>",
            }
        )
    if not waves:
        annotations.append(_note("Click a pixel of the detector array to see its echo"))
    elif not any(len(w.t_s) for w in waves):
        annotations.append(_note("No echo in the selected pixel(s)"))
    layout = base_layout(
        "time since emission (ns)",
        f"power at the receiver ({prefix}W)",
        legend={
            "orientation": "h",
            "x": 0,
            "y": 1.01,
            "yanchor": "bottom",
            "font": {"size": 10},
            "bgcolor": "rgba(255,255,255,0.8)",
        },
        shapes=shapes,
        annotations=annotations,
        hovermode="closest",
    )
    layout["margin"]["t"] = 10 + 18 * math.ceil(len(data) and len(waves) / 2)
    layout["xaxis"]["tickformat"] = ",.0f"
    layout["xaxis"]["hoverformat"] = ",.2f"
    return {"data": data, "layout": layout}


def _no_echo_trace(w: simcore.Waveform, color: str) -> dict:
    return {
        "type": "scatter",
        "mode": "markers",
        "x": [None],  # plotly lists a trace in the legend only if it has a point
        "y": [None],
        "name": f"({w.row}, {w.col}) no echo",
        "showlegend": True,
        "marker": {"color": color},
    }


def _vline(x: float, color: str) -> dict:
    return {
        "type": "line",
        "xref": "x",
        "yref": "paper",
        "x0": x,
        "x1": x,
        "y0": 0,
        "y1": 1,
        "line": {"color": color, "width": 1.5, "dash": "longdash"},
    }


def _note(text: str) -> dict:
    return {
        "text": text,
        "xref": "paper",
        "yref": "paper",
        "x": 0.5,
        "y": 0.5,
        "showarrow": False,
        "font": {"size": 13, "color": "#757575"},
    }


# ----------------------------------------------------------------------------------------------
# the stats panel
# ----------------------------------------------------------------------------------------------
def stats_rows(summary: dict) -> list[dict]:
    """Label/value rows of the summary, with units."""

    def fmt(value, spec: str = "d", unit: str = "") -> str:
        if value is None:
            return "–"
        return f"{value:{spec}}{unit}"

    sigma = summary.get("range_sigma_m_median")
    return [
        {"label": "Points", "value": fmt(summary["n_points"], ",d")},
        {"label": "Target points", "value": fmt(summary["n_target_points"], ",d")},
        {"label": "Outliers (false alarms)", "value": fmt(summary["n_outliers"], ",d")},
        {"label": "Dropped pixels (missed)", "value": fmt(summary["n_dropped"], ",d")},
        {
            "label": "Pixels seeing the target",
            "value": f"{summary['n_hit_pixels']:,d} of {summary['n_pixels']:,d}",
        },
        {"label": "Mean detection probability", "value": fmt(summary["p_detect_mean"], ".3f")},
        {"label": "Median SNR", "value": fmt(summary["snr_median"], ".3g")},
        {
            "label": "Median range σ",
            "value": "–" if sigma is None else f"{sigma * 100:.3g} cm",
        },
    ]


def stage_rows(timings_s: dict[str, float], extra_s: dict[str, float]) -> list[dict]:
    """One row per pipeline stage (ms, or 'cached'), then the app's own steps."""
    rows = []
    for stage in simcore.STAGES:
        t = timings_s.get(stage, 0.0)
        rows.append(
            {"stage": stage, "ms": "cached" if t == 0.0 else f"{t * 1e3:.1f}", "cached": t == 0.0}
        )
    for name, t in extra_s.items():
        rows.append({"stage": name, "ms": f"{t * 1e3:.1f}", "cached": False})
    return rows


def snr_histogram(result: simcore.Result) -> dict:
    """Plotly histogram of the SNR of every pixel that receives an echo, in log10 bins (the axis
    is labelled in SNR), with the TNR marked (a pixel needs SNR above about TNR to be detected)."""
    snr = np.asarray(result.receiver.snr, dtype=np.float64)
    snr = snr[np.isfinite(snr) & (snr > 0)]
    tnr = result.scene.timing.tnr
    layout = base_layout("SNR (log scale)", "pixels", bargap=0.0, showlegend=False)
    layout["margin"] = {"l": 48, "r": 8, "t": 8, "b": 38}
    if snr.size == 0:
        layout["annotations"] = [_note("No echo")]
        return {"data": [], "layout": layout}
    logs = np.log10(np.clip(snr, SNR_FLOOR, None))  # weaker echoes are counted in the first bin
    lo, hi = min(float(logs.min()), math.log10(tnr)) - 0.1, float(logs.max()) + 0.1
    edges = np.linspace(lo, hi, 41)
    counts, _ = np.histogram(logs, bins=edges)
    ticks = np.arange(math.ceil(lo), math.floor(hi) + 1)
    layout["xaxis"].update(
        range=[lo, hi],
        tickvals=ticks.tolist(),
        ticktext=[f"{10.0**k:g}" for k in ticks],
    )
    layout["shapes"] = [_vline(math.log10(tnr), "#d62728")]
    layout["annotations"] = [
        {
            "text": f"TNR {tnr:g}",
            "x": math.log10(tnr),
            "xref": "x",
            "y": 1,
            "yref": "paper",
            "showarrow": False,
            "xanchor": "left",
            "yanchor": "top",
            "font": {"color": "#d62728", "size": 10},
        }
    ]
    centres = (edges[:-1] + edges[1:]) / 2
    bars = {
        "type": "bar",
        "x": centres.tolist(),
        "y": counts.tolist(),
        "marker": {"color": "#5c6bc0"},
        "customdata": (10**centres).tolist(),
        "hovertemplate": "SNR ≈ %{customdata:.3g}: %{y} pixels<extra></extra>",
    }
    return {"data": [bars], "layout": layout}
