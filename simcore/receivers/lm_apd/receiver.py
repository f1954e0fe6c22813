"""The linear-mode APD receiver (Eqs. 7-28): the paper's chain, ``receiver.kind = "lm_apd"``.

Response (Eqs. 7-18): the APD's gain and responsivity, the peak signal current of each echo, its
SNR after the amplifier chain and the noise at the peak. Background light (the background stage)
adds its primary photocurrent's shot noise, with gain and excess noise, to each pixel's noise
(docs/physics.md#background-noise): the readout is AC-coupled, so its DC level goes and its
noise stays. Detection, in the statistical noise
model (Section 4): the threshold V_T = TNR sigma_n, P_d (Eq. 27) drawn per pixel, the CFD and
quantisation range sigma (Eqs. 24-26) drawn as range noise, Rice false alarms (Eq. 28) drawn as
outliers; in the Monte Carlo model (Section 5) noisy waveforms through the discriminator decide
detections, ranges and false alarms instead (P_d and sigma stay the statistical model's).

The model: docs/physics.md#receiver, docs/physics.md#detection, docs/physics.md#monte-carlo.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...background import Background
from ...echo import EchoStage
from ...pulse import A_FWHM
from ...scene import Scene, SceneError
from ..records import Detection, Response
from . import apd, detection, timing

MAX_OUTLIERS = (
    5_000_000  # false alarms per flash at most (K per pixel bounds them; 1024^2 x 16 not)
)


@dataclass(frozen=True, kw_only=True)
class LmApdResponse(Response):
    """The LM-APD's response; besides :class:`Response`, per lit pixel (n,):

    model : the detector constants (gain, responsivity, fixed noise terms)
    i_pk_a : peak signal current [A]
    sigma_pk_a : noise at the peak, shot + dark + thermal (+ background shot) through the chain
        (Eq. 27) [A rms]
    ``snr`` is SNR_na of Eq. 18 (with the background's shot noise in its noise).
    Per pixel of the array (pixels**2,), flat index, None without background light:
    background_a : the background's mean current at the APD output, R_resp P_bg [A] (removed
        by the AC coupling; its shot noise stays)
    sigma_n_pixel_a : each pixel's signal-free noise, sqrt(F_chain (i_nd^2 + i_nt^2 + 2 q B
        i_bg0 M^2 F)) [A rms]
    And per lit pixel (n,): saturated, the echo's peak plus the background current exceed
    ``detector.linear_max_a`` (flagged: such a pixel gives no point).
    """

    model: apd.ReceiverModel
    i_pk_a: np.ndarray
    sigma_pk_a: np.ndarray
    background_a: np.ndarray | None = None
    sigma_n_pixel_a: np.ndarray | None = None
    saturated: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True)
class LmApdDetection(Detection):
    """The LM-APD's detection; besides :class:`Detection`, ``threshold_a``: V_T = TNR sigma_n
    [A] (``threshold_w`` is V_T over the responsivity)."""

    threshold_a: float
    threshold_pixel_w: np.ndarray | None = None
    saturated: np.ndarray | None = None


def respond(scene: Scene, echo: EchoStage, background: Background) -> LmApdResponse:
    """Eqs. 7-18 for every lit pixel's band-limited peak (the unfiltered one with the paper's
    Eq. 14 form), the background's shot noise in each pixel's noise."""
    rx = apd.receiver_model(
        scene.detector, scene.amplifiers, scene.laser.wavelength_m, paper_qe=scene.uses("qe_paper")
    )
    energy_j = scene.laser.pulse_energy_j
    peak_w = echo.features.peak_w_per_j * energy_j
    snr_peak_w = peak_w
    if scene.uses("unfiltered_peak"):
        raw_w_per_j = echo.features.peak_raw_w_per_j
        assert raw_w_per_j is not None  # the echo stage keeps it for this option
        snr_peak_w = raw_w_per_j * energy_j
    i_pk_a = rx.responsivity_a_w * snr_peak_w
    if background.any_light:
        return _respond_with_background(scene, echo, background, rx, peak_w, i_pk_a)
    return LmApdResponse(
        peak_power_w=peak_w,
        snr=rx.snr(i_pk_a),
        noise_figures=_noise_figures(rx),
        model=rx,
        i_pk_a=i_pk_a,
        sigma_pk_a=rx.sigma_peak_a(i_pk_a),
        saturated=_saturated(scene, rx, peak_w, 0.0),
    )


def _saturated(scene: Scene, rx: apd.ReceiverModel, peak_w, background_a) -> np.ndarray:
    """(n,) bool: the band-limited echo peak plus the background current exceed the chain's
    linear range ``detector.linear_max_a``."""
    return rx.responsivity_a_w * peak_w + background_a > scene.detector.linear_max_a


def _respond_with_background(scene, echo, background, rx, peak_w, i_pk_a) -> LmApdResponse:
    """Eqs. 7-18 with the background's shot noise (Eq. 10 for its current R_resp P_bg) in each
    pixel's noise: the SNR of Eq. 18 is i_pk / sigma_pk, sigma_pk the noise at the peak with
    the background (docs/physics.md#background-noise)."""
    background_a = rx.responsivity_a_w * np.asarray(background.power_w, dtype=np.float64).ravel()
    sigma_n_pixel_a = rx.sigma_peak_a(background_a)  # shot(i_bg) + dark + thermal, the chain
    lit_bg_a = background_a[echo.pixel]
    sigma_pk_a = rx.sigma_peak_a(i_pk_a + lit_bg_a)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.minimum(np.where(sigma_pk_a > 0, i_pk_a / sigma_pk_a, np.inf), rx.snr_max)
    figures = _noise_figures(rx)
    figures["background_current_a_max"] = float(background_a.max())
    figures["sigma_n_pixel_a_max"] = float(sigma_n_pixel_a.max())
    # the background's share of each pixel's signal-free noise variance [1]
    share = 1.0 - (rx.sigma_n_a / np.maximum(sigma_n_pixel_a, rx.sigma_n_a)) ** 2
    figures["background_noise_share_max"] = float(share.max())
    figures["background_noise_share_median"] = (
        float(np.median(share[echo.pixel])) if len(echo.pixel) else 0.0
    )
    return LmApdResponse(
        peak_power_w=peak_w,
        snr=snr,
        noise_figures=figures,
        model=rx,
        i_pk_a=i_pk_a,
        sigma_pk_a=sigma_pk_a,
        background_a=background_a,
        sigma_n_pixel_a=sigma_n_pixel_a,
        saturated=_saturated(scene, rx, peak_w, lit_bg_a),
    )


def _noise_figures(rx: apd.ReceiverModel) -> dict[str, float]:
    return {
        "gain": rx.gain,
        "responsivity_a_w": rx.responsivity_a_w,
        "excess_noise": rx.excess_noise,
        "chain_noise_factor": rx.chain_noise_factor,
        "dark_noise_a": rx.dark_noise_a,
        "thermal_noise_a": rx.thermal_noise_a,
        "sigma_n_a": rx.sigma_n_a,
    }


def _response_reads(s: Scene) -> tuple:
    return (
        s.laser.pulse_energy_j,
        s.laser.wavelength_m,
        s.detector,
        s.amplifiers,
        (s.uses("qe_paper"), s.uses("unfiltered_peak")),
    )  # detector.linear_max_a is in s.detector


def detect(scene: Scene, echo: EchoStage, rx: LmApdResponse) -> LmApdDetection:
    """Section 4 (or 5 with ``fidelity.noise_model = "montecarlo"``, or "photon" for its
    photon statistics, docs/physics.md#mcintyre): detections, ranges and
    false alarms of one flash, seeded from the scene, each pixel recording at most
    ``timing.max_stops`` stops (docs/physics.md#limited-stops). With background light each
    pixel has its own noise: the threshold is TNR x a dark pixel's noise (``timing.
    threshold_mode = global``) or TNR x the pixel's own (``per_pixel``); P_d, the range sigma and
    the false alarms follow from each pixel's noise (docs/physics.md#background-noise)."""
    t = scene.timing
    rng = np.random.default_rng([scene.seed, 2024])
    threshold_a = t.tnr * rx.model.sigma_n_a
    threshold_pixel_a = pixel_thresholds_a(scene, rx)  # (N,) or None (all = threshold_a)
    threshold_lit_a = threshold_a if threshold_pixel_a is None else threshold_pixel_a[echo.pixel]
    sigma_m = range_sigma_m(scene, echo, rx)
    r_true_m = timing.range_from_half_max_m(echo.features.t_half_s, echo.shape.t_half_s)
    n_false = false_alarms_per_pixel(scene, _effective_tnr(scene, rx, threshold_pixel_a))
    lo, hi = gate_m(scene)
    p_echo = detection_probability(scene, rx, threshold_lit_a)
    holdoff_s = stop_holdoff_s(scene, echo)
    # the chance that noise stops used up the pixel's stops before its echo (K = 1:
    # 1 - exp(-nu t_e)), in the detection probability
    n_false_lit = n_false[echo.pixel] if isinstance(n_false, np.ndarray) else n_false
    rate_hz = n_false_lit / (2.0 * (hi - lo) / timing.C)
    t_echo_s = 2.0 * (r_true_m - lo) / timing.C
    p_d = p_echo * detection.echo_survival_probability(t_echo_s, rate_hz, t.max_stops, holdoff_s)

    n = len(echo.pixel)
    if scene.fidelity.noise_model in ("montecarlo", "photon"):
        # Section 5: noisy waveforms through the discriminator decide detections, ranges and
        # false alarms; P_d and sigma above stay the statistical model's, for comparison
        from . import montecarlo  # noqa: PLC0415  (imported only when the MC model is asked for)

        extra: dict[str, Any] = {}
        if rx.background_a is not None:
            extra = {
                "background_a": rx.background_a,
                "per_pixel_threshold": t.threshold_mode == "per_pixel",
            }
        mc = montecarlo.montecarlo_detection(
            rng, echo, rx.model, scene, max_stops=t.max_stops, holdoff_s=holdoff_s, **extra
        )
        drawn, r_meas_m, outliers = mc.detected, mc.range_m, mc.outliers
    else:  # Section 4: Eq. 27 draws the detection, Eq. 24 the range noise, Eq. 28 the outliers
        drawn = rng.random(n) < p_echo
        noise = rng.standard_normal(n)
        with np.errstate(invalid="ignore"):
            r_meas_m = r_true_m + np.where(drawn, sigma_m * noise, 0.0)
        r_meas_m = _gross_errors(scene, echo, rx, r_true_m, r_meas_m, drawn, holdoff_s)
        drawn, outliers = _limited_stops(
            rng, scene, echo.pixel, np.where(drawn, r_meas_m, np.nan), n_false, holdoff_s
        )
    detected = drawn & np.isfinite(r_meas_m) & (r_meas_m >= lo) & (r_meas_m <= hi)
    if rx.saturated is not None and rx.saturated.any():
        detected = detected & ~rx.saturated  # beyond the linear range: flagged, no point
    r_meas_m = np.where(detected, r_meas_m, np.nan)
    to_w = 1.0 / rx.model.responsivity_a_w
    false_points = detection.expected_false_points(
        n_false, scene.detector.pixels**2, lo, hi, t.max_stops, 0.5 * timing.C * holdoff_s,
        echo.pixel, r_true_m, p_echo,
    )  # fmt: skip
    return LmApdDetection(
        p_detect=p_d,
        detected=detected,
        range_true_m=r_true_m,
        range_sigma_m=sigma_m,
        range_m=r_meas_m,
        threshold_w=threshold_a / rx.model.responsivity_a_w,
        n_false_per_pixel=n_false,
        outliers=outliers,
        threshold_a=threshold_a,
        threshold_pixel_w=None if threshold_pixel_a is None else threshold_pixel_a * to_w,
        saturated=rx.saturated,
        summary_figures={"n_false_points_expected": false_points},
    )


def _gross_errors(scene, echo, rx: LmApdResponse, r_true_m, r_meas_m, drawn, holdoff_s):
    """(n,) ranges with the discriminator's gross errors drawn where the SNR is low enough for
    them (docs/physics.md#gross-errors), from a stream of their own: the other draws of the
    flash do not move. The Monte Carlo's table is computed (and cached) only when a drawn echo
    is in its SNR range."""
    t = scene.timing
    from . import gross_errors as gross  # noqa: PLC0415  (only when needed)

    in_range = drawn & (rx.snr <= gross.snr_grid(t.tnr + gross.TNR_STEP)[-1])
    if not in_range.any():
        return r_meas_m
    gross.check_calibration_cost(echo.shape.tau_s, scene.detector.bandwidth_hz, echo.dt_s, t.tnr)
    table = gross.gross_errors_at(
        rx.model, echo.shape.tau_s, echo.shape.a, scene.detector.bandwidth_hz, echo.dt_s,
        echo.cfd_delay_s, t.cfd_fraction, t.tnr, t.resolution_s, holdoff_s,
    )  # fmt: skip
    rng = np.random.default_rng([scene.seed, 2024, 25])
    return detection.draw_gross_errors(
        rng, r_meas_m, r_true_m, drawn, table.probability_at(rx.snr), table.displacement_m
    )


def pixel_thresholds_a(scene: Scene, rx: LmApdResponse) -> np.ndarray | None:
    """(pixels**2,) each pixel's arming threshold TNR sigma_n,pixel [A] with
    ``timing.threshold_mode = per_pixel`` and background light; None where every pixel has the
    global threshold TNR sigma_n of a dark pixel."""
    if scene.timing.threshold_mode != "per_pixel" or rx.sigma_n_pixel_a is None:
        return None
    return scene.timing.tnr * rx.sigma_n_pixel_a


def _effective_tnr(scene: Scene, rx: LmApdResponse, threshold_pixel_a) -> float | np.ndarray:
    """The threshold over each pixel's own signal-free noise (pixels**2,), or the scene's TNR
    where all pixels share it (no background, or per-pixel thresholds)."""
    if rx.sigma_n_pixel_a is None or threshold_pixel_a is not None:
        return scene.timing.tnr
    return scene.timing.tnr * rx.model.sigma_n_a / rx.sigma_n_pixel_a


def gate_m(scene: Scene) -> tuple[float, float]:
    """The range gate [max(0, R_st - R_gate / 2), R_st + R_gate / 2] [m]."""
    half = scene.timing.range_gate_m / 2.0
    return max(0.0, scene.gate_center_m - half), scene.gate_center_m + half


def stop_holdoff_s(scene: Scene, echo: EchoStage) -> float:
    """The re-arm hold-off after a stop: ``timing.rearm_holdoff_fwhm`` FWHMs of the emitted
    pulse [s] (one by default, the Monte Carlo's)."""
    return scene.timing.rearm_holdoff_fwhm * echo.shape.tau_s * A_FWHM / echo.shape.a


def _limited_stops(rng, scene, echo_pixel, echo_range_m, n_false, holdoff_s):
    """The echo stops (n,) bool and the false alarms of one pulse, at most K stops per pixel.

    While the expected noise stops per pixel are at most K, every noise up-crossing is drawn as
    Section 4 step 5 always did (Poisson count over the array, uniform pixel and range) and the
    stops are picked from them and the echoes (so a K that never binds gives the unlimited
    draw); above, they are drawn stop by stop (``detection.draw_limited_stops``), in memory and
    time O(pixels x K). Both sample the same process."""
    t = scene.timing
    lo, hi = gate_m(scene)
    n_pixels = scene.detector.pixels**2
    holdoff_m = 0.5 * timing.C * holdoff_s
    if np.max(n_false) > t.max_stops:
        rate_per_m = n_false / (hi - lo)
        return detection.draw_limited_stops(
            rng, n_pixels, echo_pixel, echo_range_m, rate_per_m, lo, hi, t.max_stops, holdoff_m
        )
    if isinstance(n_false, np.ndarray):  # each pixel its own rate (background light)
        outliers = detection.draw_outliers_per_pixel(rng, n_false, lo, hi)
    else:
        outliers = detection.draw_outliers(
            rng, n_pixels, n_false, scene.gate_center_m, t.range_gate_m
        )
    is_echo = np.isfinite(echo_range_m) & (echo_range_m >= lo) & (echo_range_m <= hi)
    pixel = np.concatenate([outliers.pixel, np.asarray(echo_pixel)[is_echo]])
    range_m = np.concatenate([outliers.range_m, echo_range_m[is_echo]])
    stop = detection.limited_stops(pixel, range_m, t.max_stops, holdoff_m)
    n_out = len(outliers.pixel)
    echo_stop = np.zeros(len(echo_range_m), dtype=bool)
    echo_stop[np.flatnonzero(is_echo)[stop[n_out:]]] = True
    keep = stop[:n_out]
    if not keep.all():
        outliers = detection.Outliers(pixel=outliers.pixel[keep], range_m=outliers.range_m[keep])
    return echo_stop, outliers


def detection_probability(scene: Scene, rx: LmApdResponse, threshold_a) -> np.ndarray:
    """(n,) Eq. 27, ours (the peak's own shot noise, and the background's) or as printed
    (thermal only). ``threshold_a``: V_T [A], one for all or (n,) per lit pixel."""
    if scene.uses("eq27_paper"):
        return detection.detection_probability_paper(rx.snr, scene.timing.tnr)
    return detection.detection_probability(rx.i_pk_a, threshold_a, rx.sigma_pk_a)


def range_sigma_m(scene: Scene, echo: EchoStage, rx: LmApdResponse) -> np.ndarray:
    """(n,) Eq. 24: the CFD jitter (Eq. 25: ours, each sample with its own noise; or the paper
    forms ``eq25_equal_noise``, ``eq25_risetime``) with the quantisation (Eq. 26)."""
    t = scene.timing
    if scene.uses("eq25_risetime"):
        rise_s = timing.rise_time_10_90_s(echo.shape)
        s_cfd_m = timing.sigma_cfd_paper_m(rx.snr, t.cfd_fraction, rise_s)
    elif scene.uses("eq25_equal_noise"):
        s_cfd_m = timing.sigma_cfd_m(
            rx.snr,
            echo.features.cfd_slope_per_s,
            t.cfd_fraction,
            echo.cfd_delay_s,
            echo.shape.sigma_h_s,
        )
    else:
        s_cfd_m = sigma_cfd_per_sample_m(scene, echo, rx)
    return timing.range_sigma_m(s_cfd_m, timing.sigma_quantisation_m(t.resolution_s))


def sigma_cfd_per_sample_m(scene: Scene, echo: EchoStage, rx: LmApdResponse) -> np.ndarray:
    """(n,) Eq. 25 (ours): each CFD sample with the shot noise of its own signal current
    (Eq. 10) besides the dark and thermal noise, through the chain, and their covariance from
    the current midway between them (``EchoFeatures.cfd_shot_level``). With a saturation
    (``detector.snr_max``) the jitter is at least the equal-noise form's at that SNR."""
    i_pk_a = rx.model.responsivity_a_w * rx.peak_power_w  # the band-limited peak
    level = echo.features.cfd_shot_level
    if rx.background_a is None:
        delayed_a, prompt_a, mid_a = (rx.model.sigma_peak_a(i_pk_a * level[:, j]) for j in range(3))
    else:  # each sample's shot noise with the background's current added
        bg_a = rx.background_a[echo.pixel]
        delayed_a, prompt_a, mid_a = (
            rx.model.sigma_peak_a(i_pk_a * level[:, j] + bg_a) for j in range(3)
        )
    args = (scene.timing.cfd_fraction, echo.cfd_delay_s, echo.shape.sigma_h_s)
    slope = echo.features.cfd_slope_per_s
    sigma_m = timing.sigma_cfd_per_sample_m(
        i_pk_a, delayed_a, prompt_a, slope, *args, sigma_mid_a=mid_a
    )
    if np.isfinite(rx.model.snr_max):
        sigma_m = np.maximum(sigma_m, timing.sigma_cfd_m(rx.model.snr_max, slope, *args))
    return sigma_m


def false_alarms_per_pixel(scene: Scene, tnr=None) -> float | np.ndarray:
    """Eq. 28 (Rice, or as printed) over the gate: the expected noise up-crossings per pixel,
    at the scene's TNR or at ``tnr`` ((pixels**2,): each pixel's threshold over its own noise,
    an array out). Refused where the stops they give, at most K per pixel, exceed MAX_OUTLIERS
    per flash."""
    t, bandwidth_hz = scene.timing, scene.detector.bandwidth_hz
    tnr = t.tnr if tnr is None else tnr
    if scene.uses("eq28_paper"):
        n_false = detection.false_alarms_per_pixel_paper(tnr, t.range_gate_m, bandwidth_hz)
    else:
        n_false = detection.false_alarms_per_pixel(tnr, t.range_gate_m, bandwidth_hz)
    if isinstance(n_false, np.ndarray):
        expected = float(np.minimum(n_false, t.max_stops).sum())
    else:
        expected = min(n_false, t.max_stops) * scene.detector.pixels**2
    if expected > MAX_OUTLIERS:
        raise SceneError(
            f"timing.max_stops = {t.max_stops} at timing.tnr = {t.tnr:g} gives about "
            f"{expected:.3g} false alarms per flash over the {t.range_gate_m:g} m gate, more than "
            f"the {MAX_OUTLIERS:,} this simulator draws; lower timing.max_stops, raise the TNR "
            "or shorten timing.range_gate_m"
        )
    return n_false


def _detection_reads(s: Scene) -> tuple:
    return (
        s.timing,
        s.fidelity.noise_model,
        s.seed,
        s.gate_center_m,
        s.detector.pixels,
        s.detector.bandwidth_hz,
        s.detector.linear_max_a,
        tuple(s.uses(f) for f in ("eq25_risetime", "eq25_equal_noise", "eq27_paper", "eq28_paper")),
    )
