"""The Geiger-mode peak window and its expected counts: the window's width and the share of an
echo it holds, each lit pixel's chance to be armed when its echo comes, the thresholds in counts
for the false-alarm probability of ``timing.tnr``, and the detection probability and range sd
those counts predict.

The model: docs/physics.md#geiger-mode.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from ...constants import C
from ...echo import EchoStage
from ...scene import Scene, with_overrides
from . import events as ev
from .frame import ECHO_TAIL_SCALES, JITTER_REACH, _gate_s, photon_energy_j
from .limits import armed_probability
from .records import GmResponse


def window_bins(scene: Scene, echo: EchoStage) -> int:
    """The peak window: the pulse's FWHM (tau, Eq. 1) widened by the jitter's, in bins (>= 1)."""
    gm = scene.gm
    fwhm_s = np.hypot(echo.shape.tau_s * _fwhm_over_tau(echo), 2.3548 * gm.jitter_s)
    return int(max(1, round(fwhm_s / gm.bin_s)))


def _fwhm_over_tau(echo: EchoStage) -> float:
    """FWHM of Eq. 1's pulse over tau: 1 for a = 2.446 (ours), 0.699 for the paper's 3.5."""
    from ...pulse import A_FWHM  # noqa: PLC0415

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
        k[pos] = poisson_isf(q, uniq[pos]) + 1.0
        lost = pos & ~np.isfinite(k)  # a q far below what the survival function resolves
        if lost.any():
            k[lost] = _tail_count(uniq[lost], q)
    return np.maximum(k, 1.0)[inverse].reshape(mu.shape)


def poisson_isf(q: float, mu: np.ndarray) -> np.ndarray:
    """The least k with P(Poisson(mu) > k) <= q, elementwise, 0 < q < 1 (inf for q <= 0):
    ``scipy.stats.poisson.isf``'s own steps (its quantile at 1 - q from ``special.pdtrik``,
    one step down where the CDF allows), without importing scipy.stats (half a second of a
    cold run)."""
    mu = np.asarray(mu, dtype=np.float64)
    if q <= 0.0:
        return np.full(mu.shape, np.inf)
    p = 1.0 - q
    vals = np.ceil(special.pdtrik(p, mu))
    below = np.maximum(vals - 1, 0)
    return np.where(special.pdtr(below, mu) >= p, below, vals)


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
    echo comes (:func:`.limits.armed_probability`: the background's renewal process since
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


def _inside_gate(scene: Scene, range_m) -> np.ndarray:
    """Whether each range lies inside the range gate (a processor reports no range before the
    gate opens or after it closes: a centroid less the pulse's mean delay can fall there)."""
    t_lo, t_len = _gate_s(scene)
    return (range_m >= 0.5 * C * t_lo) & (range_m <= 0.5 * C * (t_lo + t_len))


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


def pulses_needed(scene: Scene, result, p_target: float, max_pulses: int) -> float:
    """The least frame length N (``gm.pulses``) whose predicted P_d (counts of N pulses against
    their threshold, :func:`frame_detection_probability`) reaches ``p_target`` in the median lit
    pixel, searched over 60 lengths from 1 to ``max_pulses``; inf if none."""
    for n in np.unique(np.geomspace(1, max_pulses, 60).astype(int)):
        s = with_overrides(scene, {"gm.pulses": int(n)})
        p_d = frame_detection_probability(s, result.echo, result.receiver)
        if float(np.median(p_d)) >= p_target:
            return float(n)
    return math.inf
