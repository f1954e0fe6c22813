"""The figure of a pose track (``DIR/tracking.png`` of ``lmapd flyaround --track``) and the two
tables beside it (``DIR/poses.csv``, ``DIR/tracking.csv``)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

__all__ = ["plot_tracking", "write_csv"]


def write_csv(path: str | Path, columns, rows) -> None:
    """Write ``rows`` under the header ``columns`` as CSV (floats in full precision: repr),
    atomically."""
    from .. import io  # noqa: PLC0415

    with io.atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        writer.writerows(rows)


def plot_tracking(fly: Any, tracked: Any, path: str | Path) -> None:
    """A PNG of the track: rotation and translation errors per frame (log scale; lost frames
    marked), the range, and the points per frame, against time. Written atomically."""
    import numpy as np  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    from .. import io  # noqa: PLC0415

    t = tracked.t_s
    lost = tracked.lost
    fig = Figure(figsize=(8.0, 8.5), layout="constrained")
    ax_r, ax_t, ax_d, ax_n = fig.subplots(4, 1, sharex=True)
    kind = fly.scene.trajectory.kind
    summary = tracked.summary()
    fig.suptitle(
        f"Pose track of the {fly.target_name or 'target'} ({kind}, {len(t)} frames, "
        f"{fly.scene.detector.pixels} px): {summary['n_lost']} lost\n"
        f"lost rule: {tracked.lost_rule}",
        fontsize=9,
    )
    floor = 1e-4
    for ax, values, label in (
        (ax_r, tracked.rotation_error_deg, "rotation error [deg]"),
        (ax_t, tracked.translation_error_m, "translation error [m]"),
    ):
        v = np.maximum(values, floor)
        ax.semilogy(t[~lost], v[~lost], "o-", color="C0", ms=4, label="tracked")
        if lost.any():
            ax.semilogy(t[lost], v[lost], "x", color="C3", ms=7, label="lost")
        ax.set_ylabel(label)
        ax.legend(loc="best", fontsize=8)
    ax_r.axhline(1.0, color="0.5", lw=0.8, ls="--")
    ax_t.axhline(0.10, color="0.5", lw=0.8, ls="--")
    ax_d.plot(t, tracked.range_m, "o-", color="C1", ms=3)
    ax_d.set_ylabel("range [m]")
    ax_n.bar(t, tracked.points_used, width=0.6 * (np.ptp(t) / max(len(t) - 1, 1) or 1.0))
    ax_n.set_ylabel("points per frame")
    ax_n.set_xlabel("time [s]")
    for ax in (ax_r, ax_t, ax_d, ax_n):
        ax.grid(True, alpha=0.3)
    if fly.target_credit:
        fig.text(0.995, 0.002, fly.target_credit, ha="right", va="bottom", fontsize=7)
    with io.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
