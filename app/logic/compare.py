"""Compare: a pinned frame beside the newest one, a child of the app's logic.

*Pin* keeps the frame on the page: its headline figures (points, outliers, dropped pixels, median
SNR, median range sigma) and its point cloud. Change anything after it (pose, pixels, energy, TNR,
Sun, receiver, fidelity, seed, materials): the stats panel shows the pinned figures, the new ones
and the change side by side, and the cloud view draws the pinned cloud faintly under the new one
(both in the target-fixed display frame, so a pose change shows how the sampling moved on the
target). *Unpin* drops it; so does a change of target (another display frame).
"""

from __future__ import annotations

import math
from typing import Any

from app.engine import Frame
from app.payloads import cloud
from app.payloads.scene3d import DisplayFrame

# the figures compared: (label, summary key, kind); kind "count" (integer), "snr" or "sigma_m"
COMPARED = (
    ("Points", "n_points", "count"),
    ("Outliers (false alarms)", "n_outliers", "count"),
    ("Dropped pixels (missed)", "n_dropped", "count"),
    ("Median SNR", "snr_median", "snr"),
    ("Median range σ", "range_sigma_m_median", "sigma_m"),
)
STATE_KEYS = ("pinned", "compare_rows", "pinned_cloud", "n_pinned_points")


def _number(value: Any) -> float | None:
    """``value`` as a finite float, or None (a summary says None where a figure has no value)."""
    if value is None:
        return None
    v = float(value)
    return v if math.isfinite(v) else None


def figure_text(value: Any, kind: str) -> str:
    """One figure with its unit: counts with thousands separators, SNR to 3 digits, the range
    sigma [m] in centimetres; '–' where there is none."""
    v = _number(value)
    if v is None:
        return "–"
    if kind == "count":
        return f"{int(v):,d}"
    if kind == "snr":
        return f"{v:.3g}"
    return f"{v * 100:.3g} cm"


def change_text(pinned: Any, now: Any, kind: str) -> str:
    """The change from ``pinned`` to ``now``, signed, in the figure's unit ('–' if either has no
    value; '0' if none)."""
    a, b = _number(pinned), _number(now)
    if a is None or b is None:
        return "–"
    d = b - a
    if kind == "count":
        return f"{int(round(d)):+,d}" if d else "0"
    if kind == "snr":
        return f"{d:+.3g}" if d else "0"
    return f"{d * 100:+.3g} cm" if d else "0"


def compare_rows(pinned: dict, now: dict) -> list[dict]:
    """Rows of the side-by-side table from two frames' summaries (``simcore.Result.summary``):
    label, pinned value, new value, change."""
    return [
        {
            "label": label,
            "pinned": figure_text(pinned.get(key), kind),
            "now": figure_text(now.get(key), kind),
            "change": change_text(pinned.get(key), now.get(key), kind),
        }
        for label, key, kind in COMPARED
    ]


def scene_text(frame: Frame) -> str:
    """A short description of a frame's scene (pose, array, energy, TNR) for the pinned label."""
    s = frame.result.scene
    return (
        f"pitch {s.pose.pitch_deg:g}°, azimuth {s.pose.azimuth_deg:g}°, "
        f"{s.pose.distance_m:.4g} m, {s.detector.pixels} px, "
        f"{s.laser.pulse_energy_j * 1e3:.3g} mJ, TNR {s.timing.tnr:g}"
    )


class FrameCompare:
    """The pinned frame on a trame state: ``pinned`` (None, or its label and figures),
    ``compare_rows`` (the side-by-side table, empty when nothing is pinned), ``pinned_cloud``
    (its points, drawn faintly) and ``n_pinned_points``."""

    def __init__(self, state):
        self.state = state
        self.summary: dict | None = None  # the pinned frame's summary
        state.update(
            {"pinned": None, "compare_rows": [], "pinned_cloud": None, "n_pinned_points": 0}
        )

    def pin(self, frame: Frame, display: DisplayFrame) -> None:
        """Pin ``frame`` (the one the page shows), drawn in ``display`` (the engine's frame)."""
        self.summary = dict(frame.summary)
        points = cloud.pinned_cloud(frame.result, display)
        with self.state:
            self.state.update(
                {
                    "pinned": {"label": scene_text(frame)},
                    "compare_rows": compare_rows(self.summary, frame.summary),
                    "pinned_cloud": points,
                    "n_pinned_points": int(len(frame.result.points)),
                }
            )

    def unpin(self, *_: Any, **__: Any) -> None:
        """Drop the pinned frame."""
        self.summary = None
        with self.state:
            self.state.update(
                {"pinned": None, "compare_rows": [], "pinned_cloud": None, "n_pinned_points": 0}
            )

    def for_frame(self, frame: Frame) -> dict:
        """The state a newly shown ``frame`` updates (merged into its single flush): the table
        against the pinned frame, or nothing when none is pinned."""
        if self.summary is None:
            return {}
        return {"compare_rows": compare_rows(self.summary, frame.summary)}
