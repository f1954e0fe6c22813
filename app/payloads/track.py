"""The fly-around's pose track on the page: the true and the estimated target frames as two axis
triads in the 3D view (the display frame of ``app.payloads.scene3d``, fixed to the target), and
a chart of the rotation and translation errors along the track so far.

A triad's axes are the target body frame's x, y and z, of lengths 1, 0.7 and 0.45 of
``TRIAD_SIZE`` target radii (the longest is x), from the frame's origin (the target's centre). The
true triad is the body frame itself; the estimated one is the estimate T_sensor_target carried
into the display by the TRUE pose (as the cloud's points are): where the estimate is right the
two coincide, and their offset is the error seen from the target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from app.payloads import encode
from app.payloads.charts import axis, base_layout, note
from app.payloads.scene3d import DisplayFrame

TRIAD_SIZE = 1.25  # [target radii] the x axis's length: out of the mesh, seen
AXIS_LENGTHS = (1.0, 0.7, 0.45)  # x, y, z: the longest is x
TRUE_COLOR = "#66bb6a"  # green: the true target frame
ESTIMATE_COLOR = "#ec407a"  # magenta: the estimated one
ROTATION_COLOR = "#1565c0"
TRANSLATION_COLOR = "#ef6c00"


def triad_points(pose: np.ndarray, size_m: float) -> np.ndarray:
    """(4, 3) the origin and the x, y, z axis ends [m, sensor frame] of the target frame at
    ``pose`` (4, 4) T_sensor_target."""
    rot, t = np.asarray(pose)[:3, :3], np.asarray(pose)[:3, 3]
    ends = [t + size_m * length * rot[:, k] for k, length in enumerate(AXIS_LENGTHS)]
    return np.vstack([t, *ends])


def triad_mesh(points_display: np.ndarray) -> dict:
    """vtk.js mesh state of a triad's three lines (points (4, 3) [m], display frame)."""
    segments = np.array([[0, 1], [0, 2], [0, 3]])
    return {
        "mesh": {
            "points": encode.typed_array(np.asarray(points_display, dtype=np.float32)),
            "lines": encode.typed_array(encode.polyline_cells(segments)),
        }
    }


def true_pose(hits_pose, body_from_mesh: np.ndarray) -> np.ndarray:
    """(4, 4) the true T_sensor_target of a frame (the target BODY frame, as the tracker and
    the fly-around's ground truth give it) from the pipeline's pose (``result.hits.pose``:
    mesh -> sensor) and the model's ``body_from_mesh``."""
    out = np.eye(4)
    out[:3, :3] = np.asarray(hits_pose.rotation) @ np.asarray(body_from_mesh).T
    out[:3, 3] = hits_pose.translation_m
    return out


def triads(
    frame: DisplayFrame, hits_pose, truth: np.ndarray, estimate: np.ndarray | None
) -> dict[str, dict | None]:
    """``fly_triad_true`` and ``fly_triad_estimate``: the two triads in the display frame (the
    estimate None until its frame is tracked), carried there by the frame's pose ``hits_pose``
    (mesh -> sensor, as the cloud is). ``truth``, ``estimate``: (4, 4) T_sensor_target."""
    size_m = TRIAD_SIZE * frame.radius_m
    rot, t = np.asarray(hits_pose.rotation), np.asarray(hits_pose.translation_m)
    true_d = frame.from_sensor(triad_points(truth, size_m), rot, t)
    out: dict[str, dict | None] = {"fly_triad_true": triad_mesh(true_d), "fly_triad_estimate": None}
    if estimate is not None:
        est_d = frame.from_sensor(triad_points(estimate, size_m), rot, t)
        out["fly_triad_estimate"] = triad_mesh(est_d)
    return out


def error_chart(
    t_s: Sequence[float],
    rotation_error_deg: Sequence[float],
    translation_error_m: Sequence[float],
    lost: Sequence[bool],
    now_s: float | None = None,
) -> dict:
    """A plotly figure of the errors along the track so far: rotation [deg] (left axis) and
    translation [m] (right axis) against the frame time [s], lines through the frames tracked,
    a lost frame a cross on the time axis (its errors are not the tracker's estimate of
    anything), the shown frame's time a vertical line."""
    t = [float(x) for x in t_s]
    kept = [i for i, gone in enumerate(lost) if not gone]
    gone = [i for i, g in enumerate(lost) if g]

    def series(values, name, color, y):
        return {
            "type": "scatter",
            "mode": "lines+markers",
            "x": [t[i] for i in kept],
            "y": [_round(values[i]) for i in kept],
            "name": name,
            "line": {"color": color, "width": 1.5},
            "marker": {"size": 5},
            "yaxis": y,
        }

    data = [
        series(rotation_error_deg, "rotation error (deg)", ROTATION_COLOR, "y"),
        series(translation_error_m, "translation error (m)", TRANSLATION_COLOR, "y2"),
    ]
    if gone:
        data.append(
            {
                "type": "scatter",
                "mode": "markers",
                "x": [t[i] for i in gone],
                "y": [0.0] * len(gone),
                "name": "lost",
                "marker": {"symbol": "x", "size": 9, "color": "#c62828"},
                "yaxis": "y",
            }
        )
    layout = base_layout(
        "time since the epoch (s)",
        "rotation error (deg)",
        yaxis2=axis("translation error (m)", overlaying="y", side="right", rangemode="tozero"),
        showlegend=True,
        legend={"orientation": "h", "y": 1.0, "yanchor": "bottom", "x": 0.0, "font": {"size": 10}},
        height=220,
    )
    layout["yaxis"]["rangemode"] = "tozero"
    layout["margin"] = {**layout["margin"], "r": 56, "t": 40}
    if now_s is not None:
        layout["shapes"] = [
            {
                "type": "line",
                "xref": "x",
                "yref": "paper",
                "x0": float(now_s),
                "x1": float(now_s),
                "y0": 0,
                "y1": 1,
                "line": {"color": "#9e9e9e", "width": 1, "dash": "dot"},
            }
        ]
    if not t:
        layout["annotations"] = [note("tracking the frame shown...")]
    return {"data": data, "layout": layout}


def _round(x: float) -> float | None:
    return round(float(x), 6) if math.isfinite(x) else None
