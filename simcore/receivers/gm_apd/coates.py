"""The moments of Coates' estimate of one bin of a Geiger-mode histogram at finite pulses, tabulated
(docs/physics.md#gm-pileup).

The Coates centroid at finite N. Coates' estimate of bin j is v_j = -ln(1 - n_j / A_j) less the
background's r b, with A_j ~ Binomial(N, alpha_j) pulses armed and n_j | A_j ~ Binomial(A_j, h_j),
h_j = q_j / alpha_j (exact for the first photon: the pulses are independent); the estimator
clips n_j = A_j to A_j - 1/2 and gives 0 where A_j = 0. Its mean and variance per bin are summed
exactly over n and A where A is small (a table over A <= A_TABLE and h), by the misses' Poisson
law or the delta method where A is large. The centroid's expectation is the ratio of the expected
sums, its variance the delta method's, sum_j ((t_j - t_c) / V)^2 Var v_j (the Coates increments
are uncorrelated, as the Nelson-Aalen estimator's are). With few pulses the late bins have no
armed pulse left and the centroid moves towards the echo's onset: the pile-up bias.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy import special

from ...cache import TableCache

A_TABLE = 128  # armed pulses up to which the Coates estimate's moments are tabulated exactly


U_MAX = 14.0  # the table's h runs to 1 - e^-14 (beyond: the same, every armed pulse fires)


U_STEP = 0.05


SMALL_MEAN_A = 30.0  # below this mean of A the moments are summed over A exactly


POISSON_MU_MAX = 60.0  # misses' Poisson table up to this mean (beyond: the delta method)


MOMENT_CHUNK = 1 << 14  # bins whose moments are summed over A at once


def _u_grid() -> np.ndarray:
    return np.arange(0.0, U_MAX + U_STEP / 2, U_STEP)


# the table depends on this module's constants only: computed once, kept on disk (simcore.cache)
TABLE = TableCache("gm_coates_moments", (Path(__file__).resolve(),), max_memory=1, max_entries=4)


@lru_cache(maxsize=1)
def _coates_table() -> np.ndarray:
    """(A_TABLE + 1, U, 3) mean, variance and covariance with n of f = -ln(1 - min(n, A - 1/2)
    / A), n ~ Binomial(A, h), h = 1 - e^-u on the u grid; A = 0 gives 0 (no armed pulse). The
    variance, not the second moment, is tabulated: every entry is then nearly linear in h where
    h is small, so the interpolation in u keeps it. Computed once (0.1-0.2 s) and cached on
    disk (:data:`TABLE`)."""
    return TABLE.get((A_TABLE, U_MAX, U_STEP), lambda: {"moments": _coates_table_computed()})[
        "moments"
    ]


def _coates_table_computed() -> np.ndarray:
    """:func:`_coates_table` computed."""
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
    if not _summed_compiled(n_pulses, alpha, h, mean_a, live, out):
        _summed_numpy(n_pulses, alpha, h, mean_a, live, out)
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


SUMMED_SERIAL_BELOW = 4096  # bins summed over A on one thread below this many


def _summed_compiled(n_pulses, alpha, h, mean_a, live, out) -> bool:
    """:func:`_summed_numpy` by the compiled kernel (:mod:`.kernel`, bin by bin on the frame's
    threads: no (bins, A, 3) gathers), where numba loads; False where it does not."""
    from ...echo.features import compiled_kernel  # noqa: PLC0415

    if compiled_kernel() is None:
        return False
    from ... import parallel  # noqa: PLC0415
    from . import kernel  # noqa: PLC0415  (numba: loaded with the echo kernel)

    sel = np.flatnonzero(live & (mean_a < SMALL_MEAN_A))
    bounds = np.array([b for b, _ in _A_SUM_CLASSES])
    k_max = np.array([k for _, k in _A_SUM_CLASSES])
    k_top = np.minimum(k_max[np.searchsorted(bounds, mean_a[sel], side="right")], n_pulses)
    k = np.arange(int(k_top.max(initial=0)) + 1)
    log_choose = (
        special.gammaln(n_pulses + 1) - special.gammaln(k + 1) - special.gammaln(n_pulses - k + 1)
    )
    i, wu = _u_index(h[sel])
    threads = parallel.threads_for(len(sel), SUMMED_SERIAL_BELOW)
    summed = kernel.summed_over_armed(
        n_pulses, alpha[sel], k_top, i, wu, log_choose, _coates_table(), threads
    )
    out[:, sel] = summed
    return True


def _summed_numpy(n_pulses, alpha, h, mean_a, live, out) -> None:
    """Where the armed pulses' mean is below SMALL_MEAN_A: the four moments summed over A
    exactly (A's binomial law to the class's largest A, its tail below 1e-7), into ``out``."""
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
