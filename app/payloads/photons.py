"""The Geiger-mode array's chart: the selected pixels' photon-count histograms of the frame's
pulses, with the counts expected without dead time or jitter drawn over them (their difference
at the echo's leading edge is the pile-up)."""

from __future__ import annotations

import math

import numpy as np

import simcore
from app.payloads.charts import base_layout, note
from app.payloads.style import SELECTION_COLORS
from simcore.receivers.gm_apd import frame_pulse_energy_j, photon_energy_j

MARGIN_BINS = 12  # bins shown either side of the echo's waveform
NO_ECHO_BINS = 80  # bins shown around the busiest bin of a pixel without an echo


def photon_figure(result: simcore.Result, selection: list) -> dict:
    """The plotly figure of the selected pixels' histograms (counts per TDC bin over
    ``gm.pulses`` pulses, against time since emission) and their expected counts."""
    scene, rx = result.scene, result.receiver
    gm, n = scene.gm, result.pixels
    data: list[dict] = []
    annotations: list[dict] = []
    for i, (row, col) in enumerate(selection):
        color = SELECTION_COLORS[i % len(SELECTION_COLORS)]
        flat = int(row) * n + int(col)
        bins, counts = rx.histogram.pixel_counts(flat)
        w = result.waveform(int(row), int(col))
        k0, k1 = _window_bins(w, bins, counts, rx.gate_start_s, gm.bin_s, rx.histogram.n_bins)
        shown = (bins >= k0) & (bins < k1)
        elsewhere = int(counts[~shown].sum())
        data.append(
            {
                "type": "bar",
                "x": _centre_ns(rx.gate_start_s, gm.bin_s, bins[shown]).tolist(),
                "y": counts[shown].tolist(),
                "width": gm.bin_s * 1e9,
                "name": f"({row}, {col}) counts"
                + (f", {elsewhere:,} more elsewhere in the gate" if elsewhere else ""),
                "marker": {"color": color, "opacity": 0.55},
                "hovertemplate": "%{x:.2f} ns: %{y} counts<extra></extra>",
            }
        )
        k = np.arange(k0, k1)
        expected = _expected_counts(result, w, flat, k)
        data.append(
            {
                "type": "scatter",
                "mode": "lines",
                "x": _centre_ns(rx.gate_start_s, gm.bin_s, k).tolist(),
                "y": expected.tolist(),
                "name": f"({row}, {col}) expected (no dead time, no jitter)",
                "line": {"color": color, "width": 1.5, "shape": "hvh"},
                "hovertemplate": "%{x:.2f} ns: %{y:.3g} expected<extra></extra>",
            }
        )
    if not selection:
        annotations.append(note("Click a pixel of the detector array to see its photon counts"))
    layout = base_layout(
        "time since emission (ns)",
        f"avalanches per {gm.bin_s * 1e12:.0f} ps bin ({gm.pulses} pulses)",
        legend={"orientation": "h", "x": 0, "y": 1.01, "yanchor": "bottom", "font": {"size": 10}},
        annotations=annotations,
        barmode="overlay",
        hovermode="closest",
    )
    layout["margin"]["t"] = 10 + 18 * math.ceil(len(data) / 2)
    return {"data": data, "layout": layout}


def _centre_ns(gate_start_s: float, bin_s: float, k: np.ndarray) -> np.ndarray:
    """Time since emission of bin ``k``'s centre [ns]."""
    return (gate_start_s + (np.asarray(k) + 0.5) * bin_s) * 1e9


def _window_bins(w, bins, counts, gate_start_s: float, bin_s: float, n_bins: int):
    """The bins to draw: the echo's waveform span with a margin, else around the busiest bin."""
    if len(w.t_s):
        lo = math.floor((w.t_s[0] - gate_start_s) / bin_s) - MARGIN_BINS
        hi = math.ceil((w.t_s[-1] - gate_start_s) / bin_s) + MARGIN_BINS
    elif len(bins):
        busiest = int(bins[np.argmax(counts)])
        lo, hi = busiest - NO_ECHO_BINS // 2, busiest + NO_ECHO_BINS // 2
    else:
        lo, hi = 0, NO_ECHO_BINS
    return max(lo, 0), min(max(hi, lo + 1), n_bins)


def _expected_counts(result: simcore.Result, w, flat: int, k: np.ndarray) -> np.ndarray:
    """Mean avalanches per bin over the frame without dead time or jitter: pulses x bin x
    (PDE x the echo's photon rate P_r(t) / (h nu) + the pixel's background and dark rate)."""
    scene, rx = result.scene, result.receiver
    gm = scene.gm
    t = rx.gate_start_s + (k + 0.5) * gm.bin_s
    echo_w = np.interp(t, w.t_s, w.power_w, left=0.0, right=0.0) if len(w.t_s) else 0.0 * t
    # the waveform is the laser pulse's; the frame's pulses carry it less the attenuation
    echo_w = echo_w * frame_pulse_energy_j(scene) / scene.laser.pulse_energy_j
    rate_hz = gm.pde * echo_w / photon_energy_j(scene.laser.wavelength_m) + rx.rate_hz[flat]
    return gm.pulses * gm.bin_s * rate_hz
