"""The Geiger-mode summary figures: each lit pixel's range bias, sd and skewness as the
frame's estimator gives them at any flux (the expected histogram, :mod:`.pileup`), the
``gm.*`` figures predicted from them and measured against the ground truth, and the pile-up
warning.

The model: docs/physics.md#gm-pileup.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from ...constants import C
from ...echo import EchoStage
from ...scene import Scene
from . import pileup as gp
from . import selection as gs
from .expected import Timing, with_threshold
from .frame import ECHO_TAIL_SCALES, JITTER_REACH, _gate_s, frame_pulse_energy_j, photon_energy_j
from .records import GmResponse
from .windows import echo_armed_probability, window_bins


def _pileup_timing(scene: Scene, echo: EchoStage) -> Timing:
    gm = scene.gm
    return Timing(
        scale_s=echo.shape.tau_s / echo.shape.a,
        jitter_s=gm.jitter_s,
        bin_s=gm.bin_s,
        dead_time_s=gm.dead_time_s,
        n_pulses=gm.pulses,
    )


def predicted_range_m(
    scene: Scene, echo: EchoStage, rx: GmResponse, pre: int, length: int, min_counts=1.0
):
    """(n,) each lit pixel's range as its histogram gives it on average (pile-up, the
    frame's finite pulses, jitter and bins included: :mod:`.pileup`), its sd [m], its
    skewness [1] and its expected signal counts in the window [1], for the frame's estimator
    (the centroid, or the first-photon fit of ``gm.pileup_correction``); ``min_counts``: the
    lit pixels' thresholds in counts. The centroid's prediction before the thresholds is the
    receiver stage's (``rx.expected``, :func:`expected_prediction`): a threshold change
    re-uses it."""
    if len(echo.pixel) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)
    expected = getattr(rx, "expected", None)
    if expected is not None:
        pred = with_threshold(expected, np.asarray(min_counts, dtype=np.float64))
    else:
        pred = _predict(scene, echo, rx.rate_hz, rx.histogram.n_bins, pre, length, min_counts)
    t_lo = rx.gate_start_s
    return 0.5 * C * (t_lo + pred.t_s), 0.5 * C * pred.sd_s, pred.skew, pred.signal_counts


def expected_prediction(scene: Scene, echo: EchoStage, rate_hz, n_bins: int):
    """The centroid's prediction of every lit pixel before the thresholds (``sd_s`` its
    variance per count, :func:`.pileup.predict_pixels` with ``min_counts`` None), as the
    receiver stage keeps it; None for the first-photon fit (its thresholds enter throughout)."""
    if scene.gm.pileup_correction == "fit":
        return None
    pre, length = analysis_window(scene, echo, n_bins)
    return _predict(scene, echo, rate_hz, n_bins, pre, length, None)


def analysis_window(scene: Scene, echo: EchoStage, n_bins: int) -> tuple[int, int]:
    """The analysis window around a pixel's peak window: from one s and the jitter before it
    (``pre`` bins) to 12 s after it, ``length`` bins in all (at most the gate's)."""
    gm = scene.gm
    s_scale = echo.shape.tau_s / echo.shape.a
    pre = int(np.ceil((s_scale + JITTER_REACH * gm.jitter_s) / gm.bin_s)) + 1
    length = pre + int(
        np.ceil((ECHO_TAIL_SCALES * s_scale + JITTER_REACH * gm.jitter_s) / gm.bin_s)
    )
    return pre, min(length, n_bins)


def _predict(scene: Scene, echo: EchoStage, rate_hz, n_bins: int, pre, length, min_counts):
    """:func:`.pileup.predict_pixels` of the lit pixels, times from the gate's opening."""
    gm = scene.gm
    t_lo = _gate_s(scene)[0]
    pe_per_weight = gm.pde * frame_pulse_energy_j(scene) / photon_energy_j(scene.laser.wavelength_m)
    element_pe = pe_per_weight * np.asarray(echo.weights)
    rate = np.asarray(rate_hz)[echo.pixel]
    return gp.predict_pixels(
        _pileup_timing(scene, echo),
        np.asarray(echo.arrivals_s) - t_lo,
        element_pe,
        rate,
        echo_armed_probability(scene, echo, rate),
        window_bins(scene, echo),
        pre,
        length,
        n_bins,
        gm.coates,
        gm.pileup_correction,
        min_counts,
    )


def selection_offsets_m(scene: Scene, echo: EchoStage, counts, k_t, pre: int, length: int):
    """(n,) what detection's threshold does to each lit pixel's centroid at a few counts
    (:mod:`.selection`): the detected pixels' mean error less the expected histogram's
    centroid [m] (0 beyond the table), and their median error less that centroid [m] (NaN
    beyond the table: the Cornish-Fisher term stands). Both 0 / NaN for the first-photon fit
    (not a centroid) and for analysis windows of more than gp.MAX_BINS bins (TDC bins far
    finer than the pulse)."""
    gm = scene.gm
    n = len(counts)
    zero, none = np.zeros(n), np.full(n, np.nan)
    if n == 0 or gm.pileup_correction == "fit" or length > gp.MAX_BINS:
        return zero, none
    if not np.any((counts > 0) & (counts <= gs.MU_MAX)):  # no pixel the table reaches
        return zero, none
    table = gs.selection_table(
        echo.shape.tau_s / echo.shape.a,
        gm.jitter_s,
        gm.bin_s,
        window_bins(scene, echo),
        int(pre),
        int(length),
        int(gm.pulses),
        bool(gm.coates),
    )
    shift_s, median_s = gs.selection_shifts(table, counts, gm.pulses, k_t)
    return 0.5 * C * shift_s, 0.5 * C * median_s


SATURATED_SHARE = 1.0 - np.exp(-1.0)  # a pixel is piled up when its echo fires it this often


def pileup_figures(
    scene: Scene,
    signal_pe,
    bias_m,
    sigma_m,
    skew,
    detected,
    shift_m=None,
    median_m=None,
) -> dict:
    """The summary's Geiger-mode figures, predicted for the histogram's estimator [m]: the
    range bias, the median of the detected pixels' errors (of the mixture of their laws, each
    N(m_i, sigma_i^2), pixels of different flux having different biases; m_i the median of
    pixel i's errors given that it is detected: where it has under one photoelectron per pulse,
    b_i plus ``median_m`` (detection's selection and the skewness of a few counts, from
    :mod:`.selection`) or, beyond that table, b_i - g_i sigma_i / 6 (the Cornish-Fisher term of
    its skewness g_i); b_i otherwise), and the scatter, the sd of those errors about their mean,
    sqrt(mean sigma_i^2 + Var b_i), b_i shifted by ``shift_m`` (the selection's shift of the
    detected pixels' mean); the share of lit pixels with over one photoelectron per pulse (their
    echo fires them in more than 1 - 1/e of the pulses: piled up), and a warning when most
    are."""
    n = len(bias_m)
    shift_m = np.zeros(n) if shift_m is None else np.asarray(shift_m, dtype=np.float64)
    median_m = np.full(n, np.nan) if median_m is None else np.asarray(median_m, dtype=np.float64)
    sel = detected & np.isfinite(bias_m) & np.isfinite(sigma_m)
    sat = float(np.mean(signal_pe > 1.0)) if len(signal_pe) else 0.0
    # the skewness of a centroid of few counts and the threshold's selection of them (not of
    # a piled-up estimate, whose law the rare re-armed pulses shape)
    starved = np.asarray(signal_pe)[sel] <= 1.0
    tabled = starved & np.isfinite(median_m[sel])
    median_i = np.where(
        tabled,
        bias_m[sel] + np.where(tabled, median_m[sel], 0.0),
        bias_m[sel] - np.where(starved, skew[sel], 0.0) * sigma_m[sel] / 6.0,
    )
    bias_m = bias_m + np.where(np.asarray(signal_pe) <= 1.0, shift_m, 0.0)
    bias = mixture_median(median_i, sigma_m[sel]) if sel.any() else None
    # the cloud's scatter about its mean: each pixel's sd and the spread of the pixels' biases
    spread = np.mean(sigma_m[sel] ** 2) + np.var(bias_m[sel]) if sel.any() else np.nan
    sigma = float(np.sqrt(spread)) if np.isfinite(spread) else None
    figures: dict = {
        "gm.range_bias_m": bias,
        "gm.range_sigma_m": sigma,
        "gm.saturated_pixel_fraction": sat,
        "gm.signal_pe_median": float(np.median(signal_pe)) if len(signal_pe) else 0.0,
        "gm.frame_pulse_energy_j": frame_pulse_energy_j(scene),
        "warnings": [],
    }
    if sat > 0.5:
        if scene.gm.pileup_correction == "fit":
            advice = "the first-photon fit corrects the ranges"
        else:
            advice = "raise gm.attenuation_db or set gm.pileup_correction = fit"
        figures["warnings"].append(
            f"Geiger mode: {100 * sat:.0f} % of the lit pixels are piled up (over one "
            f"photoelectron per pulse, median {figures['gm.signal_pe_median']:.3g}); range "
            f"bias {1e3 * (bias or 0.0):+.0f} mm (predicted): {advice}"
        )
    return figures


def mixture_median(mean, sd) -> float:
    """The median of an equal mixture of N(mean_i, sd_i^2) (bisection on the mixture's CDF,
    to a nanometre or 200 steps) [same unit]."""
    mean = np.asarray(mean, dtype=np.float64)
    sd = np.maximum(np.asarray(sd, dtype=np.float64), 1e-12)
    lo, hi = float(np.min(mean - 9 * sd)), float(np.max(mean + 9 * sd))
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if np.mean(special.ndtr((mid - mean) / sd)) < 0.5:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-9:
            break
    return 0.5 * (lo + hi)


def measured_figures(error_m, detected) -> dict:
    """The detected pixels' range error against the noise-free energy-weighted range: its
    median and its sd about the mean [m] (what the predicted figures are checked against)."""
    err = error_m[detected & np.isfinite(error_m)]
    return {
        "gm.range_error_median_m": float(np.median(err)) if len(err) else None,
        "gm.range_error_sd_m": float(np.std(err)) if len(err) > 1 else None,
    }
