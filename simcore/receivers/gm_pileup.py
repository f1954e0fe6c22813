"""Geiger-mode pile-up: what the histogram's range estimators give at any flux, and the
first-photon (pile-up) correction (docs/physics.md#gm-pileup).

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

The Coates centroid at finite N. Coates' estimate of bin j is v_j = -ln(1 - n_j / A_j) less the
background's r b, with A_j ~ Binomial(N, alpha_j) pulses armed and n_j | A_j ~ Binomial(A_j, h_j),
h_j = q_j / alpha_j (exact for the first photon: the pulses are independent); the estimator
clips n_j = A_j to A_j - 1/2 and gives 0 where A_j = 0. Its mean and variance per bin are summed
exactly over n and A where A is small (a table over A <= A_TABLE and h), by the misses' Poisson
law or the delta method where A is large. The centroid's expectation is the ratio of the expected
sums, its variance the delta method's, sum_j ((t_j - t_c) / V)^2 Var v_j (the Coates increments
are uncorrelated, as the Nelson-Aalen estimator's are). With few pulses the late bins have no
armed pulse left and the centroid moves towards the echo's onset: the pile-up bias.

The correction (``gm.pileup_correction = "fit"``): the maximum-likelihood fit of each detected
pixel's first avalanches after the window opens (at most one per pulse: the first-photon
histogram, which the pulse-tagged avalanches give for any dead time) by the single-surface
model, two parameters, the echo's start t0 and its photoelectrons per pulse N_s (the jitter
after the dead time's arbitration, the background from its known rate): dead-time aware by
construction, as photon-counting processors' first-photon corrections are.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special

A_TABLE = 128  # armed pulses up to which the Coates estimate's moments are tabulated exactly
U_MAX = 14.0  # the table's h runs to 1 - e^-14 (beyond: the same, every armed pulse fires)
U_STEP = 0.05
SMALL_MEAN_A = 30.0  # below this mean of A the moments are summed over A exactly
POISSON_MU_MAX = 60.0  # misses' Poisson table up to this mean (beyond: the delta method)
CELLS_PER_SIGMA = 2.0  # fine cells per jitter sd (and per bin at least 2, at most 16; 2 and 16
# give the same bias within 0.3 mm at 0.1-10^4 pe, 250 ps bins, 200 ps jitter)
MAX_BINS = 512  # bins of a modelled window at most (finer TDC bins are merged)
BLOCK_VALUES = 1 << 20  # fine cells (or bins) of a block of pixels at most (8 MB per array)
MOMENT_CHUNK = 1 << 14  # bins whose moments are summed over A at once


# ----------------------------------------------------------------------------------------------
# the moments of Coates' estimate of one bin
# ----------------------------------------------------------------------------------------------
def _u_grid() -> np.ndarray:
    return np.arange(0.0, U_MAX + U_STEP / 2, U_STEP)


@lru_cache(maxsize=1)
def _coates_table() -> np.ndarray:
    """(A_TABLE + 1, U, 3) mean, variance and covariance with n of f = -ln(1 - min(n, A - 1/2)
    / A), n ~ Binomial(A, h), h = 1 - e^-u on the u grid; A = 0 gives 0 (no armed pulse). The
    variance, not the second moment, is tabulated: every entry is then nearly linear in h where
    h is small, so the interpolation in u keeps it."""
    u = _u_grid()
    h = -np.expm1(-u)
    out = np.zeros((3, A_TABLE + 1, len(u)))
    for a in range(1, A_TABLE + 1):
        n = np.arange(a + 1)[:, None]
        f = -np.log1p(-np.minimum(n, a - 0.5) / a)
        with np.errstate(divide="ignore"):
            logp = (
                special.gammaln(a + 1)
                - special.gammaln(n + 1)
                - special.gammaln(a - n + 1)
                + special.xlogy(n, h[None, :])
                + special.xlog1py(a - n, -h[None, :])
            )
        p = np.exp(logp)
        m1 = (p * f).sum(axis=0)
        out[0, a] = m1
        out[1, a] = np.maximum((p * (f - m1[None, :]) ** 2).sum(axis=0), 0.0)
        out[2, a] = (p * (f - m1[None, :]) * n).sum(axis=0)
    out = np.ascontiguousarray(np.moveaxis(out, 0, -1))  # (A, U, 3): one gather per lookup
    out.setflags(write=False)
    return out


@lru_cache(maxsize=1)
def _poisson_log_table() -> tuple[np.ndarray, ...]:
    """On a mu grid: E[ln M'], Var ln M' and Cov(ln M', M) of M' = max(M, 1/2), M ~ Poisson(mu)."""
    mu = np.linspace(0.0, POISSON_MU_MAX, 1201)
    m = np.arange(0, int(POISSON_MU_MAX * 3) + 40)[:, None]
    lm = np.log(np.maximum(m, 0.5))
    p = np.exp(special.xlogy(m, mu[None, :]) - mu[None, :] - special.gammaln(m + 1))
    l1 = (p * lm).sum(axis=0)
    var = np.maximum((p * (lm - l1[None, :]) ** 2).sum(axis=0), 0.0)
    cov = (p * (lm - l1[None, :]) * m).sum(axis=0)
    return mu, l1, var, cov


def _u_index(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The u grid's cell of each h and the weight of its upper node."""
    u = np.minimum(-np.log1p(-np.clip(h, 0.0, 1.0 - 1e-16)), U_MAX) / U_STEP
    i = np.minimum(u.astype(np.intp), len(_u_grid()) - 2)
    return i, u - i


def _table_moments(a_int: np.ndarray, i: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(3, ...) the tabulated mean, variance and covariance with n at integer A <= A_TABLE,
    interpolated in u = -ln(1 - h) (cell i, weight w of :func:`_u_index`)."""
    tab = _coates_table()
    lo, hi = tab[a_int, i], tab[a_int, i + 1]
    return np.moveaxis(lo + (hi - lo) * w[..., None], -1, 0)


def _large_a_moments(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """(3, ...) the moments for large A: f = ln A - ln M', M = A - n ~ Binomial(A, 1 - h) the
    misses (Cov(f, n) = Cov(ln M', M)), by their Poisson law where few are expected, the delta
    method otherwise."""
    p = 1.0 - h
    mu = a * p
    mu_t, l1_t, var_t, cov_t = _poisson_log_table()
    out = np.empty((3, *mu.shape))
    few = mu < POISSON_MU_MAX
    out[0][few] = np.log(a[few]) - np.interp(mu[few], mu_t, l1_t)
    out[1][few] = np.interp(mu[few], mu_t, var_t)
    out[2][few] = np.interp(mu[few], mu_t, cov_t)
    many = ~few
    if many.any():
        m, v = mu[many], (a * p * h)[many]
        out[0][many] = np.log(a[many]) - np.log(m) + v / (2 * m * m)
        out[1][many] = v / (m * m)
        out[2][many] = v / m
    return out


def _moments_at(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """(3, ...) mean, variance and covariance with n of Coates' estimate at A armed pulses
    (real A >= 0: the table linear in A up to A_TABLE, the large-A law beyond)."""
    a = np.asarray(a, dtype=np.float64)
    h = np.broadcast_to(h, a.shape)
    out = np.zeros((3, *a.shape))
    small = a <= A_TABLE
    if small.any():
        lo = np.minimum(np.floor(a[small]).astype(np.intp), A_TABLE - 1)
        w = (a[small] - lo)[None]
        i, wu = _u_index(h[small])
        out[:, small] = _table_moments(lo, i, wu) * (1 - w) + _table_moments(lo + 1, i, wu) * w
    big = ~small
    if big.any():
        out[:, big] = _large_a_moments(a[big], h[big])
    return out


# mean of A below each bound -> the largest A summed (Poisson tails beyond it below 1e-7)
_A_SUM_CLASSES = ((0.05, 4), (1.0, 9), (4.0, 17), (10.0, 30), (SMALL_MEAN_A, 60))
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(7)
_GH_W = _GH_W / _GH_W.sum()


def coates_bin_moments(n_pulses: int, alpha: np.ndarray, h: np.ndarray) -> np.ndarray:
    """(4, ...) for Coates' estimate f of a bin with A ~ Binomial(n_pulses, alpha) armed pulses,
    each firing in it with probability h (elementwise): E[f], E[Var(f | A)], E[Cov(f, n | A)]
    and E[m(A + 1) - m(A)], m(A) = E[f | A] (how the estimate's mean moves with one more armed
    pulse)."""
    alpha = np.clip(np.asarray(alpha, dtype=np.float64), 0.0, 1.0)
    h = np.clip(np.asarray(h, dtype=np.float64), 0.0, 1.0)
    mean_a = n_pulses * alpha
    out = np.zeros((4, *mean_a.shape))
    live = (mean_a > 1e-12) & (h > 0)
    lo_mean = 0.0
    chunks = []
    for hi_mean, k_max in _A_SUM_CLASSES:
        sel = np.flatnonzero(live & (mean_a >= lo_mean) & (mean_a < hi_mean))
        lo_mean = hi_mean
        n_chunks = -(-len(sel) // MOMENT_CHUNK)
        chunks += [(c, k_max) for c in np.array_split(sel, n_chunks)] if n_chunks else []
    for sel, k_max in chunks:
        if not len(sel):
            continue
        k_top = min(k_max, n_pulses)
        k = np.arange(k_top + 1)
        log_choose = (
            special.gammaln(n_pulses + 1)
            - special.gammaln(k + 1)
            - special.gammaln(n_pulses - k + 1)
        )
        al = alpha[sel]
        with np.errstate(divide="ignore", invalid="ignore"):
            la, l1a = np.log(al)[:, None], np.log1p(-al)[:, None]
            hits = np.where(k > 0, k * la, 0.0)  # 0 log 0 = 0
            misses = np.where(n_pulses - k > 0, (n_pulses - k) * l1a, 0.0)
        logp = log_choose[None, :] + hits + misses
        p = np.exp(logp)
        # the moments at A = 0 .. k_top + 1 (integers: the table's own rows; A_TABLE >= 61)
        i, wu = _u_index(h[sel])
        a_all = np.arange(k_top + 2)
        m = _table_moments(
            a_all[None, :], i[:, None], np.broadcast_to(wu[:, None], (len(sel), k_top + 2))
        )
        out[:3, sel] = (p[None] * m[:, :, :-1]).sum(axis=2)
        out[3, sel] = (p * (m[0, :, 1:] - m[0, :, :-1])).sum(axis=1)
    # many armed pulses and a small hazard: the delta method (no clipping, A concentrated)
    plain = (mean_a >= SMALL_MEAN_A) & (h > 0) & (h < 0.2)
    if plain.any():
        mu, hp = mean_a[plain], h[plain]
        out[0, plain] = -np.log1p(-hp) + hp / (2.0 * mu * (1.0 - hp))
        out[1, plain] = hp / (mu * (1.0 - hp))
        out[2, plain] = hp
        out[3, plain] = -hp / (2.0 * mu * (mu + 1.0) * (1.0 - hp))
    large = (mean_a >= SMALL_MEAN_A) & (h >= 0.2)
    if large.any():
        mu = mean_a[large][:, None]
        sd = np.sqrt(mu * (1.0 - alpha[large][:, None]))
        a_nodes = np.clip(mu + sd * _GH_X[None, :], 1.0, n_pulses)
        hb = np.broadcast_to(h[large][:, None], a_nodes.shape)
        m = _moments_at(a_nodes, hb)
        out[:3, large] = m @ _GH_W
        out[3, large] = (_moments_at(a_nodes + 1.0, hb)[0] - m[0]) @ _GH_W
    return out


# ----------------------------------------------------------------------------------------------
# the expected histogram of a lit pixel
# ----------------------------------------------------------------------------------------------
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
            lam += np.where(on[:, None], ep[:, k, None] * -np.expm1(np.log1p(xk) - xk), 0.0)
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
            if rho.any():
                with np.errstate(divide="ignore"):
                    terms = np.log(rho) + rel[:, 1:]
                acc = np.logaddexp.accumulate(terms, axis=1)
                back = np.full_like(acc, -np.inf)
                back[:, 1:] = acc[:, :-1]  # re-arms before cell i
                armed = armed + np.exp(back - rel[:, :-1])
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
    (n,)): the counts a detected pixel has at least (its threshold)."""
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
    # the ratio's own spread with a Poisson number of counts, given the pixel was detected
    var_t = var_t * signal * inverse_count_mean(signal, min_counts)
    return Prediction(
        t_s=np.where(ok, t_c, np.nan),
        sd_s=np.where(ok, np.sqrt(var_t), np.nan),
        signal_counts=signal,
        skew=_skew(mean_v, c, signal),
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


def predict_pixels(
    t: Timing,
    element_t_s: np.ndarray,
    element_pe: np.ndarray,
    rate_hz: np.ndarray,
    armed_at_start: np.ndarray,
    width: int,
    pre: int,
    length: int,
    n_gate_bins: int,
    coates: bool = True,
    correction: str = "none",
    min_counts=1.0,
) -> Prediction:
    """The range estimate of each lit pixel as its histogram gives it, from the gate's opening
    [s]: the echo's start (the centroid less 2 s, Eq. 1's mean delay; or the first-photon
    fit's t0, ``correction = "fit"``), and its sd (module docstring; arguments as
    :func:`expected_windows`; ``min_counts``: each pixel's detection threshold in counts).
    In blocks of pixels of at most BLOCK_VALUES fine cells; a window of more than MAX_BINS bins
    (TDC bins far finer than the pulse and the jitter) is modelled on bins merged by g to at
    most MAX_BINS (each merged bin's hazard is then still small, so Coates' estimate of it is
    the sum of its parts')."""
    # a jitter far wider than the gate puts the estimator's window start far before the gate
    # and widens its peak window past it (bins there hold nothing): the model keeps both
    # within a window length
    pre, width = min(pre, length), min(width, length)
    if length > MAX_BINS:
        g = int(np.ceil(length / MAX_BINS))
        t = Timing(
            scale_s=t.scale_s,
            jitter_s=t.jitter_s,
            bin_s=t.bin_s * g,
            dead_time_s=t.dead_time_s,
            n_pulses=t.n_pulses,
        )
        width, pre = max(1, round(width / g)), int(np.ceil(pre / g))
        length, n_gate_bins = int(np.ceil(length / g)), int(np.ceil(n_gate_bins / g))
    n = len(rate_hz)
    min_counts = np.broadcast_to(np.asarray(min_counts, dtype=np.float64), (n,))
    span = 2 * (pre + width + length) + 16
    cells = (span + 8 * length) * fine_cells_per_bin(t) + 4096
    rows = max(1, int(BLOCK_VALUES // max(cells, 1.0)))
    parts = []
    for lo in range(0, n, rows):
        sl = slice(lo, lo + rows)
        parts.append(
            _predict_block(
                t,
                element_t_s[sl],
                element_pe[sl],
                rate_hz[sl],
                armed_at_start[sl],
                width,
                pre,
                length,
                n_gate_bins,
                coates,
                correction,
                min_counts[sl],
            )
        )
    if not parts:
        empty = np.zeros(0)
        return Prediction(t_s=empty, sd_s=empty, signal_counts=empty, skew=empty)
    return Prediction(
        **{
            f: np.concatenate([getattr(p, f) for p in parts])
            for f in ("t_s", "sd_s", "signal_counts", "skew")
        }
    )


def _predict_block(
    t,
    element_t_s,
    element_pe,
    rate_hz,
    armed_at_start,
    width,
    pre,
    length,
    n_gate_bins,
    coates,
    correction,
    min_counts,
) -> Prediction:
    """:func:`predict_pixels` for one block of pixels."""
    start_bin, q, alpha = expected_windows(
        t, element_t_s, element_pe, rate_hz, armed_at_start, width, pre, length, n_gate_bins
    )
    bg = rate_hz * t.bin_s
    centroid = coates_centroid(t, q, alpha, start_bin, bg, coates, min_counts)
    if correction != "fit":
        return Prediction(
            t_s=centroid.t_s - 2.0 * t.scale_s,
            sd_s=centroid.sd_s,
            signal_counts=centroid.signal_counts,
            skew=centroid.skew,
        )
    first = Timing(
        scale_s=t.scale_s,
        jitter_s=t.jitter_s,
        bin_s=t.bin_s,
        dead_time_s=np.inf,
        n_pulses=t.n_pulses,
    )
    a0 = alpha[:, 0]
    q1, _ = expected_histogram(
        first, element_t_s, element_pe, np.zeros_like(rate_hz), start_bin, length, a0
    )
    t0, sd, skew = predict_fit(
        first, q1 / np.maximum(a0, 1e-300)[:, None], a0, start_bin, min_counts
    )
    return Prediction(t_s=t0, sd_s=sd, signal_counts=centroid.signal_counts, skew=skew)


# ----------------------------------------------------------------------------------------------
# the first-photon correction
# ----------------------------------------------------------------------------------------------
@lru_cache(maxsize=1)
def first_photon_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ln N grid, and the mean and variance (in units of s) of the first primary event's delay
    after the echo's start for a single surface of N photoelectrons per pulse, given one in
    the pulse: density N x e^-x e^(-N G(x)) / (1 - e^-N), G(x) = 1 - (1 + x) e^-x."""
    log_n = np.linspace(np.log(1e-4), np.log(1e7), 442)
    x = np.concatenate([np.geomspace(1e-7, 1e-2, 800), np.linspace(1e-2, 40.0, 8000)[1:]])
    big_g = -np.expm1(np.log1p(x) - x)
    n = np.exp(log_n)[:, None]
    surv = np.exp(-n * big_g[None, :])
    cdf = (1.0 - surv) / -np.expm1(-n)
    # moments by parts from the CDF (trapezoid over the non-uniform grid)
    dx = np.diff(x)
    tail = 1.0 - cdf
    mid = 0.5 * (tail[:, 1:] + tail[:, :-1])
    mean = x[0] + (mid * dx).sum(axis=1)
    xm = 0.5 * (x[1:] + x[:-1])
    second = x[0] ** 2 + (2.0 * xm * mid * dx).sum(axis=1)
    return log_n, mean, np.maximum(second - mean * mean, 0.0)


def first_photon_delay(signal_pe) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the first photon's delay [units of s] for ``signal_pe``."""
    log_n, mean, var = first_photon_table()
    ln = np.log(np.clip(np.asarray(signal_pe, dtype=np.float64), 1e-4, 1e7))
    return np.interp(ln, log_n, mean), np.interp(ln, log_n, var)


def signal_from_spread(var_delay) -> np.ndarray:
    """The photoelectrons per pulse whose first-photon delay has variance ``var_delay`` [s^2
    units of s]: the table inverted (the variance falls with N)."""
    log_n, _, var = first_photon_table()
    v = np.asarray(var_delay, dtype=np.float64)
    return np.exp(np.interp(-v, -var, log_n))


@dataclass(frozen=True, kw_only=True)
class FirstPhotonFit:
    """The first-photon model fitted to each pixel's first avalanches of its armed pulses.

    t0_s : (q,) the echo's start from the gate's opening [s] (NaN where no signal)
    signal_pe : (q,) its photoelectrons per pulse [1]
    saturated : (q,) bool, (nearly) every armed pulse fired: N_s from the spread
    n_first : (q,) signal first avalanches (background subtracted) [1]
    """

    t0_s: np.ndarray
    signal_pe: np.ndarray
    saturated: np.ndarray
    n_first: np.ndarray


def first_events_histogram(events, pixel, start_bin, length, n_pulses, dead_bins):
    """(q, length) first avalanche of each pulse in each pixel's window [start, start + length)
    and (q,) the pulses armed when it opens (no avalanche within the dead time before it)."""
    q = len(pixel)
    if q == 0:
        return np.zeros((0, length)), np.zeros(0)
    n_all = int(max(int(events.pixel.max()) + 1 if len(events) else 0, int(pixel.max()) + 1))
    row_of = np.full(n_all, -1, dtype=np.int64)
    row_of[pixel] = np.arange(q)
    row = row_of[events.pixel]
    sel = row >= 0
    row, b, pulse = row[sel], events.bin[sel].astype(np.int64), events.pulse[sel].astype(np.int64)
    rel = b - start_bin[row]
    # pulses dead when the window opens
    dead = (rel < 0) & (rel >= -dead_bins)
    dead_key = np.unique(row[dead] * n_pulses + pulse[dead])
    armed = n_pulses - np.bincount(dead_key // n_pulses, minlength=q)
    inside = (rel >= 0) & (rel < length)
    key = row[inside] * n_pulses + pulse[inside]
    keep = ~np.isin(key, dead_key)
    key, rel_in = key[keep], rel[inside][keep]
    # events are sorted by pixel, then bin: a pulse's first occurrence is its earliest
    _, first = np.unique(key, return_index=True)
    hist = np.zeros((q, length))
    np.add.at(hist, (key[first] // n_pulses, rel_in[first]), 1.0)
    return hist, armed.astype(np.float64)


def fit_first_photon(
    t: Timing,
    hist: np.ndarray,
    armed: np.ndarray,
    start_bin: np.ndarray,
    background_per_bin: np.ndarray,
) -> FirstPhotonFit:
    """Fit each pixel's first-avalanche histogram (q, L) of ``armed`` pulses (module
    docstring; docs/physics.md#gm-pileup):

    - the background: a pulse still armed at bin j fires on it with r b, so the signal's first
      avalanches are n_j - A_j r b (A_j the armed pulses left);
    - N_s from the share of armed pulses that fired, f = S / A_0: N_s = -ln(1 - f); where
      nearly all fired (A_0 - S < 3, no information left in the share) from the spread of
      the first avalanches instead, Var t = s^2 Var x(N_s) + sigma_j^2 + b^2 / 12;
    - t0 from their mean, t0 = mean t - s E x(N_s): the first photon's mean delay of the
      model (jitter and the bin are centred).
    """
    n_b = hist.shape[1]
    t_bin = (start_bin[:, None] + np.arange(n_b)[None, :] + 0.5) * t.bin_s
    a0 = np.maximum(armed, 1.0)
    left = a0[:, None] - np.concatenate(
        [np.zeros((len(hist), 1)), np.cumsum(hist, axis=1)[:, :-1]], axis=1
    )
    sig = np.maximum(hist - np.maximum(left, 0.0) * background_per_bin[:, None], 0.0)
    n_sig = sig.sum(axis=1)
    ok = n_sig > 0
    safe = np.where(ok, n_sig, 1.0)
    mean_t = (sig * t_bin).sum(axis=1) / safe
    var_t = (sig * (t_bin - mean_t[:, None]) ** 2).sum(axis=1) / np.maximum(safe - 1.0, 1.0)
    frac = np.minimum(n_sig / a0, 1.0 - 0.5 / a0)
    n_share = -np.log1p(-frac)
    saturated = a0 - n_sig < 3.0
    s2 = t.scale_s**2
    var_x = (var_t - t.jitter_s**2 - t.bin_s**2 / 12.0) / s2
    n_spread = signal_from_spread(np.maximum(var_x, 0.0))
    n_s = np.where(saturated, np.maximum(n_spread, n_share), n_share)
    mean_x, _ = first_photon_delay(n_s)
    t0 = mean_t - t.scale_s * mean_x
    return FirstPhotonFit(
        t0_s=np.where(ok, t0, np.nan),
        signal_pe=np.where(ok, n_s, np.nan),
        saturated=saturated & ok,
        n_first=n_sig,
    )


_Z_NODES_FIT = special.ndtri((np.arange(32) + 0.5) / 32)  # equal-probability normal nodes


def predict_fit(
    t: Timing, q: np.ndarray, alpha0: np.ndarray, start_bin: np.ndarray, min_counts=1.0
):
    """Expected t0, its sd and skewness of :func:`fit_first_photon` from the expected
    first-avalanche histogram (q : (n, L) per armed pulse, the first photon of each; alpha0 :
    (n,) the pulses armed when the window opens). t0 = mean t - s E x(N_s): the mean of
    S = N a0 sum q first avalanches spreads by Var t E[1/S | S >= k] (k: ``min_counts``), and
    the fitted N_s by its own law, carried through E x at
    32 equal-probability normal nodes (E x is bounded and bends where N_s is large, so not by
    its slope): ln N_s from the share with Var N_s = (e^N_s - 1) / A_0; where saturated, Var x
    from the spread with Var(Var t) = 2 (Var t)^2 / S (nearly Gaussian: the jitter), clipped
    at 0 (no limit on N_s) and at the share's N_s."""
    armed = t.n_pulses * alpha0
    hist = armed[:, None] * q
    fit = fit_first_photon(t, hist, armed, start_bin, np.zeros(len(q)))
    n_b = q.shape[1]
    t_bin = (start_bin[:, None] + np.arange(n_b)[None, :] + 0.5) * t.bin_s
    total = np.maximum(hist.sum(axis=1), 1e-300)
    mean_t = (hist * t_bin).sum(axis=1) / total
    var_t = (hist * (t_bin - mean_t[:, None]) ** 2).sum(axis=1) / total
    counts = np.maximum(total, 1.0)
    var_mean = var_t * inverse_count_mean(total, min_counts)
    a0 = np.maximum(armed, 1.0)
    n_s = np.clip(np.nan_to_num(fit.signal_pe, nan=1e-4), 1e-4, 1e7)
    z = _Z_NODES_FIT[None, :]
    # from the share
    sd_ln = np.sqrt(np.expm1(np.minimum(n_s, 50.0)) / (a0 * n_s * n_s))[:, None]
    n_share = np.exp(np.clip(np.log(n_s)[:, None] + z * sd_ln, np.log(1e-4), np.log(1e7)))
    # from the spread
    share_frac = np.minimum(total / a0, 1.0 - 0.5 / a0)
    n_floor = -np.log1p(-share_frac)[:, None]
    s2 = t.scale_s**2
    var_x = ((var_t - t.jitter_s**2 - t.bin_s**2 / 12.0) / s2)[:, None]
    sd_v = (np.sqrt(2.0 / counts) * var_t / s2)[:, None]
    n_spread = np.maximum(signal_from_spread(np.maximum(var_x + z * sd_v, 0.0)), n_floor)
    nodes = np.where(fit.saturated[:, None], n_spread, n_share)
    ex = first_photon_delay(nodes)[0]
    ex_fit = first_photon_delay(n_s)[0]
    t0 = fit.t0_s - t.scale_s * (ex.mean(axis=1) - ex_fit)
    sd = np.sqrt(var_mean + (t.scale_s * ex.std(axis=1)) ** 2)
    skew = _skew(hist, t_bin - mean_t[:, None], total) * np.sqrt(var_mean) / np.maximum(sd, 1e-300)
    return t0, sd, skew
