"""The Geiger-mode detection stage (a threshold change re-runs only this): each pixel's densest
window of the width of the pulse, its counts against a threshold set from the expected
background counts for the false-alarm probability of a Gaussian threshold at ``timing.tnr``
(:mod:`.windows`), and the range by the centroid of the (Coates-corrected, ``gm.coates``)
histogram around it (:mod:`.histogram`), or by the first-photon fit of its first avalanches
(``gm.pileup_correction = "fit"``, :mod:`.first_photon`). A detected window on the echo gives
the pixel's point; one elsewhere (background, dark counts) an outlier. Each lit pixel's range
bias and sd as that estimator gives them at any flux (pile-up, finite pulses) are predicted from
its expected histogram (:mod:`.figures`): ``range_sigma_m`` and the summary's ``gm.*`` figures;
the expected false points from the scan statistic (:mod:`.false_points`). The single-pulse
first-photon ranges are kept for :func:`simcore.pointcloud.first_photon_cloud`.

The model: docs/physics.md#geiger-mode.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import special

from ...constants import C
from ...echo import EchoStage
from ...scene import Scene
from ..records import Outliers
from . import first_photon as fp
from . import histogram as gh
from .false_points import expected_false_points
from .figures import (
    _pileup_timing,
    analysis_window,
    measured_figures,
    pileup_figures,
    predicted_range_m,
    selection_offsets_m,
)
from .frame import ECHO_TAIL_SCALES, JITTER_REACH
from .records import GmDetection, GmResponse
from .windows import (
    _echo_span_s,
    _inside_gate,
    _predicted,
    _threshold_power_w,
    echo_armed_probability,
    false_alarm_probability,
    threshold_counts,
    window_bins,
)


def detect(scene: Scene, echo: EchoStage, rx: GmResponse) -> GmDetection:
    """Peak windows, thresholds, ranges, outliers and the first-photon cloud of the frame."""
    gm, t = scene.gm, scene.timing
    h = rx.histogram
    n_pixels = scene.detector.pixels**2
    width = window_bins(scene, echo)
    s_scale = echo.shape.tau_s / echo.shape.a
    bg_per_bin = rx.rate_hz * gm.bin_s  # mean primary background events per pulse and bin
    mu_window = gm.pulses * bg_per_bin * width
    n_windows = h.n_bins / width
    p_fa = false_alarm_probability(t.tnr)
    k_t = threshold_counts(mu_window, n_windows, p_fa)

    peaks = gh.peak_windows(h, width)
    over = peaks.count >= k_t[peaks.pixel]
    p_pix, p_start = peaks.pixel[over], peaks.start_bin[over]
    # the analysis window: from one s and the jitter before the peak window to 12 s after it
    pre, length = analysis_window(scene, echo, h.n_bins)
    dead_bins = int(round(gm.dead_time_s / gm.bin_s)) if gm.dead_time_s < 1.0 else h.n_bins
    est = gh.centroid_times(
        h, p_pix, p_start - pre, length, gm.bin_s, bg_per_bin[p_pix], dead_bins, gm.coates
    )
    t_mean_s = rx.gate_start_s + est.t_s
    # range: the centroid less the mean photon delay of Eq. 1's pulse, 2 s (Gamma(2, s))
    r_est_m = 0.5 * C * (t_mean_s - 2.0 * s_scale)
    if gm.pileup_correction == "fit":
        first, armed = fp.first_events_histogram(
            rx.events, p_pix, p_start - pre, length, gm.pulses, dead_bins
        )
        fit = fp.fit_first_photon(
            _pileup_timing(scene, echo), first, armed, p_start - pre, bg_per_bin[p_pix]
        )
        r_est_m = 0.5 * C * (rx.gate_start_s + fit.t0_s)
    r_est_m = np.where(_inside_gate(scene, r_est_m), r_est_m, np.nan)

    lit_of = np.full(n_pixels, -1, dtype=np.int64)
    lit_of[echo.pixel] = np.arange(len(echo.pixel))
    first_s, last_s = _echo_span_s(echo)
    reach_s = JITTER_REACH * gm.jitter_s
    lo_bin = (first_s - reach_s - rx.gate_start_s) / gm.bin_s
    hi_bin = (last_s + ECHO_TAIL_SCALES * s_scale + reach_s - rx.gate_start_s) / gm.bin_s
    li = lit_of[p_pix]
    on_echo = np.zeros(len(p_pix), dtype=bool)
    lit_hit = li >= 0
    on_echo[lit_hit] = (p_start[lit_hit] + width > lo_bin[li[lit_hit]]) & (
        p_start[lit_hit] <= hi_bin[li[lit_hit]]
    )
    good = on_echo & np.isfinite(r_est_m)
    n = len(echo.pixel)
    detected = np.zeros(n, dtype=bool)
    detected[li[good]] = True
    range_m = np.full(n, np.nan)
    range_m[li[good]] = r_est_m[good]
    out = ~on_echo & np.isfinite(r_est_m)
    outliers = Outliers(pixel=p_pix[out].astype(np.int64), range_m=r_est_m[out])

    peak_counts = np.zeros(n)
    lit_peak = lit_of[peaks.pixel] >= 0
    peak_counts[lit_of[peaks.pixel[lit_peak]]] = peaks.count[lit_peak]
    counts_all = np.zeros(n_pixels)
    counts_all[p_pix] = peaks.count[over]

    a_num = np.asarray(echo.arrivals_s) * np.asarray(echo.weights)
    w_sum = np.asarray(echo.weights).sum(axis=1)
    r_true_m = 0.5 * C * a_num.sum(axis=1) / np.where(w_sum > 0, w_sum, 1.0)
    p_d, sigma_weak_m = _predicted(scene, echo, rx, k_t[echo.pixel])
    lit_k = k_t[echo.pixel]
    pred_m, sigma_m, skew, counts = predicted_range_m(scene, echo, rx, pre, length, lit_k)
    # where the expected histogram holds no excess over the background (a pixel detected by
    # chance), the weak-signal sd stands
    sigma_m = np.where(np.isfinite(sigma_m), sigma_m, sigma_weak_m)
    # at a few counts the threshold keeps the realisations whose counts bunch
    shift_m, median_m = selection_offsets_m(scene, echo, counts, lit_k, pre, length)
    figures = pileup_figures(
        scene, rx.signal_pe, pred_m - r_true_m, sigma_m, skew, detected, shift_m, median_m
    )
    figures.update(measured_figures(range_m - r_true_m, detected))
    false_pixel = np.minimum(1.0, n_windows * special.pdtrc(k_t - 1.0, mu_window))
    false_points = expected_false_points(scene, h.n_bins, width, rx.rate_hz, k_t, echo.pixel, p_d)
    fp_range, fp_echo = _first_photon(scene, rx, lo_bin, hi_bin, lit_of, s_scale)
    return GmDetection(
        p_detect=p_d,
        detected=detected,
        range_true_m=r_true_m,
        range_sigma_m=sigma_m,
        range_m=range_m,
        threshold_w=_threshold_power_w(scene, echo, float(np.median(k_t)), bg_per_bin, width),
        n_false_per_pixel=float(np.mean(false_pixel)),
        outliers=outliers,
        threshold_counts=k_t,
        peak_counts=peak_counts,
        first_photon_range_m=fp_range,
        first_photon_is_echo=fp_echo,
        point_attributes={
            "counts": (peak_counts, counts_all[outliers.pixel]),
            "signal_pe": (rx.signal_pe, np.zeros(len(outliers.pixel))),
        },
        summary_figures={"n_false_points_expected": false_points, **figures},
    )


def frame_warnings(scene: Scene, echo: EchoStage, rx: GmResponse, d: GmDetection) -> list[str]:
    """One line for each way a Geiger-mode frame's figures can mislead: a threshold most lit
    pixels cannot reach, pixels blinded by the background's dead time, detections ranged
    outside the gate."""
    gm, t = scene.gm, scene.timing
    out = []
    lit_k = np.asarray(d.threshold_counts)[echo.pixel]
    beyond = lit_k > gm.pulses
    if len(lit_k) and np.count_nonzero(beyond) * 2 > len(lit_k):
        out.append(
            f"{np.count_nonzero(beyond)} of {len(lit_k)} lit pixels cannot be detected: "
            f"timing.tnr = {t.tnr:g} sets their threshold (median {np.median(lit_k):.0f} "
            f"counts) above gm.pulses = {gm.pulses} (a window holds one avalanche a pulse); "
            "more gm.pulses or a lower timing.tnr"
        )
    armed = echo_armed_probability(scene, echo, rx.rate_hz[echo.pixel])
    if len(armed) and np.median(armed) < 0.5:
        out.append(
            f"the background and dark counts keep most lit pixels dead (gm.dead_time_s = "
            f"{gm.dead_time_s:g} s) when their echo arrives (median chance to be armed "
            f"{np.median(armed):.2g}): a shorter gm.dead_time_s, a narrower "
            "receive.filter_width_m or a gate that opens nearer the target"
        )
    over = np.asarray(d.peak_counts) >= lit_k
    lost = over & ~np.asarray(d.detected)
    lost[np.isin(echo.pixel, d.outliers.pixel)] = False
    if lost.any():
        out.append(
            f"{int(lost.sum())} lit pixels passed the threshold but their range fell outside "
            "the gate or had no excess over the background: no point (a piled-up echo "
            "ranges early)"
        )
    return out


def _detect_with_warnings(scene: Scene, echo: EchoStage, rx: GmResponse) -> GmDetection:
    """:func:`detect`, its summary figures joined by the frame's warnings (a list of lines)."""
    d = detect(scene, echo, rx)
    lines = frame_warnings(scene, echo, rx, d)
    if not lines:
        return d
    figures = dict(d.summary_figures)
    figures["warnings"] = [*figures.get("warnings", []), *lines]
    return dataclasses.replace(d, summary_figures=figures)


def _first_photon(scene, rx: GmResponse, lo_bin, hi_bin, lit_of, s_scale):
    """Each pixel's first avalanche of pulse 0 as a range (c/2 (t - 2 s)), and whether it fell
    in the echo's window."""
    n_pixels = scene.detector.pixels**2
    e = rx.events
    first = e.pulse == 0
    pix, b = e.pixel[first].astype(np.int64), e.bin[first].astype(np.int64)
    # events are sorted by pixel then bin: the first of each pixel is its earliest
    new = np.r_[True, pix[1:] != pix[:-1]] if len(pix) else np.zeros(0, bool)
    pix, b = pix[new], b[new]
    t_s = rx.gate_start_s + (b + 0.5) * scene.gm.bin_s
    range_m = np.full(n_pixels, np.nan)
    range_m[pix] = 0.5 * C * (t_s - 2.0 * s_scale)
    is_echo = np.zeros(n_pixels, dtype=bool)
    li = lit_of[pix]
    lit = li >= 0
    is_echo[pix[lit]] = (b[lit] >= lo_bin[li[lit]]) & (b[lit] <= hi_bin[li[lit]])
    return range_m, is_echo


def _detection_reads(s: Scene) -> tuple:
    return (s.timing.tnr, s.gm.coates, s.gm.pileup_correction)
