"""Pixel selection and the waveform chart: which pixels the chart shows, and their echoes."""

from __future__ import annotations

import math

import numpy as np

import simcore
from app.payloads import encode, photons
from app.payloads.charts import base_layout, detection_text, note, range_axis, time_axis, vline
from app.payloads.stats import taken_by_false_alarm_m
from app.payloads.style import SELECTION_COLORS
from simcore import receivers
from simcore.constants import C as C_M_S


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
    """Selected (row, col) pixels of an n_from array mapped to the same spots of an n_to array
    (the pixels that hold their centres' directions, for one field of view)."""
    if n_from == n_to:
        return [[int(r), int(c)] for r, c in pixels]
    return pixels_of_tangents(pixel_tangents(pixels, n_from, 1.0), n_to, 1.0)


def pixel_tangents(pixels, n: int, fov_rad: float) -> tuple[tuple[float, float], ...]:
    """The focal-plane tangents (x/f, y/f) of the centres of (row, col) pixels of an n x n array
    of full field of view ``fov_rad`` [rad] (the grid of ``simcore.geometry.subray_tangents``)."""
    pitch = 2.0 * math.tan(fov_rad / 2.0) / n
    return tuple(
        ((int(c) - (n - 1) / 2.0) * pitch, (int(r) - (n - 1) / 2.0) * pitch) for r, c in pixels
    )


def pixels_of_tangents(tangents, n: int, fov_rad: float) -> list[list[int]]:
    """The (row, col) pixels of an n x n array of field of view ``fov_rad`` [rad] that see the
    directions of focal-plane tangents (x/f, y/f), in order, each once; directions outside the
    field of view have none."""
    pitch = 2.0 * math.tan(fov_rad / 2.0) / n
    out: list[list[int]] = []
    for tx, ty in tangents:
        # (a centre on a boundary of the new grid, 64 -> 256 say, goes to the larger index)
        rc = [math.floor(ty / pitch + n / 2.0 + 1e-9), math.floor(tx / pitch + n / 2.0 + 1e-9)]
        if 0 <= rc[0] < n and 0 <= rc[1] < n and rc not in out:
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


OWN_AXIS_SHARE = 0.05  # a background level under this share of the echo's peak gets its own axis
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


def _waveform_traces(
    w: simcore.Waveform, color: str, scale: float, taken_m: float = math.nan
) -> list[dict]:
    """Filtered and raw echo, the delayed emitted pulse and the half-maximum mark of one pixel
    (``taken_m``: the false alarm that took its stop [m], NaN if none)."""
    name = f"({w.row}, {w.col}) {detection_text(w, taken_m)}"
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


def taken_of(result: simcore.Result):
    """(row, col) -> the range [m] of the false alarm that took the pixel's stop this frame, NaN
    where none did (app.payloads.stats.taken_by_false_alarm_m)."""
    taken = taken_by_false_alarm_m(result)
    index = {int(p): i for i, p in enumerate(result.echo.pixel[np.isfinite(taken)])}
    values = taken[np.isfinite(taken)]

    def at(row: int, col: int) -> float:
        i = index.get(int(row) * result.pixels + int(col))
        return math.nan if i is None else float(values[i])

    return at


def waveform_figure(result: simcore.Result, selection: list) -> dict:
    """The plotly figure of the selected pixels' echoes (several pixels overlaid): received power
    vs time since emission, the emitted pulse for reference, the half-maximum marks, the
    threshold and the detected ranges. A receiver whose declaration asks for another chart gets
    it (``counts``: the photon-count histograms of app.payloads.photons)."""
    chart = CHARTS.get(receivers.get(result.scene.receiver.kind).chart)
    if chart is not None:
        return chart(result, selection)
    waves = [result.waveform(int(r), int(c)) for r, c in selection]
    taken = taken_of(result)
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
        data += _waveform_traces(w, color, scale, taken(w.row, w.col))
        t_det = _detected_time_ns(w)
        if t_det is not None:
            shapes.append(vline(t_det, color))
    times = [t for w in waves for t in (w.t_s[:1].tolist() + w.t_s[-1:].tolist())]
    right_axis = None  # the background's own axis, when it needs one
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
        background = _background_traces(waves, result.scene.timing.tnr, times, scale)
        level = max((max(abs(y) for y in t["y"]) for t in background), default=0.0)
        if background and level < OWN_AXIS_SHARE * peak / scale:
            # a steady level and a noise band too small to see on the echo's axis: their own
            bg_scale, bg_prefix = encode.si_prefix(level * scale)
            for trace in background:
                trace["y"] = [y * scale / bg_scale for y in trace["y"]]
                trace["yaxis"] = "y2"
                trace["name"] += " (right axis)"
            right_axis = f"background, noise ({bg_prefix}W, right axis)"
        data += background
    if not waves:
        annotations.append(note("Click a pixel of the detector array to see its echo"))
    elif not any(len(w.t_s) for w in waves):
        annotations.append(note("No echo in the selected pixel(s)"))
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
    if right_axis:
        layout["yaxis2"] = {
            "title": {"text": right_axis, "font": {"color": "#ef6c00"}},
            "overlaying": "y",
            "side": "right",
            "showgrid": False,
            "zeroline": False,
            "ticks": "outside",
            "tickfont": {"color": "#ef6c00"},
        }
        layout["margin"]["r"] = 60
    layout["xaxis"]["tickformat"] = ",.0f"
    layout["xaxis"]["hoverformat"] = ",.2f"
    if times:
        lo_ns, hi_ns = min(times) * 1e9, max(times) * 1e9
        time_axis(layout, lo_ns, hi_ns)
        data.append(range_axis(layout, lo_ns, hi_ns))
    return {"data": data, "layout": layout}


# the pixel charts a receiver's declaration may ask for besides the echo waveform (``chart``)
CHARTS = {"counts": photons.photon_figure}


def view_text(kind: str) -> dict[str, str]:
    """The waveform chart's title and caption and the SNR chart's caption for a receiver, from
    its declaration (the caption lists its chart's series)."""
    declared = receivers.get(kind)
    return {
        "waveform_title": declared.chart_title,
        "waveform_caption": " · ".join(s.text() for s in declared.chart_series),
        "snr_caption": declared.snr_caption,
    }


def _background_traces(waves: list, tnr: float, times: list, scale: float) -> list[dict]:
    """By day: the first selected pixel's background power (a steady level, which the AC-coupled
    readout removes: only its shot noise stays) and the noise band +-sigma_n (threshold / TNR)
    about zero. Nothing at night."""
    w = waves[0]
    if w.background_w <= 0 or not math.isfinite(w.threshold_w):
        return []
    x = [min(times) * 1e9, max(times) * 1e9]
    sigma = w.threshold_w / tnr
    band = {
        "type": "scatter",
        "mode": "lines",
        "x": x + x[::-1],
        "y": [sigma / scale] * 2 + [-sigma / scale] * 2,
        "fill": "toself",
        "fillcolor": "rgba(255, 179, 0, 0.18)",
        "line": {"width": 0},
        "name": f"noise ±σn = {encode.si_text(sigma, 'W')} (threshold ÷ TNR)",
        "hoverinfo": "skip",
    }
    level = {
        "type": "scatter",
        "mode": "lines",
        "x": x,
        "y": [w.background_w / scale] * 2,
        "name": f"background {encode.si_text(w.background_w, 'W')} (steady: AC-coupled out)",
        "line": {"color": "#ff8f00", "width": 1.5, "dash": "dot"},
        "hovertemplate": "%{y:.4g}<extra>background</extra>",
    }
    return [band, level]


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
