"""Compiled steps of the Geiger-mode prediction (numba, the echo kernel's conventions: cached on
disk, no GIL, parallel on the frame's threads): the moments of Coates' estimate of each bin summed
over its armed pulses' binomial law (:func:`simcore.receivers.gm_apd.coates.coates_bin_moments`,
the same sums term by term; only their order of addition differs from numpy's pairwise sums, a
few units in the last place of each moment)."""

from __future__ import annotations

import numpy as np
from numba import prange

from ...echo.kernel import jit, lock, set_threads

__all__ = ["summed_over_armed"]


@jit(parallel=True)
def _summed_over_armed(n_pulses, alpha, k_top, u_cell, u_weight, log_choose, table, out):
    for e in prange(len(alpha)):
        la = np.log(alpha[e])
        l1a = np.log1p(-alpha[e])
        i = u_cell[e]
        w = u_weight[e]
        s0 = s1 = s2 = s3 = 0.0
        # the moments at A = 0, then each next A: the table's rows, interpolated in u
        m0 = table[0, i, 0] + (table[0, i + 1, 0] - table[0, i, 0]) * w
        for k in range(k_top[e] + 1):
            logp = log_choose[k]
            if k > 0:
                logp += k * la
            if n_pulses - k > 0:
                logp += (n_pulses - k) * l1a
            p = np.exp(logp)
            m1 = table[k, i, 1] + (table[k, i + 1, 1] - table[k, i, 1]) * w
            m2 = table[k, i, 2] + (table[k, i + 1, 2] - table[k, i, 2]) * w
            nxt = table[k + 1, i, 0] + (table[k + 1, i + 1, 0] - table[k + 1, i, 0]) * w
            s0 += p * m0
            s1 += p * m1
            s2 += p * m2
            s3 += p * (nxt - m0)
            m0 = nxt
        out[0, e] = s0
        out[1, e] = s1
        out[2, e] = s2
        out[3, e] = s3


def summed_over_armed(
    n_pulses: int,
    alpha: np.ndarray,
    k_top: np.ndarray,
    u_cell: np.ndarray,
    u_weight: np.ndarray,
    log_choose: np.ndarray,
    table: np.ndarray,
    threads: int,
) -> np.ndarray:
    """(4, n) for bins whose armed pulses A ~ Binomial(n_pulses, alpha) are summed over
    A = 0 .. k_top: E[f], E[Var(f | A)], E[Cov(f, n | A)] and E[m(A + 1) - m(A)] from the
    Coates table ``table`` (A, U, 3) at each bin's u cell and weight; ``log_choose`` (K,) the
    log binomial coefficients of n_pulses over k = 0 .. max k_top."""
    out = np.zeros((4, len(alpha)))
    if len(alpha) == 0:
        return out
    set_threads(threads)
    with lock:
        _summed_over_armed(
            int(n_pulses),
            np.ascontiguousarray(alpha, dtype=np.float64),
            np.ascontiguousarray(k_top, dtype=np.int64),
            np.ascontiguousarray(u_cell, dtype=np.int64),
            np.ascontiguousarray(u_weight, dtype=np.float64),
            np.ascontiguousarray(log_choose, dtype=np.float64),
            table,
            out,
        )
    return out
