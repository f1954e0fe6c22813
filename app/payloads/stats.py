"""The stats panel: the summary with units, the stage timings, the SNR histogram."""

from __future__ import annotations

import math

import numpy as np

import simcore
from app.payloads.charts import base_layout, note, vline
from app.payloads.encode import si_text
from app.payloads.style import SNR_FLOOR
from simcore import receivers


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
        {"label": "Unlit pixels (outside the beam)", "value": fmt(summary.get("n_unlit"), ",d")},
        {
            "label": "Pixels seeing the target",
            "value": f"{summary['n_hit_pixels']:,d} of {summary['n_pixels']:,d}",
        },
        {"label": "Pixels with an echo (lit)", "value": fmt(summary.get("n_lit_pixels"), ",d")},
        {"label": "Mean detection probability", "value": fmt(summary["p_detect_mean"], ".3f")},
        {"label": _snr_label(summary), "value": fmt(summary["snr_median"], ".3g")},
        {
            "label": "Median range σ",
            "value": "–" if sigma is None else f"{sigma * 100:.3g} cm",
        },
        *_background_rows(summary),
        *_receiver_rows(summary),
    ]


CHANCE_P_D = 0.5  # a pixel missed with at least this P_d was missed by chance, not too weak
CHANCE_LABEL = f"Missed by chance (P_d ≥ {CHANCE_P_D:g})"
TAKEN_LABEL = "Taken by a false alarm (its stop used)"


def taken_by_false_alarm_m(result: simcore.Result) -> np.ndarray:
    """(n,) per lit pixel (aligned with ``result.echo.pixel``): the range [m] of the false alarm
    that took the stop the echo needed, NaN where none did, as the scene's receiver declares it
    (``Receiver.stops_taken``); all NaN for a receiver without such stops (the Geiger-mode
    array's histogram)."""
    step = receivers.get(result.scene.receiver.kind).stops_taken
    if step is None:
        return np.full(len(result.echo.pixel), np.nan)
    return np.asarray(receivers.resolve(step)(result), dtype=np.float64)


def with_chance_misses(rows: list[dict], result: simcore.Result) -> list[dict]:
    """``rows`` with, after the dropped pixels, how many of them lost their echo's stop to an
    earlier false alarm (:func:`taken_by_false_alarm_m`), and how many others had an echo
    likely to be detected (P_d >= 0.5): missed by chance this frame (the noise pulled them under
    the threshold; another seed detects most of them), not for want of signal."""
    d = result.detection
    taken = np.isfinite(taken_by_false_alarm_m(result))
    chance = ~np.asarray(d.detected) & (np.asarray(d.p_detect) >= CHANCE_P_D) & ~taken
    added = [
        {"label": TAKEN_LABEL, "value": f"{int(np.count_nonzero(taken)):,d}"},
        {"label": CHANCE_LABEL, "value": f"{int(np.count_nonzero(chance)):,d}"},
    ]
    at = next((i for i, r in enumerate(rows) if r["label"] == "Dropped pixels (missed)"), None)
    return rows + added if at is None else [*rows[: at + 1], *added, *rows[at + 1 :]]


# a stats row's glossary entry (app.ui.glossary), by the start of its label: its info button
STAT_TERMS: tuple[tuple[str, str], ...] = (
    ("Points", "Point cloud"),
    ("Target points", "Point cloud"),
    ("Outliers", "Outlier"),
    ("Dropped pixels", "P_d"),
    ("Taken by a false alarm", "Stop"),
    ("Missed by chance", "P_d"),
    ("Unlit pixels", "Pixel"),
    ("Pixels seeing the target", "Pixel"),
    ("Pixels with an echo", "Echo"),
    ("Mean detection probability", "P_d"),
    ("Median SNR", "SNR"),
    ("Median count SNR", "SNR"),
    ("Median range σ", "σ (sigma)"),
    ("Median range error", "Range"),
    ("Sun from the line of sight", "Background light"),
    ("Sunlit / Earth pixels", "Background light"),
    ("Median background power", "Background light"),
    ("Pixels in background light", "Background light"),
    ("Max background current", "Background light"),
    ("Background share of noise", "Shot noise"),
    ("Background light", "Background light"),
    ("Receiver", "Lidar"),
)


def with_terms(rows: list[dict]) -> list[dict]:
    """``rows`` with, for a row whose label :data:`STAT_TERMS` knows, its glossary ``term``
    (the page's info button opens the glossary there; a test checks each has an entry)."""
    out = []
    for row in rows:
        term = next((t for start, t in STAT_TERMS if row["label"].startswith(start)), None)
        out.append(row if term is None else {**row, "term": term})
    return out


BACKGROUND_LABEL = "Median background power (pixels in light)"
RANGE_ERROR_LABEL = "Median range error (against the noise-free range)"


def frame_rows(rows: list[dict], result: simcore.Result) -> list[dict]:
    """The stats rows of a frame shown: ``rows`` (:func:`stats_rows` of its summary) with what
    the frame's arrays add: the dropped pixels' causes (:func:`with_chance_misses`), the
    median range error beside the median range sigma (the cards quote one or the other: both
    are shown, each named for what it is), and the background power as the median over the
    pixels the background lights, with how many they are (a median over every lit pixel read
    0 W where most of the target was in shade beside a 36.6 nA maximum)."""
    rows = with_chance_misses(rows, result)
    d = result.detection
    hit = np.asarray(d.detected, dtype=bool)
    error = np.abs(np.asarray(d.range_m) - np.asarray(d.range_true_m))[hit]
    error_row = {
        "label": RANGE_ERROR_LABEL,
        "value": "–" if not len(error) else f"{float(np.median(error)) * 100:.3g} cm",
    }
    out = []
    for row in rows:
        if row["label"] == "Median background power" and result.background is not None:
            power = np.asarray(result.background.power_w).ravel()
            lit = power[power > 0]
            median = float(np.median(lit)) if len(lit) else 0.0
            out.append({"label": BACKGROUND_LABEL, "value": si_text(median, "W")})
            share = f"{len(lit):,d} of {len(power):,d} ({100 * len(lit) / len(power):.0f} %)"
            out.append({"label": "Pixels in background light", "value": share})
            continue
        out.append(row)
        if row["label"] == "Median range σ":
            out.append(error_row)
    return with_terms(out)


def _declared(summary: dict) -> receivers.Receiver:
    """The declaration of the frame's receiver (its stats rows and the words for its SNR)."""
    return receivers.get(summary.get("receiver_kind", receivers.DEFAULT_KIND))


def _snr_label(summary: dict) -> str:
    """The SNR row's name: the receiver's (a Geiger-mode frame's SNR is its counts', not one
    flash's)."""
    return _declared(summary).snr_stats_label


def _receiver_rows(summary: dict) -> list[dict]:
    """The receiver, and the rows its declaration adds (the Geiger-mode array's frame's photon
    figures): each row's text formatted from the summary's ``scene`` and noise figures
    (``noise``), left out where a figure it needs is missing."""
    declared = _declared(summary)
    fields = {
        "scene": summary.get("scene") or {},
        "noise": summary.get("noise_figures") or {},
        "summary": summary,
    }
    rows = [{"label": "Receiver", "value": _format(declared.description, fields) or declared.kind}]
    for row in declared.stats_rows:
        value = _format(row.text, fields)
        if value is not None:
            rows.append({"label": row.label, "value": value})
    return rows


def _format(text: str, fields: dict) -> str | None:
    """``text`` formatted from ``fields``; None where a value it names is missing."""
    try:
        return text.format(**fields)
    except (KeyError, IndexError, TypeError, ValueError):
        return None


def _background_rows(summary: dict) -> list[dict]:
    """By day: the Sun's angle, sunlit and Earth pixels, the median background power and its
    share of the noise (from the receiver's figures); one row saying so at night."""
    scene_sun = (summary.get("scene") or {}).get("sun") or {}
    if scene_sun.get("mode", "none") == "none":
        return [{"label": "Background light", "value": "none (no Sun)"}]
    if summary.get("eclipsed"):
        return [{"label": "Background light", "value": "none (target in the Earth's shadow)"}]
    sunlit, earth = summary.get("n_sunlit_pixels", 0), summary.get("n_earth_pixels", 0)
    rows = [
        {"label": "Sun from the line of sight", "value": f"{summary.get('sun_angle_deg', 0):.1f}°"},
        {"label": "Sunlit / Earth pixels", "value": f"{sunlit:,d} / {earth:,d}"},
        {
            "label": "Median background power",
            "value": si_text(summary.get("background_power_w_median", 0.0), "W"),
        },
    ]
    figures = summary.get("noise_figures") or {}
    current = figures.get("background_current_a_max")
    if current is not None:
        rows.append({"label": "Max background current", "value": si_text(current, "A")})
    share = figures.get("background_noise_share_median")
    if share is not None:
        rows.append({"label": "Background share of noise var.", "value": f"{100 * share:.0f} %"})
    if summary.get("n_saturated"):
        rows.append(
            {"label": "Saturated pixels (no point)", "value": f"{summary['n_saturated']:,d}"}
        )
    return rows


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
    declared = receivers.get(result.scene.receiver.kind)
    title = f"{declared.snr_name} (log scale)"
    layout = base_layout(title, "pixels", bargap=0.0, showlegend=False)
    layout["margin"] = {"l": 48, "r": 8, "t": 8, "b": 38}
    if snr.size == 0:
        layout["annotations"] = [note("No echo")]
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
    centres = (edges[:-1] + edges[1:]) / 2
    bars = {
        "type": "bar",
        "x": centres.tolist(),
        "y": counts.tolist(),
        "marker": {"color": "#5c6bc0"},
        "customdata": (10**centres).tolist(),
        "hovertemplate": "SNR ≈ %{customdata:.3g}: %{y} pixels<extra></extra>",
    }
    if not declared.threshold_on_snr_axis:  # e.g. in counts (from TNR's false-alarm rate)
        return {"data": [bars], "layout": layout}
    layout["shapes"] = [vline(math.log10(tnr), "#d62728")]
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
    return {"data": [bars], "layout": layout}


def quality_rows(quality: dict) -> list[dict]:
    """The frame scored against the target's true mesh (``Result.quality``): the figures a
    student reads as "how good is this cloud", each with its unit."""

    def mm(value, signed: bool = False) -> str:
        if value is None:
            return "n/a (no target point)"
        return f"{1e3 * value:+.1f} mm" if signed else f"{1e3 * value:.1f} mm"

    tau_cm = 100 * quality["tau_m"]
    return [
        {
            "label": f"Precision (within {tau_cm:g} cm of the target)",
            "value": f"{quality['precision']:.1%}",
        },
        {
            "label": f"Recall (seen surface within {tau_cm:g} cm of a point)",
            "value": f"{quality['recall']:.1%}",
        },
        {"label": "F-score", "value": f"{quality['f_score']:.3f}"},
        {"label": "Range bias (median error)", "value": mm(quality["range_bias_m"], signed=True)},
        {"label": "Range error RMS (line of sight)", "value": mm(quality["range_rmse_m"])},
        {
            "label": "Point-to-mesh distance, median",
            "value": mm(quality["distance_to_mesh_median_m"]),
        },
        {"label": "Range error, 95 % within", "value": mm(quality["range_error_p95_m"])},
        {
            "label": "Target points > tau off",
            "value": f"{quality['target_outlier_fraction']:.1%}",
        },
        {
            "label": "False alarms (of all points)",
            "value": f"{quality['false_alarm_fraction']:.1%}",
        },
        {"label": "Point density", "value": f"{quality['point_density_per_m2']:.3g} per m²"},
    ]
