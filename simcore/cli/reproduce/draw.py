"""The drawing helpers of ``lmapd reproduce``: figures, the material legend, point-cloud panels and
the single-pixel echo panel (matplotlib, imported only when a figure is drawn)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...constants import C
from ...materials import MATERIAL_NAMES
from ...pipeline import Result
from ...reproduce import fwhm_s
from ...result import n_peaks as count_peaks

# Colours of the library materials (index = material id) and of the false alarms.
MATERIAL_COLORS = ("#7f7f7f", "#17becf", "#1f5fbf", "#d4a017", "#3a9a3a", "#9467bd")
OUTLIER_COLOR = "#d62728"
VIEW_HALF_M = 9.0  # [m] half width of the point-cloud panels around the target centre
CLOUD_NOTE = (
    "false alarms: all over the 1 km range gate (in view: inside the 18 m cube the two views show)"
)


def new_figure(width_in: float, height_in: float):
    from matplotlib.figure import Figure  # noqa: PLC0415  (heavy; only when plotting)

    return Figure(figsize=(width_in, height_in), layout="constrained")


def material_legend(fig, present: set[int], outliers: bool, credit: str | None) -> None:
    from matplotlib.lines import Line2D  # noqa: PLC0415

    handles = [
        Line2D([], [], ls="", marker="o", ms=6, color=MATERIAL_COLORS[m], label=MATERIAL_NAMES[m])
        for m in sorted(present)
    ]
    if outliers:
        handles.append(
            Line2D([], [], ls="", marker="x", ms=6, color=OUTLIER_COLOR, label="false alarm")
        )
    if credit:  # the model's credit as the legend's last entry, so that it never overlaps it
        handles.append(Line2D([], [], ls="", label=f"   {credit}"))
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=len(handles),
        fontsize=8.5,
        handletextpad=0.3,
    )


def credit_line(fig, credit: str) -> None:
    """The model's credit line at the bottom right, inside the constrained layout."""
    fig.supxlabel(credit, x=0.995, ha="right", fontsize=7)


def marker_size(result: Result, half_width_m: float, panel_in: float) -> float:
    """Scatter marker area [pt^2] about one pixel footprint at the target, at least 0.25."""
    footprint_m = result.scene.pose.distance_m * result.scene.ifov_rad
    points_per_m = 72.0 * panel_in / (2.0 * half_width_m)
    return max(0.25, (0.9 * footprint_m * points_per_m) ** 2)


def draw_cloud(ax_front, ax_top, result: Result, title: str, panel_in: float) -> set[int]:
    """Front view (image x right, up) and, if ``ax_top`` is given, top view (x, depth behind the
    target centre) of one cloud, coloured by material; false alarms inside the panels as red
    crosses. Returns the material ids drawn."""
    pts = result.points
    attrs = result.attributes
    out = attrs["is_outlier"]
    mat = attrs["material_id"]
    depth = pts[:, 2] - result.scene.pose.distance_m
    x, up = pts[:, 0], -pts[:, 1]
    h = VIEW_HALF_M
    size = marker_size(result, h, panel_in)
    tgt = ~out
    colors = np.array(MATERIAL_COLORS)[np.maximum(mat[tgt], 0)]
    views = [(ax_front, up)] + ([(ax_top, depth)] if ax_top is not None else [])
    # false alarms spread over the whole range gate: draw those inside the panels' cube only
    in_cube = out & (np.abs(x) <= h) & (np.abs(up) <= h) & (np.abs(depth) <= h)
    for ax, vertical in views:
        ax.scatter(x[tgt], vertical[tgt], s=size, c=colors, marker="s", linewidths=0)
        inside = in_cube
        ax.scatter(x[inside], vertical[inside], s=14, c=OUTLIER_COLOR, marker="x", linewidths=0.8)
        ax.set_xlim(-h, h)
        ax.set_ylim(-h, h)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.25)
    ax_front.set_title(
        f"{title}\n{int(tgt.sum())} points, {int(out.sum())} false alarms ({int(in_cube.sum())} "
        "in view)",
        fontsize=8,
    )
    ax_front.set_xlabel("x (image right) [m]", fontsize=7)
    ax_front.set_ylabel("up [m]", fontsize=7)
    if ax_top is not None:
        ax_top.set_xlabel("x (image right) [m]", fontsize=7)
        ax_top.set_ylabel("depth behind centre [m] (lidar below)", fontsize=7)
    return {int(m) for m in np.unique(mat[tgt])}


def plot_waveform(ax, result: Result, info: dict[str, Any], title: str) -> dict[str, Any]:
    """Draw one pixel's echo (raw, band-limited, emitted pulse, threshold, timing, the sub-ray
    delays of Eq. 29) on ``ax``; return its numbers."""
    e = result.echo
    wf = result.waveform(info["row"], info["col"])
    t0 = 2.0 * result.scene.pose.distance_m / C
    t_ns = (wf.t_s - t0) * 1e9
    i = info["index"]
    has = e.weights[i] > 0
    # the emitted pulse, band-limited, scaled to the echo's peak and delayed by the true range
    emitted_ns = (wf.emitted_t_s + 2.0 * wf.range_true_m / C - t0) * 1e9
    scale = 1e6  # W -> uW
    top = scale * float(wf.filtered_w.max())
    ax.plot(t_ns, scale * wf.power_w, color="0.55", lw=1.0, label="P_r(t), before the band limit")
    ax.plot(t_ns, scale * wf.filtered_w, color="C0", lw=1.8, label="y(t), band-limited (120 MHz)")
    ax.plot(
        emitted_ns,
        scale * wf.emitted_w,
        color="C3",
        lw=1.2,
        ls="--",
        label="emitted pulse, band-limited, scaled, delayed to R",
    )
    ax.axhline(scale * wf.threshold_w, color="k", lw=0.8, ls=":", label="threshold TNR sigma_n")
    ax.axvline((wf.t_half_s - t0) * 1e9, color="C2", lw=0.9, label="half-maximum time (Eq. 31)")
    w = e.weights[i][has]
    ax.vlines((e.arrivals_s[i][has] - t0) * 1e9, 0.0, 0.25 * top * w / w.max(), color="C1", lw=0.6)
    ax.plot([], [], color="C1", lw=0.6, label="sub-ray delays 2 r_k / c and weights (Eq. 29)")
    ax.set_ylim(-0.03 * top, 1.75 * top)
    ax.set_xlabel("time after 2 D / c  [ns]   (D = 500 m, the target centre)")
    ax.set_ylabel("received power [uW]")
    metres = ax.secondary_xaxis("top", functions=(lambda t: 0.5e-9 * C * t, lambda r: 2e9 * r / C))
    metres.set_xlabel("range behind the target centre [m]", fontsize=8)
    metres.tick_params(labelsize=7)
    n_peaks = count_peaks(wf.filtered_w)
    fwhm, ref_fwhm = fwhm_s(wf.t_s, wf.filtered_w), fwhm_s(wf.emitted_t_s, wf.emitted_w)
    ax.set_title(
        f"{title}\npixel (row {info['row']}, col {info['col']}): {' + '.join(info['parts'])}, "
        f"SNR {float(result.receiver.snr[i]):.0f}\n"
        f"depth span {info['depth_span_m']:.2f} m, rms {info['depth_rms_m']:.3f} m; {n_peaks} "
        f"peak(s); FWHM {1e9 * fwhm:.2f} ns (pulse {1e9 * ref_fwhm:.2f} ns)",
        fontsize=8.5,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    return {
        **info,
        "n_peaks": n_peaks,
        "snr": float(result.receiver.snr[i]),
        "peak_power_w": float(result.receiver.peak_power_w[i]),
        "range_true_m": wf.range_true_m,
        "range_m": wf.range_m,
        "fwhm_s": fwhm,
        "emitted_fwhm_s": ref_fwhm,
        "fwhm_ratio": fwhm / ref_fwhm,
        "t_s": wf.t_s.tolist(),
        "power_w": wf.power_w.tolist(),
        "filtered_w": wf.filtered_w.tolist(),
        "arrivals_s": e.arrivals_s[i][has].tolist(),
        "weights_per_j": w.tolist(),
    }
