"""The photon-count chart (``chart = "counts"`` in a receiver's declaration: the Geiger-mode
array's): the selected pixels' photon-count histograms of the frame's
pulses, with the counts expected from the same pulses drawn over them (dead time, jitter and
bins included: what the histogram should show on average) and the counts that would come
without dead time (on their own axis when they dwarf the histogram: their difference from the
measured counts at the echo's leading edge is the pile-up)."""

from __future__ import annotations

import math

import numpy as np

import simcore
from app.payloads.charts import base_layout, detection_text, note, range_axis, time_axis
from app.payloads.style import SELECTION_COLORS
from simcore import receivers
from simcore.constants import C as C_M_S

MARGIN_BINS = 12  # bins shown either side of the echo's waveform
NO_ECHO_BINS = 80  # bins shown around the busiest bin of a pixel without an echo
OWN_AXIS_RATIO = 2.0  # the no-dead-time curve gets its own axis when it peaks this much higher


def photon_figure(result: simcore.Result, selection: list) -> dict:
    """The plotly figure of the selected pixels' histograms (counts per TDC bin over
    ``gm.pulses`` pulses, against time since emission), their expected counts with the dead
    time, and without it (right-hand axis when it would flatten the histogram)."""
    view = receivers.resolve(receivers.get(result.scene.receiver.kind).counts)(result)
    n = result.pixels
    bars: list[dict] = []
    with_dead: list[dict] = []
    without: list[dict] = []
    annotations: list[dict] = []
    span: list[float] = []
    for i, (row, col) in enumerate(selection):
        color = SELECTION_COLORS[i % len(SELECTION_COLORS)]
        flat = int(row) * n + int(col)
        bins, counts = view.pixel_counts(flat)
        w = result.waveform(int(row), int(col))
        k0, k1 = _window_bins(w, bins, counts, view.gate_start_s, view.bin_s, view.n_bins)
        shown = (bins >= k0) & (bins < k1)
        elsewhere = int(counts[~shown].sum())
        x_bars = _centre_ns(view.gate_start_s, view.bin_s, bins[shown])
        bars.append(
            {
                "type": "bar",
                "x": x_bars.tolist(),
                "y": counts[shown].tolist(),
                "customdata": _range_m(x_bars).tolist(),
                "width": view.bin_s * 1e9,
                "name": f"({row}, {col}) measured counts"
                + (f", {elsewhere:,} more elsewhere in the gate" if elsewhere else "")
                + ("" if w.detected else f"; {detection_text(w)}"),
                "marker": {"color": color, "opacity": 0.6},
                "hovertemplate": "%{x:,.2f} ns (%{customdata:,.2f} m): %{y} counts"
                "<extra>measured</extra>",
            }
        )
        k = np.arange(k0, k1)
        x = _centre_ns(view.gate_start_s, view.bin_s, k)
        span += [float(x[0]) - view.bin_s * 1e9, float(x[-1]) + view.bin_s * 1e9]
        common = {"type": "scatter", "mode": "lines", "x": x.tolist()}
        common["customdata"] = _range_m(x).tolist()
        with_dead.append(
            {
                **common,
                "y": np.round(view.expected(w, flat, k0, k1), 4).tolist(),
                "name": f"({row}, {col}) expected (same pulses, dead time and jitter)",
                "line": {"color": color, "width": 2, "shape": "hvh"},
                "hovertemplate": "%{x:,.2f} ns (%{customdata:,.2f} m): %{y:.3g} expected"
                "<extra>with dead time</extra>",
            }
        )
        without.append(
            {
                **common,
                "y": np.round(view.arriving(w, flat, k), 4).tolist(),
                "name": f"({row}, {col}) without dead time",
                "line": {"color": color, "width": 1.2, "dash": "dot", "shape": "hvh"},
                "hovertemplate": "%{x:,.2f} ns (%{customdata:,.2f} m): %{y:.3g} expected"
                "<extra>without dead time</extra>",
            }
        )
    if not selection:
        annotations.append(note("Click a pixel of the detector array to see its photon counts"))
    left_peak = max([max(t["y"], default=0) for t in bars + with_dead] + [1.0])
    right_peak = max([max(t["y"], default=0) for t in without] + [0.0])
    own_axis = right_peak > OWN_AXIS_RATIO * left_peak
    layout = base_layout(
        "time since emission (ns)",
        f"avalanches per {view.bin_s * 1e12:.0f} ps bin ({view.pulses:,} pulses)",
        legend={"orientation": "h", "x": 0, "y": 1.01, "yanchor": "bottom", "font": {"size": 10}},
        annotations=annotations,
        barmode="overlay",
        hovermode="closest",
    )
    if own_axis:
        for trace in without:
            trace["yaxis"] = "y2"
            trace["name"] += " (right axis)"
        layout["yaxis2"] = {
            "title": {"text": "without dead time (right axis)", "font": {"color": "#757575"}},
            "overlaying": "y",
            "side": "right",
            "showgrid": False,
            "zeroline": False,
            "rangemode": "tozero",
            "ticks": "outside",
            "tickfont": {"color": "#757575"},
        }
        layout["margin"]["r"] = 60
    layout["yaxis"]["rangemode"] = "tozero"
    data = bars + with_dead + without
    if span:
        echo = _echo_span_ns(with_dead, view.bin_s * 1e9)
        whole = (min(span), max(span))
        if echo is not None and echo[1] - echo[0] < ZOOM_SHARE * (whole[1] - whole[0]):
            # opened on the echo, the whole window a click away (a button above the legend)
            layout["updatemenus"] = [_window_buttons(layout, echo, whole)]
            whole = echo
        time_axis(layout, *whole)
        data.append(range_axis(layout, *whole))
    layout["margin"]["t"] = 10 + 18 * math.ceil(len(bars) * 3 / 2)
    return {"data": data, "layout": layout}


ZOOM_SHARE = 0.6  # the chart opens on the echo when it spans less than this of the window
ECHO_LEVEL = 0.05  # the echo: the bins whose expected counts reach this share of their peak
ECHO_MARGIN_BINS = 4


def _echo_span_ns(expected: list[dict], bin_ns: float) -> tuple[float, float] | None:
    """The times [ns] of the selected pixels' echoes in the histogram: the bins whose expected
    counts (dead time included) reach ECHO_LEVEL of their pixel's peak, with a margin; None
    where no pixel has expected counts."""
    times: list[float] = []
    for trace in expected:
        y = np.asarray(trace["y"], dtype=np.float64)
        if len(y) and y.max() > 0:
            x = np.asarray(trace["x"], dtype=np.float64)[y >= ECHO_LEVEL * y.max()]
            times += [float(x[0]), float(x[-1])]
    if not times:
        return None
    margin = ECHO_MARGIN_BINS * bin_ns
    return min(times) - margin, max(times) + margin


def _window_buttons(layout: dict, echo: tuple[float, float], whole: tuple[float, float]) -> dict:
    """Two buttons that set the time axis (and its range axis above) to the echo or to the
    whole window the chart holds."""

    def axes(lo: float, hi: float) -> dict:
        scratch = {"xaxis": {}}
        time_axis(scratch, lo, hi)
        range_axis(scratch, lo, hi)
        top = scratch["xaxis2"]
        return {
            **{f"xaxis.{key}": value for key, value in scratch["xaxis"].items()},
            "xaxis2.tickvals": top["tickvals"],
            "xaxis2.ticktext": top["ticktext"],
        }

    return {
        "type": "buttons",
        "direction": "left",
        "showactive": True,
        "active": 0,
        "x": 1.0,
        "xanchor": "right",
        "y": 1.0,
        "yanchor": "top",
        "pad": {"r": 4, "t": 4},
        "font": {"size": 10},
        "buttons": [
            {"label": "Echo", "method": "relayout", "args": [axes(*echo)]},
            {"label": "Whole window", "method": "relayout", "args": [axes(*whole)]},
        ],
    }


def _range_m(t_ns: np.ndarray) -> np.ndarray:
    """The range a time since emission means, c t / 2 [m], to the centimetre."""
    return np.round(np.asarray(t_ns) * 1e-9 * C_M_S / 2.0, 2)


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
