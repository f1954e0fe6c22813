"""The plotly layout pieces the charts share: axes, a light layout, marker lines, notes."""

import math

from simcore.constants import C as C_M_S


def axis(title: str, **extra) -> dict:
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
        "xaxis": axis(x_title),
        "yaxis": axis(y_title),
        **extra,
    }


def vline(x: float, color: str) -> dict:
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


def note(text: str) -> dict:
    return {
        "text": text,
        "xref": "paper",
        "yref": "paper",
        "x": 0.5,
        "y": 0.5,
        "showarrow": False,
        "font": {"size": 13, "color": "#757575"},
    }


def nice_step(span: float, n_ticks: int = 6) -> float:
    """A 1, 2 or 5 x 10^k step that cuts ``span`` into about ``n_ticks`` intervals."""
    raw = max(span, 1e-12) / n_ticks
    power = 10.0 ** math.floor(math.log10(raw))
    return next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw)


def _decimals(step: float) -> int:
    return max(0, -math.floor(math.log10(step) + 1e-9))


def time_axis(layout: dict, lo_ns: float, hi_ns: float) -> None:
    """The chart's time axis over [lo_ns, hi_ns]: ticks every 1, 2 or 5 x 10^k ns written in
    full with thousands separators (20,005 ns, not "20.005k"), to the step's decimals."""
    step = nice_step(hi_ns - lo_ns)
    layout["xaxis"].update(
        range=[lo_ns, hi_ns],
        tick0=0,
        dtick=step,
        tickformat=f",.{_decimals(step)}f",
        hoverformat=",.2f",
    )


def range_axis(layout: dict, lo_ns: float, hi_ns: float) -> dict:
    """A top axis giving the range c t / 2 [m] of the chart's times, inside the plot: its ticks
    at round ranges, placed on the time axis it follows (zoom and pan move both). Returns the
    empty trace that shows it (plotly draws an axis that a trace uses)."""
    lo_m, hi_m = lo_ns * 1e-9 * C_M_S / 2.0, hi_ns * 1e-9 * C_M_S / 2.0
    step = nice_step(hi_m - lo_m)
    first = math.ceil(lo_m / step)
    ranges = [k * step for k in range(first, math.floor(hi_m / step) + 1)]
    digits = _decimals(step)
    layout["xaxis2"] = {
        "matches": "x",
        "overlaying": "x",
        "side": "top",
        "showgrid": False,
        "zeroline": False,
        "showline": False,
        # inside the plot, along its top: clear of the legend above it
        "ticks": "inside",
        "ticklabelposition": "inside",
        "tickfont": {"size": 10, "color": "#616161"},
        "tickvals": [round(2.0 * r / C_M_S * 1e9, 6) for r in ranges],
        "ticktext": [f"{r:,.{digits}f} m" for r in ranges],
    }
    return {
        "type": "scatter",
        "mode": "lines",
        "x": [lo_ns, hi_ns],
        "y": [None, None],
        "xaxis": "x2",
        "name": "range axis",
        "showlegend": False,
        "hoverinfo": "skip",
    }


def detection_text(w, taken_m: float = math.nan) -> str:
    """What became of a pixel's echo this frame: its range, or why it gave no point (its stop
    taken by a false alarm at ``taken_m`` [m], app.payloads.stats.taken_by_false_alarm_m; a
    likely echo missed by chance; or one too weak for the threshold)."""
    if w.detected and math.isfinite(w.range_m):
        return f"R = {w.range_m:.3f} m"
    if math.isfinite(taken_m):
        return f"not detected: taken by a false alarm at {taken_m:.1f} m (P_d {w.p_detect:.2f})"
    if w.p_detect >= 0.5:
        return f"not detected: P_d {w.p_detect:.2f}, missed by chance this frame"
    return f"not detected (P_d {w.p_detect:.2f}: too weak for the threshold)"
