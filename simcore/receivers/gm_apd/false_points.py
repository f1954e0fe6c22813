"""The Geiger-mode frame's expected false points: the scan statistic of a Poisson process
(Naus's approximation) over each pixel's histogram, thinned by the dead time
(docs/physics.md#false-points).
"""

from __future__ import annotations

import numpy as np
from scipy import special

from ...scene import Scene

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
