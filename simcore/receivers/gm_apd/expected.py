"""The expected Geiger-mode histogram of a lit pixel and the Coates centroid it gives on average
(docs/physics.md#gm-pileup).

The expected histogram. Each lit pixel's echo elements (Eqs. 1, 29, 30) and constant rate give
its cumulative primary intensity Lambda(t) = sum_k N_k G((t - t_k) / s) + r t exactly
(G(x) = 1 - (1 + x) e^-x); the pixel fires in a fine cell of time (half the jitter or the
bin at most) with probability armed x (1 - e^-dLambda), armed = the share of pulses not within
the dead time of an earlier avalanche: those armed when the window opens (a0), less those that
fired within the dead time before, plus those that re-arm (a background avalanche d earlier,
before the window: r a0 per unit time; with few pulses left armed after a bright echo's onset
these few re-armed pulses carry Coates' largest estimates). Jitter then moves each avalanche (a
convolution of the fine cells with the Gaussian), and the TDC sums the cells into bins: q_j, the
expected avalanches per pulse in bin j, and alpha_j = 1 - (expected avalanches within the dead
time before bin j), the share of pulses armed at bin j (the expectation of Coates' A_j / N).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .coates import coates_bin_moments

CELLS_PER_SIGMA = 2.0  # fine cells per jitter sd (and per bin at least 2, at most 16; 2 and 16
# give the same bias within 0.3 mm at 0.1-10^4 pe, 250 ps bins, 200 ps jitter)


BLOCK_VALUES = 1 << 20  # fine cells (or bins) of a block of pixels at most (8 MB per array)


@dataclass(frozen=True, kw_only=True)
class Timing:
    """What shapes a pixel's histogram: Eq. 1's Gamma(2, s) scale, jitter sd, TDC bin, dead
    time, the pulses of a frame [s, s, s, s, 1]."""

    scale_s: float
    jitter_s: float
    bin_s: float
    dead_time_s: float
    n_pulses: int


def fine_cells_per_bin(t: Timing) -> int:
    """Fine cells per TDC bin: CELLS_PER_SIGMA per jitter sd and 8 per s, 2 to 16."""
    finest = min(t.jitter_s / CELLS_PER_SIGMA, t.scale_s / 8.0)
    return int(np.clip(np.ceil(t.bin_s / max(finest, 1e-300)), 2, 16))


def expected_histogram(
    t: Timing,
    element_t_s: np.ndarray,
    element_pe: np.ndarray,
    rate_hz: np.ndarray,
    start_bin: np.ndarray,
    n_bins: int,
    armed_at_start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(n, n_bins) expected avalanches per pulse in each bin q_j and the expected share of
    pulses armed at each bin alpha_j, over bins start_bin .. start_bin + n_bins - 1.

    element_t_s : (n, K) start of each echo element's pulse from the gate's opening [s]
    element_pe : (n, K) its mean photoelectrons per pulse [1] (0 = none)
    rate_hz : (n,) constant primary rate (background, dark) [1/s]
    start_bin : (n,) int, first bin of each pixel's window (from the gate's opening)
    armed_at_start : (n,) share of pulses armed when the window opens [1]
    """
    n = len(start_bin)
    k_fine = fine_cells_per_bin(t)
    dt = t.bin_s / k_fine
    # the fine cells run `reach` before the window to `reach` after it (jitter moves them in);
    # a jitter much wider than the window is cut at twice the window (or 2048 cells) either
    # side: what it would carry further is lost from the window anyway (the background it
    # would bring in from beyond is left out)
    reach = int(min(np.ceil(4.0 * t.jitter_s / dt), max(2 * n_bins * k_fine, 2048)))
    n_cells = n_bins * k_fine + 2 * reach
    q = np.zeros((n, n_bins))
    alpha = np.zeros((n, n_bins))
    x = (np.arange(-reach, n_bins * k_fine + reach + 1) * dt)[None, :]  # cell edges
    kern_x = np.arange(-reach, reach + 1) * dt
    if t.jitter_s > 0:
        edges = np.r_[kern_x - dt / 2, kern_x[-1] + dt / 2] / t.jitter_s
        kern = np.diff(special.ndtr(edges))
    else:
        kern = (kern_x == 0).astype(float)
    dead_cells = t.dead_time_s / dt
    element_t_s, element_pe, order = _collapse_narrow(element_t_s, element_pe, dt / 16.0)
    rate_hz, start_bin = rate_hz[order], start_bin[order]
    armed_at_start = armed_at_start[order]
    dead_bins = int(round(t.dead_time_s / t.bin_s)) if dead_cells < n_cells else n_bins
    row_block = max(1, BLOCK_VALUES // (n_cells + 1))
    for lo in range(0, n, row_block):
        sl = slice(lo, lo + row_block)
        t0 = start_bin[sl, None] * t.bin_s  # window start, from the gate's opening
        te = t0 + x  # (m, n_cells + 1)
        lam = rate_hz[sl, None] * (te - te[:, :1])
        et, ep = element_t_s[sl], element_pe[sl]
        for k in range(et.shape[1]):
            on = ep[:, k] > 0
            if not on.any():
                continue
            if not on.all():  # only the rows that have this element
                rows = np.flatnonzero(on)
                xk = np.maximum((te[rows] - et[rows, k, None]) / t.scale_s, 0.0)
                lam[rows] += ep[rows, k, None] * -np.expm1(np.log1p(xk) - xk)
                continue
            xk = np.maximum((te - et[:, k, None]) / t.scale_s, 0.0)
            lam += ep[:, k, None] * -np.expm1(np.log1p(xk) - xk)  # every row has it
        a0 = armed_at_start[sl]
        p = -np.expm1(-np.diff(lam, axis=1))
        # pulses dead when the grid opens, from an avalanche less than d before it (the
        # background's, at r a0 per unit time since the gate opened), re-arm inside it
        origin = te[:, :-1] - t.dead_time_s
        rho = np.where(
            (origin >= 0.0) & (origin < te[:, :1]), (rate_hz[sl] * a0)[:, None] * dt, 0.0
        )
        rearmed = np.cumsum(rho, axis=1)
        m = int(round(min(dead_cells, n_cells + 1.0)))
        if m > n_cells:  # no re-arming after an avalanche of the grid: in closed form
            # armed_i = a0 e^-(L_i - L_0) + sum_{c < i} rho_c e^-(L_i - L_{c+1}), the sum
            # as a running log-sum-exp (L reaches 10^4 in a bright echo)
            rel = lam - lam[:, :1]
            armed = a0[:, None] * np.exp(-rel[:, :-1])
            live = np.flatnonzero(rho.any(axis=1))  # the rows with re-armed pulses (the
            if len(live):  # others would add exp(-inf) = 0 to every cell)
                with np.errstate(divide="ignore"):
                    terms = np.log(rho[live]) + rel[live, 1:]
                acc = np.logaddexp.accumulate(terms, axis=1)
                back = np.full_like(acc, -np.inf)
                back[:, 1:] = acc[:, :-1]  # re-arms before cell i
                armed[live] = armed[live] + np.exp(back - rel[live, :-1])
            e = np.minimum(armed, 1.0) * p
        else:  # cell by cell, the cells' rows contiguous
            p_t = np.ascontiguousarray(p.T)
            base_t = np.ascontiguousarray((a0[:, None] + rearmed).T)
            e_t = np.zeros_like(p_t)
            recent = np.zeros(len(p))  # avalanches of the grid within the dead time
            for i in range(n_cells):
                e_t[i] = np.clip(base_t[i] - recent, 0.0, 1.0) * p_t[i]
                recent += e_t[i]
                if m == 0:
                    recent -= e_t[i]
                elif i - m + 1 >= 0:
                    recent -= e_t[i - m + 1]
            e = e_t.T
        # jitter: convolve the cells with the Gaussian, keep the window's cells, sum into bins
        if len(kern) <= 129:
            from scipy.ndimage import convolve1d  # noqa: PLC0415

            ej = convolve1d(e, kern, axis=1, mode="constant")
        else:  # a jitter of many cells: by FFT ("same": centred on the cells)
            size = e.shape[1] + len(kern) - 1
            n_fft = 1 << int(np.ceil(np.log2(size)))
            full = np.fft.irfft(
                np.fft.rfft(e, n_fft, axis=1) * np.fft.rfft(kern, n_fft)[None, :], n_fft, axis=1
            )
            off = (len(kern) - 1) // 2
            ej = np.maximum(full[:, off : off + e.shape[1]], 0.0)
        qb = ej[:, reach : reach + n_bins * k_fine].reshape(len(e), n_bins, k_fine).sum(axis=2)
        q[sl] = qb
        # armed share at bin j: a0 and the re-armed, less the avalanches within the dead time
        # before j (what Coates' A_j counts)
        cq = np.concatenate([np.zeros((len(qb), 1)), np.cumsum(qb, axis=1)], axis=1)
        j = np.arange(n_bins)
        lo_j = np.maximum(j - dead_bins, 0) if dead_bins < n_bins else np.zeros_like(j)
        back_in = rearmed[:, reach + j * k_fine]
        alpha[sl] = a0[:, None] + back_in - (cq[:, j] - cq[:, lo_j])
    back = np.empty_like(order)
    back[order] = np.arange(n)
    return q[back], np.clip(alpha, 0.0, 1.0)[back]


def _collapse_narrow(element_t_s, element_pe, within_s: float):
    """The elements of pixels whose echo spans less than ``within_s`` merged into one at their
    weighted time (the cumulative intensity moves by O(span^2 / s^2)), and an order that puts
    those pixels first (their blocks then evaluate one element): (t, pe, order)."""
    pe = np.asarray(element_pe, dtype=np.float64)
    et = np.asarray(element_t_s, dtype=np.float64)
    has = pe > 0
    first = np.where(has, et, np.inf).min(axis=1)
    last = np.where(has, et, -np.inf).max(axis=1)
    narrow = ~(last - first >= within_s)  # no element or one place
    total = pe.sum(axis=1)
    mean_t = (pe * np.where(has, et, 0.0)).sum(axis=1) / np.where(total > 0, total, 1.0)
    et = et.copy()
    pe = pe.copy()
    et[narrow, 0] = mean_t[narrow]
    pe[narrow, 0] = total[narrow]
    pe[narrow, 1:] = 0.0
    order = np.argsort(~narrow, kind="stable")
    return et[order], pe[order], order


@dataclass(frozen=True, kw_only=True)
class Prediction:
    """The Coates centroid of each lit pixel as its histogram gives it.

    t_s : (n,) expected centroid from the gate's opening [s] (NaN where no signal)
    sd_s : (n,) its standard deviation [s]
    signal_counts : (n,) expected signal avalanches of the frame in the window [1]
    skew : (n,) its skewness [1]: the window's third cumulant over its variance^1.5, over the
        square root of the counts (a mean of S events); few counts of Eq. 1's skewed pulse
        put the median below the mean by about skew x sd / 6
    """

    t_s: np.ndarray
    sd_s: np.ndarray
    signal_counts: np.ndarray
    skew: np.ndarray


def coates_centroid(
    t: Timing,
    q: np.ndarray,
    alpha: np.ndarray,
    start_bin: np.ndarray,
    background_per_bin: np.ndarray,
    coates: bool = True,
    min_counts=1.0,
) -> Prediction:
    """Expected centroid and its sd of Coates' estimates (``coates``) or of the raw counts
    less the background over each pixel's window (module docstring); ``min_counts`` (scalar or
    (n,)): the counts a detected pixel has at least (its threshold; None: ``sd_s`` holds the
    variance before the count's factor, :func:`with_threshold` applies it)."""
    n_b = q.shape[1]
    bg = background_per_bin[:, None]
    t_bin = (start_bin[:, None] + np.arange(n_b)[None, :] + 0.5) * t.bin_s
    if coates:
        h = np.where(alpha > 0, q / np.maximum(alpha, 1e-300), 0.0)
        e1, ev, ec, ed = coates_bin_moments(t.n_pulses, alpha.ravel(), h.ravel()).reshape(
            4, *q.shape
        )
        mean_v = e1 - bg
    else:
        mean_v = q - bg
    total = mean_v.sum(axis=1)
    ok = total > 0
    safe = np.where(ok, total, 1.0)
    t_c = (mean_v * t_bin).sum(axis=1) / safe
    c = t_bin - t_c[:, None]  # Z = sum_j c_j v_j has the centroid's spread times V
    if coates:
        # the Doob decomposition of Z over the bins: bin j's own spread, and its counts
        # moving the armed pulses of every later bin: R'_k, how the later bins' expected sum
        # moves with one more armed pulse at k, R'_k = c_k E[m(A_k + 1) - m(A_k)] +
        # (1 - h_k) R'_{k+1} (an armed pulse stays armed past bin k with 1 - h_k)
        r_next = np.zeros_like(q)
        for j in range(n_b - 2, -1, -1):
            r_next[:, j] = c[:, j + 1] * ed[:, j + 1] + (1.0 - h[:, j + 1]) * r_next[:, j + 1]
        var_n = t.n_pulses * alpha * h * (1.0 - h)
        var_z = (c * c * ev - 2.0 * c * r_next * ec + r_next * r_next * var_n).sum(axis=1)
    else:  # multinomial counts over the frame, per pulse
        cq = (c * q).sum(axis=1)
        var_z = ((c * c * q).sum(axis=1) - cq * cq) / t.n_pulses
    var_t = np.maximum(var_z, 0.0) / (safe * safe)
    signal = t.n_pulses * np.maximum(q - bg, 0.0).sum(axis=1)
    raw = Prediction(
        t_s=np.where(ok, t_c, np.nan),
        sd_s=np.where(ok, var_t, np.nan),
        signal_counts=signal,
        skew=_skew(mean_v, c, signal),
    )
    return raw if min_counts is None else with_threshold(raw, min_counts)


def with_threshold(raw: Prediction, min_counts=1.0) -> Prediction:
    """``raw`` (:func:`coates_centroid` without a threshold: ``sd_s`` its variance per count
    [s^2]) given its detected pixels' thresholds ``min_counts`` (scalar or (n,)): the ratio's
    own spread with a Poisson number of counts, given the pixel was detected."""
    var_t = raw.sd_s * raw.signal_counts * inverse_count_mean(raw.signal_counts, min_counts)
    return Prediction(
        t_s=raw.t_s, sd_s=np.sqrt(var_t), signal_counts=raw.signal_counts, skew=raw.skew
    )


def inverse_count_mean(mean_counts, min_counts=1.0) -> np.ndarray:
    """E[1 / S | S >= k] of S ~ Poisson(mu), elementwise [1]: a centroid of S events spreads by
    Var / S, and a detected pixel has at least its threshold k (>= 1) of them. Summed exactly
    below mu = 50, (1 + 1/mu) / mu above (the next terms are O(mu^-3))."""
    mu = np.asarray(mean_counts, dtype=np.float64)
    k = np.broadcast_to(np.maximum(np.asarray(min_counts, dtype=np.float64), 1.0), mu.shape)
    m = np.maximum(mu, 1e-12)
    out = (1.0 + 1.0 / m) / m
    small = mu < 50.0
    if small.any():
        s = np.arange(1, 141)[None, :]
        ms, ks = m[small][:, None], k[small][:, None]
        p = np.exp(special.xlogy(s, ms) - ms - special.gammaln(s + 1.0)) * (s >= ks)
        total = p.sum(axis=1)
        est = (p / s).sum(axis=1) / np.maximum(total, 1e-300)
        # beyond reach (k far above mu): the pixel holds about k counts
        out[small] = np.where(total > 1e-250, est, 1.0 / ks[:, 0])
    return out


def _skew(weights, c, counts) -> np.ndarray:
    """(n,) skewness of a mean of ``counts`` events distributed as ``weights`` over offsets
    ``c`` from their mean (per row): k3 / k2^1.5 / sqrt(counts)."""
    w = np.maximum(weights, 0.0)
    total = np.maximum(w.sum(axis=1), 1e-300)
    k2 = (w * c * c).sum(axis=1) / total
    k3 = (w * c * c * c).sum(axis=1) / total
    with np.errstate(divide="ignore", invalid="ignore"):
        g = k3 / k2**1.5 / np.sqrt(np.maximum(counts, 1.0))
    return np.where(np.isfinite(g), g, 0.0)


def expected_windows(
    t: Timing,
    element_t_s: np.ndarray,
    element_pe: np.ndarray,
    rate_hz: np.ndarray,
    armed_at_start: np.ndarray,
    width: int,
    pre: int,
    length: int,
    n_gate_bins: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each lit pixel's analysis window as its detection forms it from the expected histogram
    (its densest window of ``width`` bins, from ``pre`` bins before it, ``length`` long:
    gm_apd.detect's): (n,) its first bin, (n, length) q_j and alpha_j over it (bins outside
    the gate hold nothing).

    element_t_s, element_pe : (n, K) the echo elements from the gate's opening [s], [1]
    rate_hz : (n,) constant rate [1/s]; armed_at_start : (n,) pulses armed before the echo [1]
    """
    n = len(rate_hz)
    width = max(int(width), 1)  # a gate shorter than one bin (1e-30 m) gives detect 0 bins
    has = element_pe > 0
    first_s = np.where(has, element_t_s, np.inf).min(axis=1)
    last_s = np.where(has, element_t_s, -np.inf).max(axis=1)
    first_s = np.where(np.isfinite(first_s), first_s, 0.0)
    last_s = np.where(np.isfinite(last_s), last_s, first_s)
    reach = int(min(np.ceil(4.0 * t.jitter_s / t.bin_s), 2 * length)) + 1
    margin = pre + width + reach + 2
    span_start = np.floor(first_s / t.bin_s).astype(np.int64) - margin
    echo_bins = int(np.ceil(float(np.max(last_s - first_s, initial=0.0)) / t.bin_s))
    span = echo_bins + margin + length + 4
    q, alpha = expected_histogram(
        t, element_t_s, element_pe, rate_hz, span_start, span, armed_at_start
    )
    cum = np.concatenate([np.zeros((n, 1)), np.cumsum(q, axis=1)], axis=1)
    moving = cum[:, width:] - cum[:, :-width]
    peak = np.argmax(moving, axis=1)
    ws = np.clip(peak - pre, 0, span - length)
    rows = np.arange(n)[:, None]
    cols = ws[:, None] + np.arange(length)[None, :]
    start_bin = span_start + ws
    absolute = start_bin[:, None] + np.arange(length)[None, :]
    inside = (absolute >= 0) & (absolute < n_gate_bins)
    return start_bin, np.where(inside, q[rows, cols], 0.0), alpha[rows, cols]
