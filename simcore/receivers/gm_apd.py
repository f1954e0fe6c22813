"""The Geiger-mode (single-photon) APD array, ``receiver.kind = "gm_apd"``.

Response (the receiver stage): every pixel's primary event rate, the echo's photoelectrons per
pulse (the frame's pulses carry ``laser.pulse_energy_j`` less ``gm.attenuation_db``: photon-starved
by default), and the frame itself: ``gm.pulses`` pulses of avalanches of every pixel
(:mod:`simcore.receivers.gm_events`: Poisson primaries from the optical echo of Eqs. 1, 29, 30,
background and dark counts; non-paralysable dead time reset per gate, jitter, TDC bins,
afterpulsing, crosstalk), kept as a sparse per-pixel histogram.

Detection (the detection stage; a threshold change re-runs only this): each pixel's densest
window of the width of the pulse, its counts against a threshold set from the expected
background counts for the false-alarm probability of a Gaussian threshold at ``timing.tnr``,
and the range by the centroid of the (Coates-corrected, ``gm.coates``) histogram around it
(:mod:`simcore.receivers.gm_histogram`), or by the first-photon fit of its first avalanches
(``gm.pileup_correction = "fit"``). A detected window on the echo gives the pixel's point;
one elsewhere (background, dark counts) an outlier. Each lit pixel's range bias and sd as that
estimator gives them at any flux (pile-up, finite pulses) are predicted from its expected
histogram (:mod:`simcore.receivers.gm_pileup`): ``range_sigma_m`` and the summary's ``gm.*``
figures. The single-pulse first-photon cloud is :func:`first_photon_cloud`.

The model: docs/physics.md#geiger-mode.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import special

from ..constants import C, H
from ..echo import EchoStage
from ..scene import Scene, SceneError
from . import Detection, Receiver, Response, register
from . import gm_events as ev
from . import gm_histogram as gh
from . import gm_pileup as gp
from .gm_limits import BYTES_PER_EVENT, MAX_EVENTS, armed_probability
from .lm_apd.detection import Outliers

MAX_EVENTS_PER_PULSE = 10_000  # expected avalanches of one pixel in one gate at most
ECHO_TAIL_SCALES = 12.0  # the analysis window runs 12 s past the echo (Gamma(2) tail 8e-5)
JITTER_REACH = 4.0  # jitter standard deviations the windows allow either side


def background_power_w(scene: Scene, background=None) -> np.ndarray:
    """(rows, cols) optical background power per pixel at the detector [W]: the background
    stage's ``power_w``, zeros where there is none (night, or no background stage)."""
    n = scene.detector.pixels
    if background is None:
        return np.zeros((n, n))
    power_w = np.asarray(getattr(background, "power_w", background), dtype=np.float64)
    if power_w.shape != (n, n):
        raise ValueError(f"background power_w has shape {power_w.shape}, expected {(n, n)}")
    return power_w


def photon_energy_j(wavelength_m: float) -> float:
    """h nu = h c / lambda [J]."""
    return H * C / wavelength_m


def frame_pulse_energy_j(scene: Scene) -> float:
    """The energy of the Geiger-mode frame's pulses, laser.pulse_energy_j attenuated by
    ``gm.attenuation_db``: E 10^(-A / 10) [J]."""
    return scene.laser.pulse_energy_j * 10.0 ** (-scene.gm.attenuation_db / 10.0)


@dataclass(frozen=True, kw_only=True)
class GmResponse(Response):
    """The Geiger-mode array's response; besides :class:`Response` (``snr``: the frame's
    expected signal counts over the square root of signal plus background counts in the peak
    window, S / sqrt(S + B)):

    signal_pe : (n,) mean echo photoelectrons per pulse of each lit pixel, PDE E_r / (h nu) [1]
    rate_hz : (pixels**2,) constant primary event rate of every pixel (background + dark) [1/s]
    events : the frame's recorded avalanches (sorted by pixel, bin, pulse)
    histogram : their sparse per-pixel histogram
    gate_start_s : time of the gate's opening since emission [s]
    """

    signal_pe: np.ndarray
    rate_hz: np.ndarray
    events: ev.Events
    histogram: gh.Histogram
    gate_start_s: float


@dataclass(frozen=True, kw_only=True)
class GmDetection(Detection):
    """The Geiger-mode detection; besides :class:`Detection` (``threshold_w``: the band-limited
    peak power of a single-surface echo whose expected peak-window counts reach the threshold):

    threshold_counts : (pixels**2,) counts a pixel's peak window must reach
    peak_counts : (n,) counts in each lit pixel's peak window (0 where it has no event)
    first_photon_range_m : (pixels**2,) range of each pixel's first avalanche of the frame's
        first pulse, NaN where none (the single-pulse first-photon cloud)
    first_photon_is_echo : (pixels**2,) bool, that avalanche came from the echo's window
    """

    threshold_counts: np.ndarray
    peak_counts: np.ndarray
    first_photon_range_m: np.ndarray
    first_photon_is_echo: np.ndarray


def _gate_s(scene: Scene) -> tuple[float, float]:
    """Gate opening since emission and gate length [s] (the LM-APD's gate)."""
    half = scene.timing.range_gate_m / 2.0
    lo = max(0.0, scene.gate_center_m - half)
    hi = scene.gate_center_m + half
    return 2.0 * lo / C, 2.0 * (hi - lo) / C


def _detector(scene: Scene) -> ev.Detector:
    gm = scene.gm
    return ev.Detector(
        gate_s=_gate_s(scene)[1],
        dead_time_s=gm.dead_time_s,
        jitter_s=gm.jitter_s,
        bin_s=gm.bin_s,
        afterpulsing=gm.afterpulsing,
        crosstalk=gm.crosstalk,
    )


def expected_load(scene: Scene, signal_pe, rate_hz, lit_pixel) -> tuple[float, float]:
    """The frame's load before any avalanche is drawn: the most avalanches one pixel records
    in one gate, and the avalanches of the whole frame (every pixel, ``gm.pulses`` pulses),
    from each pixel's primaries in the gate (its constant rate over the gate, plus its echo's
    photoelectrons) capped by the dead time, with crosstalk and afterpulsing.

    signal_pe : (n,) mean echo photoelectrons per pulse of the lit pixels ``lit_pixel`` [1]
    rate_hz : (pixels**2,) every pixel's constant primary rate [1/s]
    """
    gm = scene.gm
    gate_s = _gate_s(scene)[1]
    primaries = np.asarray(rate_hz, dtype=np.float64) * gate_s
    primaries[np.asarray(lit_pixel)] += signal_pe
    cap = 1.0 + gate_s / gm.dead_time_s if gm.dead_time_s > 0 else np.inf
    per_gate = np.minimum(primaries, cap) * (1.0 + gm.crosstalk) / (1.0 - gm.afterpulsing)
    worst = float(per_gate.max()) if len(per_gate) else 0.0
    return worst, float(per_gate.sum()) * gm.pulses


def _frame_rates(scene: Scene, echo: EchoStage, background) -> tuple[np.ndarray, np.ndarray]:
    """(n,) the lit pixels' echo photoelectrons per pulse and (pixels**2,) every pixel's
    constant primary rate [1/s], as :func:`respond` forms them."""
    hv_j = photon_energy_j(scene.laser.wavelength_m)
    signal_pe = scene.gm.pde * frame_pulse_energy_j(scene) * np.sum(echo.weights, axis=1) / hv_j
    bg_w = background_power_w(scene, background).reshape(-1)
    return signal_pe, scene.gm.pde * bg_w / hv_j + scene.gm.dark_count_rate_hz


def frame_load(scene: Scene, echo: EchoStage, background=None) -> tuple[float, float]:
    """:func:`expected_load` of ``scene``'s frame from its echo and background stages (an
    upper bound: a pixel's echo counts as all its photoelectrons up to the dead time's cap)."""
    signal_pe, rate_hz = _frame_rates(scene, echo, background)
    return expected_load(scene, signal_pe, rate_hz, echo.pixel)


_THROUGHPUT_A = np.logspace(-6.0, 12.0, 181)  # S d / s grid of :func:`_echo_throughput`


def _echo_throughput_table() -> np.ndarray:
    """F(a) = int x e^-x / (1 + a x e^-x) dx over x >= 0 on the grid ``_THROUGHPUT_A``."""
    x = np.linspace(0.0, 80.0, 8001)
    g = x * np.exp(-x)
    f = g[None, :] / (1.0 + _THROUGHPUT_A[:, None] * g[None, :])
    return np.sum((f[:, 1:] + f[:, :-1]) * 0.5 * np.diff(x)[None, :], axis=1)


_THROUGHPUT_F = _echo_throughput_table()


def frame_avalanches(scene: Scene, echo: EchoStage, background=None) -> float:
    """The avalanches ``scene``'s frame records on average, estimated before drawing any: per
    pixel and pulse, the constant rate's renewal throughput over the gate, r T / (1 + r d),
    plus the echo's: its rate S x e^-x / s (Eq. 1's Gamma(2, s) shape, x = t / s) through the
    dead time as a slowly varying renewal process, S F(S d / s) with
    F(a) = int x e^-x / (1 + a x e^-x) dx, at least 1 - e^-S (an echo shorter than the dead
    time fires once at most); times the crosstalk and afterpulsing factors and the pulses.
    Within 20 % of the recorded avalanches from the photon-starved to the piled-up frame
    (tests/app/test_app_budget.py)."""
    gm = scene.gm
    signal_pe, rate_hz = _frame_rates(scene, echo, background)
    gate_s = _gate_s(scene)[1]
    d = gm.dead_time_s
    per_pulse = float(np.sum(rate_hz * gate_s / (1.0 + rate_hz * d)))
    if len(signal_pe):
        a = signal_pe * d / (echo.shape.tau_s / echo.shape.a)
        log_f = np.interp(
            np.log(np.maximum(a, 1e-300)), np.log(_THROUGHPUT_A), np.log(_THROUGHPUT_F)
        )
        per_pulse += float(np.sum(np.maximum(-np.expm1(-signal_pe), signal_pe * np.exp(log_f))))
    return per_pulse * gm.pulses * (1.0 + gm.crosstalk) / (1.0 - gm.afterpulsing)


def _check_load(scene: Scene, signal_pe, rate_hz, lit_pixel) -> None:
    """Refuse frames whose expected avalanches exceed MAX_EVENTS (or one gate's exceed
    MAX_EVENTS_PER_PULSE), before drawing any: one message naming the keys to change."""
    gm = scene.gm
    worst, total = expected_load(scene, signal_pe, rate_hz, lit_pixel)
    if worst > MAX_EVENTS_PER_PULSE:
        raise SceneError(
            f"gm.dead_time_s = {gm.dead_time_s:g} s lets a pixel record about {worst:.3g} "
            f"avalanches per gate (at most {MAX_EVENTS_PER_PULSE:,}): give a longer dead time, "
            "less pulse energy or a shorter timing.range_gate_m"
        )
    if total > MAX_EVENTS:
        raise SceneError(
            f"gm.pulses = {gm.pulses} gives about {total:.3g} avalanches per frame, "
            f"{total * BYTES_PER_EVENT / 2**30:.3g} GiB to simulate (at most {MAX_EVENTS:,}): "
            "fewer pulses, a longer gm.dead_time_s, fewer pixels or a shorter "
            "timing.range_gate_m"
        )


def respond(scene: Scene, echo: EchoStage, background=None) -> GmResponse:
    """The frame: rates, photoelectrons and the avalanches of ``gm.pulses`` pulses."""
    gm = scene.gm
    energy_j = frame_pulse_energy_j(scene)
    hv_j = photon_energy_j(scene.laser.wavelength_m)
    weights = np.asarray(echo.weights)
    element_pe = gm.pde * energy_j * weights / hv_j
    signal_pe = element_pe.sum(axis=1)
    bg_w = background_power_w(scene, background).reshape(-1)
    rate_hz = gm.pde * bg_w / hv_j + gm.dark_count_rate_hz
    _check_load(scene, signal_pe, rate_hz, echo.pixel)
    t_lo, _ = _gate_s(scene)
    rates = ev.PixelRates(
        rate_hz=rate_hz,
        lit_pixel=np.asarray(echo.pixel),
        element_t_s=np.asarray(echo.arrivals_s) - t_lo,
        element_pe=element_pe,
        scale_s=echo.shape.tau_s / echo.shape.a,
    )
    det = _detector(scene)
    rng = np.random.default_rng([scene.seed, 1917])
    events = ev.simulate_frame(rng, rates, det, gm.pulses)
    hist = gh.histogram(events, det.n_bins, gm.pulses)
    s_counts, b_counts = _expected_window_counts(scene, echo, signal_pe, rate_hz[echo.pixel])
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(s_counts > 0, s_counts / np.sqrt(s_counts + b_counts), 0.0)
    return GmResponse(
        peak_power_w=echo.features.peak_w_per_j * energy_j,
        snr=snr,
        noise_figures={
            "photon_energy_j": hv_j,
            "rate_hz_median": float(np.median(rate_hz)),
            "signal_pe_median": float(np.median(signal_pe)) if len(signal_pe) else 0.0,
            "events": float(len(events)),
        },
        signal_pe=signal_pe,
        rate_hz=rate_hz,
        events=events,
        histogram=hist,
        gate_start_s=t_lo,
    )


def _response_reads(s: Scene) -> tuple:
    return (
        s.laser.pulse_energy_j,
        s.gm.attenuation_db,
        s.laser.wavelength_m,
        s.detector.pixels,
        s.timing.range_gate_m,
        s.gate_center_m,
        s.seed,
        s.gm.pde,
        s.gm.dark_count_rate_hz,
        s.gm.dead_time_s,
        s.gm.jitter_s,
        s.gm.bin_s,
        s.gm.pulses,
        s.gm.crosstalk,
        s.gm.afterpulsing,
    )


# ----------------------------------------------------------------------------------------------
# detection
# ----------------------------------------------------------------------------------------------
def window_bins(scene: Scene, echo: EchoStage) -> int:
    """The peak window: the pulse's FWHM (tau, Eq. 1) widened by the jitter's, in bins (>= 1)."""
    gm = scene.gm
    fwhm_s = np.hypot(echo.shape.tau_s * _fwhm_over_tau(echo), 2.3548 * gm.jitter_s)
    return int(max(1, round(fwhm_s / gm.bin_s)))


def _fwhm_over_tau(echo: EchoStage) -> float:
    """FWHM of Eq. 1's pulse over tau: 1 for a = 2.446 (ours), 0.699 for the paper's 3.5."""
    from ..pulse import A_FWHM  # noqa: PLC0415

    return A_FWHM / echo.shape.a


def window_fraction(scene: Scene, echo: EchoStage) -> float:
    """The largest share of a single surface's photoelectrons (Gamma(2, s), then jitter and
    bins) one peak window of :func:`window_bins` can hold [1]."""
    gm = scene.gm
    s = echo.shape.tau_s / echo.shape.a
    w_s = window_bins(scene, echo) * gm.bin_s
    reach_s = JITTER_REACH * gm.jitter_s
    t = np.linspace(-reach_s, ECHO_TAIL_SCALES * s + reach_s, 4001)
    dt = t[1] - t[0]
    cdf = ev.gamma2_cdf(t / s)  # exact on the grid; the jitter's pmf on the same step
    m = int(reach_s // dt)
    if m >= 1:
        kern = np.exp(-0.5 * (dt * np.arange(-m, m + 1) / gm.jitter_s) ** 2)
        cdf = np.convolve(np.pad(cdf, m, mode="edge"), kern / kern.sum(), mode="valid")
    return float(np.max(np.interp(t + w_s, t, cdf, right=cdf[-1]) - cdf))


def false_alarm_probability(tnr: float) -> float:
    """P_fa of a Gaussian threshold at ``tnr`` standard deviations, 0.5 erfc(TNR / sqrt 2)."""
    return float(0.5 * special.erfc(tnr / np.sqrt(2.0)))


def threshold_counts(mu_window, n_windows: float, p_fa: float) -> np.ndarray:
    """The least count k with n_windows P(Poisson(mu) >= k) <= p_fa, per pixel: over the
    gate's n_windows independent windows the background reaches k in a pixel with probability
    at most p_fa (the union bound). At least 1."""
    mu = np.asarray(mu_window, dtype=np.float64)
    uniq, inverse = np.unique(mu, return_inverse=True)
    q = p_fa / max(n_windows, 1.0)
    k = np.ones(len(uniq))
    pos = uniq > 0
    if pos.any():
        from scipy import stats  # noqa: PLC0415

        k[pos] = stats.poisson.isf(q, uniq[pos]) + 1.0
        lost = pos & ~np.isfinite(k)  # a q far below what the survival function resolves
        if lost.any():
            k[lost] = _tail_count(uniq[lost], q)
    return np.maximum(k, 1.0)[inverse].reshape(mu.shape)


def _tail_count(mu, q: float) -> np.ndarray:
    """(m,) the least k with P(Poisson(mu) >= k) <= q from the log of its first term, where
    ``stats.poisson.isf`` cannot resolve q (TNR 30: q ~ 1e-200): P(N >= k) <= P(N = k) / (1 -
    mu / (k + 1)) for k + 1 > mu, so the k found is the exact one or one above it."""
    log_q = np.log(max(q, np.finfo(float).tiny))
    mu = np.asarray(mu, dtype=np.float64)
    k = np.maximum(np.ceil(mu), 1.0)
    for _ in range(100_000):  # a few hundred steps even for q at the float's limit
        log_tail = k * np.log(mu) - mu - special.gammaln(k + 1.0) - np.log1p(-mu / (k + 1.0))
        high = log_tail > log_q
        if not high.any():
            break
        k = np.where(high, k + 1.0, k)
    return k


def _expected_window_counts(scene: Scene, echo: EchoStage, signal_pe, rate_lit_hz):
    """(n,) expected signal and background counts of the frame in each lit pixel's peak
    window: N a (1 - exp(-f N_s)) and N a r w, with a the pixel's chance to be armed when the
    echo comes (:func:`gm_limits.armed_probability`: the background's renewal process since
    the gate opened, e^{-r t} within the first dead time)."""
    gm = scene.gm
    armed = echo_armed_probability(scene, echo, rate_lit_hz)
    f = window_fraction(scene, echo)
    s_counts = gm.pulses * armed * -np.expm1(-f * signal_pe)
    b_counts = gm.pulses * armed * rate_lit_hz * window_bins(scene, echo) * gm.bin_s
    return s_counts, b_counts


def echo_armed_probability(scene: Scene, echo: EchoStage, rate_lit_hz) -> np.ndarray:
    """(n,) each lit pixel's chance to be armed when its echo's first element arrives."""
    t_echo = np.maximum(_echo_span_s(echo)[0] - _gate_s(scene)[0], 0.0)
    return armed_probability(rate_lit_hz, t_echo, scene.gm.dead_time_s)


def _echo_span_s(echo: EchoStage) -> tuple[np.ndarray, np.ndarray]:
    """(n,) first and last element arrival of each lit pixel since emission [s]."""
    w = np.asarray(echo.weights)
    a = np.asarray(echo.arrivals_s)
    has = w > 0
    first = np.where(has, a, np.inf).min(axis=1)
    last = np.where(has, a, -np.inf).max(axis=1)
    return first, last


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
    pre = int(np.ceil((s_scale + JITTER_REACH * gm.jitter_s) / gm.bin_s)) + 1
    length = pre + int(
        np.ceil((ECHO_TAIL_SCALES * s_scale + JITTER_REACH * gm.jitter_s) / gm.bin_s)
    )
    length = min(length, h.n_bins)
    dead_bins = int(round(gm.dead_time_s / gm.bin_s)) if gm.dead_time_s < 1.0 else h.n_bins
    est = gh.centroid_times(
        h, p_pix, p_start - pre, length, gm.bin_s, bg_per_bin[p_pix], dead_bins, gm.coates
    )
    t_mean_s = rx.gate_start_s + est.t_s
    # range: the centroid less the mean photon delay of Eq. 1's pulse, 2 s (Gamma(2, s))
    r_est_m = 0.5 * C * (t_mean_s - 2.0 * s_scale)
    if gm.pileup_correction == "fit":
        first, armed = gp.first_events_histogram(
            rx.events, p_pix, p_start - pre, length, gm.pulses, dead_bins
        )
        fit = gp.fit_first_photon(
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
    pred_m, sigma_m, skew = predicted_range_m(scene, echo, rx, pre, length, k_t[echo.pixel])
    # where the expected histogram holds no excess over the background (a pixel detected by
    # chance), the weak-signal sd stands
    sigma_m = np.where(np.isfinite(sigma_m), sigma_m, sigma_weak_m)
    figures = pileup_figures(scene, rx.signal_pe, pred_m - r_true_m, sigma_m, skew, detected)
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


FIRST_PHOTON_SEGMENTS = 32  # the first-photon gate's decaying background, in this many parts


def expected_false_points(scene: Scene, n_bins: int, width: int, rate_hz, k_t, lit_pixel, p_d):
    """Expected false points of the frame's cloud (docs/physics.md#false-points) [1].

    The peak search slides its window of W bins over each pixel's histogram; the background
    gives a false point where the densest window reaches k_T, with the probability that the
    scan statistic of a Poisson process (window mean mu, the gate T / (W b) windows long)
    reaches k_T (:func:`scan_probability`): about k_T times the threshold's union bound over
    disjoint windows when mu is small. The dead time d thins the background: mu = N r' W b at
    the non-paralysable rate r' = r / (1 + r d) (d < T); with d >= T (first photon) each pulse's
    one event comes at the density r e^(-rt), so the window mean decays over the gate and the
    scan's hazard is summed over FIRST_PHOTON_SEGMENTS parts of it. With d at least a window
    each pulse adds at most one count to a window, which scales the tail by N! / ((N - k)! N^k)
    (a binomial's tail against the Poisson's; 0 for k > N). A pixel gives at most one point,
    and a lit pixel a false one only when its echo is not detected (1 - P_d; an undefined P_d
    counts as missed, a bound).

    n_bins : the gate's bins; width : W [bins]; rate_hz : (pixels**2,) each pixel's constant
    primary rate r (background and dark) [1/s]; k_t : (pixels**2,) thresholds [counts];
    lit_pixel : (n,) flat index of the lit pixels; p_d : (n,) their predicted P_d [1]
    """
    gm = scene.gm
    r = np.asarray(rate_hz, dtype=np.float64)
    k = np.asarray(k_t, dtype=np.float64)
    window_s, gate_s = width * gm.bin_s, n_bins * gm.bin_s
    windows = max(n_bins / width, 2.0)
    if gm.dead_time_s < gate_s:
        p_false = scan_probability(
            gm.pulses * r / (1.0 + r * gm.dead_time_s) * window_s, k, windows
        )
    else:  # first photon: the window mean N r e^(-rt) W b at each part of the gate
        parts = np.linspace(2.0, windows, FIRST_PHOTON_SEGMENTS + 1)
        mid_s = 0.5 * (parts[1:] + parts[:-1]) * window_s
        mu = gm.pulses * window_s * r[:, None] * np.exp(-r[:, None] * mid_s[None, :])
        log_q2, log_step = _naus_logs(mu, np.broadcast_to(k[:, None], mu.shape))
        first, _ = _naus_logs(gm.pulses * r * window_s, k)
        p_false = -np.expm1(np.minimum(first + log_step @ np.diff(parts), 0.0))
    if gm.dead_time_s >= window_s:  # at most one count per pulse and window
        n = float(gm.pulses)
        kk = np.minimum(k, n)
        log_share = special.gammaln(n + 1.0) - special.gammaln(n - kk + 1.0) - kk * np.log(n)
        p_false = np.where(k <= n, p_false * np.exp(log_share), 0.0)
    p_echo = np.where(np.isfinite(p_d), p_d, 0.0)
    return float(p_false.sum() - np.sum(p_echo * p_false[np.asarray(lit_pixel)]))


def scan_probability(mu_window, k_t, n_windows: float) -> np.ndarray:
    """P(the count of a window of mean ``mu_window`` sliding over ``n_windows`` window lengths
    of a Poisson process reaches ``k_t``), per element [1].

    Naus's approximation, 1 - Q2 (Q3 / Q2)^(L/W - 2), with Q2 and Q3 the exact probabilities
    that the scan stays below k over 2 and 3 window lengths (J. I. Naus, "Approximations for
    distributions of scan statistics", J. Am. Stat. Assoc. 77, 177-183, 1982; the Poisson
    forms as given by S. E. Alm, 1983).
    """
    log_q2, log_step = _naus_logs(mu_window, k_t)
    return -np.expm1(np.minimum(log_q2 + (max(float(n_windows), 2.0) - 2.0) * log_step, 0.0))


def _naus_logs(mu_window, k_t) -> tuple[np.ndarray, np.ndarray]:
    """ln Q2 and ln(Q3 / Q2) of Naus's approximation, per element (each distinct (mu, k) pair
    evaluated once). The sums over r run over the terms within 14 sqrt(mu) + 30 of k (the rest
    are below 1e-40 of them)."""
    mu, k = np.broadcast_arrays(np.asarray(mu_window, np.float64), np.asarray(k_t, np.float64))
    pairs, inverse = np.unique(
        np.stack([mu.ravel(), np.maximum(k.ravel(), 1.0)]), axis=1, return_inverse=True
    )
    out = np.zeros((2, pairs.shape[1]))
    for sel in np.array_split(np.arange(pairs.shape[1]), max(1, pairs.shape[1] // 256)):
        out[:, sel] = _naus(pairs[0, sel], pairs[1, sel])
    inverse = np.ravel(inverse)
    return out[0, inverse].reshape(mu.shape), out[1, inverse].reshape(mu.shape)


def _naus(psi, k) -> np.ndarray:
    """(2, m): ln Q2 and ln(Q3 / Q2) for window means psi (m,) and thresholds k (m,) >= 1."""
    psi, kk = psi[:, None], k[:, None]

    def pmf(j):
        j = np.asarray(j, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.exp(j * np.log(psi) - psi - special.gammaln(j + 1.0))
        v = np.where(psi > 0, v, (j == 0).astype(np.float64))
        return np.where(j >= 0, v, 0.0)

    def cdf(j):
        j = np.asarray(j, dtype=np.float64)
        return np.where(j >= 0, special.pdtr(np.maximum(j, 0.0), psi), 0.0)

    q2 = cdf(kk - 1) ** 2 - (kk - 1) * pmf(kk) * pmf(kk - 2)
    q2 = q2 - (kk - 1 - psi) * pmf(kk) * cdf(kk - 3)
    a1 = 2 * pmf(kk) * cdf(kk - 1) * ((kk - 1) * cdf(kk - 2) - psi * cdf(kk - 3))
    a2 = (kk - 1) * (kk - 2) * cdf(kk - 3) - 2 * (kk - 2) * psi * cdf(kk - 4)
    a2 = 0.5 * pmf(kk) ** 2 * (a2 + psi**2 * cdf(kk - 5))
    reach = int(np.ceil(14.0 * np.sqrt(float(psi.max(initial=0.0))) + 30.0))
    r = kk - 1 - np.arange(reach)[None, :]  # r = k - 1, k - 2, ... (>= 1 for a3, >= 2 for a4)
    a3 = np.sum(np.where(r >= 1, pmf(2 * kk - r) * cdf(r - 1) ** 2, 0.0), axis=1, keepdims=True)
    a4 = pmf(2 * kk - r) * pmf(r) * ((r - 1) * cdf(r - 2) - psi * cdf(r - 3))
    a4 = np.sum(np.where(r >= 2, a4, 0.0), axis=1, keepdims=True)
    q3 = cdf(kk - 1) ** 3 - a1 + a2 + a3 - a4
    with np.errstate(divide="ignore", invalid="ignore"):
        log_q2 = np.where(q2 > 0, np.log(q2), -np.inf)
        log_step = np.where(q2 > 0, np.log1p(np.maximum((q3 - q2) / q2, -1.0)), -np.inf)
    return np.stack(
        [np.nan_to_num(log_q2[:, 0], nan=-np.inf), np.nan_to_num(log_step[:, 0], nan=-np.inf)]
    )


def _pileup_timing(scene: Scene, echo: EchoStage) -> gp.Timing:
    gm = scene.gm
    return gp.Timing(
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
    frame's finite pulses, jitter and bins included: :mod:`gm_pileup`), its sd [m] and its
    skewness [1], for the frame's estimator (the centroid, or the first-photon fit of
    ``gm.pileup_correction``); ``min_counts``: the lit pixels' thresholds in counts."""
    gm = scene.gm
    if len(echo.pixel) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    t_lo = rx.gate_start_s
    pe_per_weight = gm.pde * frame_pulse_energy_j(scene) / photon_energy_j(scene.laser.wavelength_m)
    element_pe = pe_per_weight * np.asarray(echo.weights)
    rate = rx.rate_hz[echo.pixel]
    pred = gp.predict_pixels(
        _pileup_timing(scene, echo),
        np.asarray(echo.arrivals_s) - t_lo,
        element_pe,
        rate,
        echo_armed_probability(scene, echo, rate),
        window_bins(scene, echo),
        pre,
        length,
        rx.histogram.n_bins,
        gm.coates,
        gm.pileup_correction,
        min_counts,
    )
    return 0.5 * C * (t_lo + pred.t_s), 0.5 * C * pred.sd_s, pred.skew


SATURATED_SHARE = 1.0 - np.exp(-1.0)  # a pixel is piled up when its echo fires it this often


def pileup_figures(scene: Scene, signal_pe, bias_m, sigma_m, skew, detected) -> dict:
    """The summary's Geiger-mode figures, predicted for the histogram's estimator [m]: the
    range bias, the median of the detected pixels' errors (of the mixture of their laws, each
    N(b_i - g_i sigma_i / 6, sigma_i^2): its median by the Cornish-Fisher term of its skewness
    g_i where it has under one photoelectron per pulse, and pixels of different flux have
    different biases), and the scatter, the
    sd of those errors about their mean, sqrt(mean sigma_i^2 + Var b_i); the share of lit pixels
    with over one photoelectron per pulse (their echo fires them in more than 1 - 1/e of the
    pulses: piled up), and a warning when most are."""
    sel = detected & np.isfinite(bias_m) & np.isfinite(sigma_m)
    sat = float(np.mean(signal_pe > 1.0)) if len(signal_pe) else 0.0
    # the skewness of a centroid of few counts (not of a piled-up estimate, whose law the
    # rare re-armed pulses shape)
    starved = np.asarray(signal_pe)[sel] <= 1.0
    median_i = bias_m[sel] - np.where(starved, skew[sel], 0.0) * sigma_m[sel] / 6.0
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


def _inside_gate(scene: Scene, range_m) -> np.ndarray:
    """Whether each range lies inside the range gate (a processor reports no range before the
    gate opens or after it closes: a centroid less the pulse's mean delay can fall there)."""
    t_lo, t_len = _gate_s(scene)
    return (range_m >= 0.5 * C * t_lo) & (range_m <= 0.5 * C * (t_lo + t_len))


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


def frame_detection_probability(scene: Scene, echo: EchoStage, rx: GmResponse) -> np.ndarray:
    """(n,) predicted P_d of each lit pixel for a frame of ``scene.gm.pulses`` pulses (its own
    threshold included): the pulses a given P_d needs, without simulating them."""
    gm = scene.gm
    width = window_bins(scene, echo)
    mu = gm.pulses * rx.rate_hz[echo.pixel] * gm.bin_s * width
    n_windows = rx.histogram.n_bins / width
    k_t = threshold_counts(mu, n_windows, false_alarm_probability(scene.timing.tnr))
    return _predicted(scene, echo, rx, k_t)[0]


def _predicted(scene: Scene, echo: EchoStage, rx: GmResponse, k_t):
    """(n,) detection probability and range sigma from the expected counts: the peak window's
    counts are Binomial(N, p) with p the per-pulse chance of an avalanche in it (signal or
    background), P_d = P(counts >= k_T); sigma: the centroid of S signal counts of a pulse of
    variance 2 s^2 (Gamma(2, s)) with jitter and bins, (c/2) sqrt(2 s^2 + sj^2 + b^2/12 / S)."""
    gm = scene.gm
    s_counts, b_counts = _expected_window_counts(scene, echo, rx.signal_pe, rx.rate_hz[echo.pixel])
    p = np.clip((s_counts + b_counts) / gm.pulses, 0.0, 1.0)
    p_d = special.bdtrc(k_t - 1.0, gm.pulses, p)
    # a window holds at most one avalanche a pulse: more counts than pulses are out of reach
    p_d = np.where(k_t <= 0, 1.0, np.where(k_t > gm.pulses, 0.0, p_d))
    s = echo.shape.tau_s / echo.shape.a
    single_s = np.sqrt(2.0 * s * s + gm.jitter_s**2 + gm.bin_s**2 / 12.0)
    with np.errstate(divide="ignore"):
        sigma_m = np.where(s_counts > 0, 0.5 * C * single_s / np.sqrt(s_counts), np.inf)
    return p_d, sigma_m


def _threshold_power_w(scene, echo, k_t: float, bg_per_bin, width: int) -> float:
    """The band-limited peak power of a single-surface echo whose expected peak-window counts
    over the frame reach ``k_t`` with the median background (inf if no echo can)."""
    gm = scene.gm
    need = (k_t - gm.pulses * float(np.median(bg_per_bin)) * width) / gm.pulses
    if need >= 1.0:
        return float("inf")
    if need <= 0:
        return 0.0
    f = window_fraction(scene, echo)
    signal_pe = -np.log1p(-need) / f
    energy_j = signal_pe * photon_energy_j(scene.laser.wavelength_m) / gm.pde
    return float(energy_j * echo.shape.peak_w_per_j)


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


def first_photon_cloud(result):
    """The single-pulse first-photon cloud of a ``gm_apd`` result: one point per pixel that
    fired in the frame's first pulse, at its first avalanche's range (``is_outlier`` where it
    was not the echo's), with the cloud's attributes and ground truth."""
    from ..pointcloud import assemble_cloud, ground_truth  # noqa: PLC0415  (upward: pointcloud)

    d, e, rx = result.detection, result.echo, result.receiver
    if not isinstance(d, GmDetection):
        raise ValueError("first_photon_cloud needs a result of receiver.kind = 'gm_apd'")
    n = result.pixels**2
    fired = np.flatnonzero(np.isfinite(d.first_photon_range_m))
    lit_of = np.full(n, -1, dtype=np.int64)
    lit_of[e.pixel] = np.arange(len(e.pixel))
    echo_pix = fired[d.first_photon_is_echo[fired]]
    noise_pix = fired[~d.first_photon_is_echo[fired]]
    li = lit_of[echo_pix]
    cloud = assemble_cloud(
        result.rays.pixel_directions,
        result.pixels,
        echo_pix,
        d.first_photon_range_m[echo_pix],
        rx.peak_power_w[li],
        rx.snr[li],
        e.material_id[li],
        e.facet_id[li],
        noise_pix,
        d.first_photon_range_m[noise_pix],
    )
    truth = ground_truth(
        e,
        result.hits,
        li,
        d.first_photon_range_m[echo_pix],
        len(noise_pix),
        tau_m=result.scene.quality.tau_m,
    )
    cloud.attributes.update(truth)
    return cloud


def _detection_reads(s: Scene) -> tuple:
    return (s.timing.tnr, s.gm.coates, s.gm.pileup_correction)


RECEIVER = register(
    Receiver(
        kind="gm_apd",
        doc="Geiger-mode single-photon APD array: photon-counting histograms of gm.pulses pulses",
        response_reads=_response_reads,
        respond=respond,
        detection_reads=_detection_reads,
        detect=_detect_with_warnings,
    )
)
