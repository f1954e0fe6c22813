"""The attitude map's figure (the app's "Attitudes" panel): one metric of every attitude of a
grid (``simcore.atlas``), drawn in Lambert's cylindrical equal-area projection.

x is the azimuth (-180 to 180 deg, the slider's range), y the sine of the pitch: a cell of the
latitude-longitude grid then covers an area proportional to its solid angle (d Omega = d(sin
pitch) d azimuth), so a share of the map's area is a share of the sphere of view directions. A
pole's cell is its cap: a strip across the whole width. The cell at azimuth 180 deg straddles the
map's edge and is drawn at both edges. A cell where the target is not seen has no value: it shows
the plot's grey background and its hover says "not seen", never a zero.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from app.payloads.charts import axis
from simcore.atlas import METRICS, AttitudeGrid

# the metrics the panel offers: name (simcore.atlas.METRICS) -> the chooser's text
MAP_METRICS: dict[str, str] = {
    "f_score": "F-score",
    "recall": "Recall",
    "n_target_points": "Target points",
    "seen_area_m2": "Seen area",
}
NOT_SEEN_COLOR = "#9e9e9e"  # the plot's background: cells without a value
MARKER_COLOR = "#d81b60"
PITCH_TICKS_DEG = (-90, -60, -30, 0, 30, 60, 90)
AZIMUTH_TICKS_DEG = (-180, -90, 0, 90, 180)
# the share metrics' scale is fixed (two maps compare); the others start at zero
FIXED_RANGE = {"f_score": (0.0, 1.0), "recall": (0.0, 1.0)}


def seen(row: Mapping[str, Any] | None) -> bool:
    """Whether an attitude's frame sees any of the target (a sample of its surface in view and
    not hidden: the recall has a value)."""
    return row is not None and row.get("quality.recall") is not None


def metric_value(row: Mapping[str, Any] | None, metric: str) -> float | None:
    """The ``metric`` of one atlas row; None where the target is not seen."""
    if not seen(row):
        return None
    assert row is not None
    value = row.get(METRICS[metric][0])
    return None if value is None else float(value)


def wrapped_deg(azimuth_deg: float) -> float:
    """An azimuth in the slider's range, (-180, 180] [deg]."""
    a = math.fmod(float(azimuth_deg), 360.0)
    a = a - 360.0 if a > 180.0 else a + 360.0 if a <= -180.0 else a
    return a + 0.0


def row_edges_deg(grid: AttitudeGrid) -> np.ndarray:
    """(n_rows + 1,) the pitch edges of the grid's rows [deg], -90 to 90: half a step either
    side of each row's pitch (a pole's cap is half a step high)."""
    half = grid.pitch_step_deg / 2.0
    inner = grid.pitch_deg[:-1] + half
    return np.concatenate([[-90.0], inner, [90.0]])


def column_edges_deg(grid: AttitudeGrid) -> tuple[np.ndarray, list[float]]:
    """The map's column edges [deg], -180 to 180, and each column's azimuth (the grid's, 0 to
    360): the cells' edges halfway between the grid's azimuths, and the map's edges; a cell
    that straddles +-180 deg is split in two, one part at each edge."""
    step = grid.azimuth_step_deg
    inner = {wrapped_deg((k + 0.5) * step) for k in range(grid.n_azimuth)} - {180.0}
    edges = np.array(sorted({-180.0, 180.0, *(round(e, 9) for e in inner)}))
    middles = (edges[:-1] + edges[1:]) / 2.0
    azimuths = [float(round(m / step) % grid.n_azimuth * step) for m in middles]
    return edges, [round(a, 9) + 0.0 for a in azimuths]


def attitude_figure(
    grid: AttitudeGrid,
    rows: Mapping[tuple[float, float], Mapping[str, Any]],
    metric: str,
    current: tuple[float, float] | None = None,
) -> dict:
    """The plotly figure of ``metric`` over ``grid``: a heatmap of its cells in the equal-area
    projection (each cell's customdata its (pitch_deg, azimuth_deg), for a click), the current
    attitude ``current`` (pitch, azimuth) marked.

    Raises KeyError for a metric that is not one of MAP_METRICS."""
    column, label, _ = METRICS[metric]
    if metric not in MAP_METRICS:
        raise KeyError(metric)
    y_edges = np.sin(np.radians(row_edges_deg(grid)))
    x_edges, azimuths = column_edges_deg(grid)
    z: list[list[float | None]] = []
    custom: list[list[list[float]]] = []
    text: list[list[str]] = []
    for pitch in grid.pitch_deg:
        pitch = float(pitch)
        pole = abs(pitch) == 90.0
        z_row, c_row, t_row = [], [], []
        for azimuth in azimuths:
            key = (pitch, 0.0) if pole else (pitch, float(azimuth))
            row = rows.get(key)
            value = metric_value(row, metric)
            z_row.append(None if value is None else float(f"{value:.6g}"))  # 6 digits
            c_row.append([pitch, wrapped_deg(key[1])])
            t_row.append(_hover(key, row, value, label))
        z.append(z_row)
        custom.append(c_row)
        text.append(t_row)
    lo_hi = FIXED_RANGE.get(metric)
    values = [v for r in z for v in r if v is not None]
    heat: dict[str, Any] = {
        "type": "heatmap",
        "name": "attitudes",
        "x": np.round(x_edges, 6).tolist(),
        "y": np.round(y_edges, 9).tolist(),
        "z": z,
        "customdata": custom,
        "text": text,
        "hovertemplate": "%{text}<extra></extra>",
        "hoverongaps": True,
        "colorscale": "Viridis",
        "zmin": lo_hi[0] if lo_hi else 0.0,
        "zmax": lo_hi[1] if lo_hi else (max(values) if values and max(values) > 0 else 1.0),
        "colorbar": {"title": {"text": label, "side": "right"}, "thickness": 12},
        "xgap": 0.5,
        "ygap": 0.5,
    }
    data: list[dict[str, Any]] = [heat]
    if current is not None:
        pitch, azimuth = current
        data.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": "current attitude",
                "x": [round(wrapped_deg(azimuth), 6)],
                "y": [round(math.sin(math.radians(pitch)), 9)],
                "marker": {
                    "symbol": "circle-open",
                    "size": 14,
                    "color": MARKER_COLOR,
                    "line": {"width": 3},
                },
                "hoverinfo": "skip",
                "showlegend": False,
            }
        )
    layout = {
        "margin": {"l": 52, "r": 8, "t": 8, "b": 40},
        "paper_bgcolor": "rgba(0,0,0,0)",
        "plot_bgcolor": NOT_SEEN_COLOR,
        "font": {"family": "Roboto, sans-serif", "size": 11},
        "xaxis": axis(
            "Azimuth (deg)",
            range=[-180, 180],
            tickvals=list(AZIMUTH_TICKS_DEG),
            showgrid=False,
            fixedrange=True,
        ),
        "yaxis": axis(
            "Pitch (deg), equal-area",
            range=[-1, 1],
            tickvals=[round(math.sin(math.radians(p)), 9) for p in PITCH_TICKS_DEG],
            ticktext=[f"{p}" for p in PITCH_TICKS_DEG],
            showgrid=False,
            fixedrange=True,
        ),
        "showlegend": False,
        "uirevision": "attitudes",
    }
    return {"data": data, "layout": layout, "metric": metric, "label": label, "column": column}


def _hover(
    attitude: tuple[float, float], row: Mapping[str, Any] | None, value: float | None, label: str
) -> str:
    """A cell's hover text: its attitude, its value (or why it has none) and what gives most
    of its points."""
    pitch, azimuth = attitude
    where = f"pitch {pitch:g}°, azimuth {wrapped_deg(azimuth):g}°"
    if row is None:
        return f"{where}: not computed yet"
    if value is None:
        return f"{where}: not seen"
    text = f"{where}<br>{label}: {value:.3g}<br>{int(row['n_target_points']):,} target points"
    if row.get("dominant_part"):
        text += f"; most from {row['dominant_part']} ({row['dominant_material']})"
    return text
