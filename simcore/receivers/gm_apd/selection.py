"""What detection's threshold does to the Geiger-mode centroid at a few counts per frame
(docs/physics.md#gm-selection).

A pixel gives a point only when its densest window of W bins holds its threshold k_T of counts.
With a few counts per frame that keeps the realisations whose counts bunch and drops those whose
counts spread out, and a spread-out realisation is one with counts in Eq. 1's long late tail: the
detected pixels' centroid sits early of the mean over all realisations, which the expected
histogram gives (:mod:`.expected`), and the law of their errors is less skewed late. Neither has
a closed form (the scan statistic of a skewed pulse), so both are read from a calibrated table,
as photon-counting altimetry calibrates its first-photon bias: for m = 1 .. M counts of one
surface's low-flux pulse (Gamma(2, s), Gaussian jitter, a uniform bin phase), drawn
TABLE_DRAWS times with a fixed seed, the frame's own estimator (the densest window from an
occupied bin, the threshold, the analysis window placed from it, Coates' weights of the
first-photon detector, the centroid less 2 s) gives each draw's error and whether it is
detected; the same draws give the model's own reading (the window at its expected place, a ratio
of expectations). A pixel's counts in its window are Binomial(N, mu / N) (one avalanche a pulse
at most), mu the expected histogram's signal counts; summed over m, the table gives the
detected pixels' mean error and the median of their errors, each less the model's mean: what
the expected histogram's centroid lacks (the selection, and at a few counts the window found in
the data and the ratio of the centroid's expectations; and the skewness of a few counts in the
median).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy import special

from ...cache import TableCache

TABLE_DRAWS = 8192  # draws per count m up to SMALL_COUNTS (where the selection acts)
TABLE_DRAWS_MANY = 2048  # draws per count m above (only the median needs them)
SMALL_COUNTS = 24
TABLE_SEED = 25_03  # issue 25, item 3: a fixed seed, so a scene reproduces its summary
TABLE_COUNTS = 48  # counts m tabulated at most
MU_MAX = 24.0  # the table's shifts are used up to this many expected counts (beyond: 0, and
# the Cornish-Fisher median): P(m > TABLE_COUNTS) there is below 1e-5


@dataclass(frozen=True, eq=False)  # hashed by identity: one table, one cache entry
class Selection:
    """The calibrated table of one estimator: per count m = 1 .. M, each draw's error [s] from
    the echo's start (NaN where the analysis window holds nothing, or past the draws of that m)
    and its densest window's counts (detected where they reach the threshold).

    err : (M, R) float; peak : (M, R) float; draws : (M,) int, the draws of each m
    num, den : (M,) the mean over the draws of sum_i w_i e_i and of sum_i w_i over the analysis
        window at its expected place (the expected histogram's densest window), w_i each
        count's share of its bin's Coates estimate and e_i its bin's time less 2 s from the
        echo's start: the model's centroid is E num / E den (a ratio of expectations) [s, 1]
    key : the arguments of :func:`selection_table` that made it (the cache's key of what is
        derived from it)
    """

    err: np.ndarray
    peak: np.ndarray
    draws: np.ndarray
    num: np.ndarray
    den: np.ndarray
    key: tuple = ()


_HERE = Path(__file__).resolve()
# the draws depend on the pulse, jitter, bin and windows only; the shifts on a table, the pulses
# and the threshold: both cached on disk, keyed by this module's source (simcore.cache)
DRAWS = TableCache("gm_selection_draws", (_HERE,), max_memory=2, max_entries=8)  # 20 MB each
SHIFTS = TableCache("gm_selection_shifts", (_HERE,), max_memory=256, max_entries=512)


@lru_cache(maxsize=16)
def selection_table(
    scale_s: float,
    jitter_s: float,
    bin_s: float,
    width: int,
    pre: int,
    length: int,
    n_pulses: int,
    coates: bool,
) -> Selection:
    """The table for Eq. 1's pulse of Gamma(2) scale ``scale_s``, the jitter and the TDC bin
    [s], the peak window of ``width`` bins, the analysis window of ``length`` bins from ``pre``
    bins before the peak window, and ``n_pulses`` (Coates' armed pulses; raw counts when not
    ``coates``). The draws and their densest windows (:func:`selection_draws`, all that costs)
    do not depend on the pulses; here each draw's Coates weights at ``n_pulses`` and its
    errors, O(m) a draw. Deterministic (TABLE_SEED)."""
    d = selection_draws(float(scale_s), float(jitter_s), float(bin_s), width, pre, length)
    top = int(min(TABLE_COUNTS, n_pulses))
    err = np.full((top, TABLE_DRAWS), np.nan)
    peak_counts = np.zeros((top, TABLE_DRAWS))
    draws = np.zeros(top, dtype=np.int64)
    num, den = np.zeros(top), np.zeros(top)
    shares = coates_shares(n_pulses, TABLE_COUNTS)
    for m in range(1, top + 1):
        b = d[f"bin_{m}"].astype(np.float64)  # (r, m) each count's bin, sorted
        phase_s = d[f"phase_{m}"][:, None]  # the echo's start within its bin
        first = d[f"first_{m}"].astype(np.intp)  # the densest window's first count
        r = len(b)
        draws[m - 1] = r
        rows = np.arange(r)
        peak_counts[m - 1, :r] = d[f"peak_{m}"]
        if coates:  # each count its share of its bin's estimate, by its counts before and same
            share = shares[d[f"before_{m}"].astype(np.intp), d[f"same_{m}"].astype(np.intp)]
        else:
            share = np.ones_like(b)
        e_bin = (b + 0.5) * bin_s - 2.0 * scale_s - phase_s  # each count's bin, from the start
        # the frame's estimator: the window from the densest one found in the counts
        ws = b[rows, first][:, None] - pre
        w = np.where((b >= ws) & (b < ws + length), share, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            err[m - 1, :r] = (w * e_bin).sum(axis=1) / w.sum(axis=1)
        # the model's: the window at its expected place
        ws = d[f"model_start_{m}"].astype(np.float64)[:, None]
        w = np.where((b >= ws) & (b < ws + length), share, 0.0)
        num[m - 1] = (w * e_bin).sum(axis=1).mean()
        den[m - 1] = w.sum(axis=1).mean()
    err.setflags(write=False)
    peak_counts.setflags(write=False)
    key = (float(scale_s), float(jitter_s), float(bin_s), width, pre, length, n_pulses, coates)
    return Selection(err=err, peak=peak_counts, draws=draws, num=num, den=den, key=key)


def coates_shares(n_pulses: int, counts: int) -> np.ndarray:
    """(counts, counts + 1) the share of its bin's Coates estimate each of ``same`` counts in
    one bin has when ``before`` counts came in earlier bins (first photon: the bin's armed
    pulses are N less those), at [before, same]: -ln(1 - min(same, A - 1/2) / A) / same,
    A = N - before (0 where no pulse is armed; column 0 unused)."""
    before = np.arange(counts)[:, None]
    same = np.arange(counts + 1)[None, :]
    armed = n_pulses - before
    a = np.maximum(armed, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where(armed > 0, -np.log1p(-np.minimum(same, a - 0.5) / a), 0.0)
        return np.where(same > 0, v / np.maximum(same, 1), 0.0)


def _counts_before_and_same(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(r, m) int64 for rows of sorted bins: how many counts of the row lie in earlier bins
    and how many share each count's bin (exact integers, as the pairwise comparison counts)."""
    r, m = b.shape
    col = np.broadcast_to(np.arange(m), (r, m))
    starts = np.ones((r, m), dtype=bool)
    starts[:, 1:] = b[:, 1:] != b[:, :-1]
    before = np.maximum.accumulate(np.where(starts, col, 0), axis=1)  # its bin's first count
    ends = np.ones((r, m), dtype=bool)
    ends[:, :-1] = starts[:, 1:]
    last = np.minimum.accumulate(np.where(ends, col, m)[:, ::-1], axis=1)[:, ::-1]
    return before.astype(np.int64), (last - before + 1).astype(np.int64)


def selection_draws(
    scale_s: float, jitter_s: float, bin_s: float, width: int, pre: int, length: int
) -> dict[str, np.ndarray]:
    """The table's draws for m = 1 .. TABLE_COUNTS counts (cached in memory and on disk,
    :data:`DRAWS`): per m, ``bin_m`` (r, m) each count's TDC bin, sorted; ``phase_m`` (r,) the
    echo's start within its bin [s]; ``first_m`` (r,) the first count of the densest window of
    ``width`` bins from an occupied bin (the earliest on ties) and ``peak_m`` (r,) its counts;
    ``model_start_m`` (r,) the first bin of the analysis window at its expected place (``pre``
    bins before the expected densest window; ``length`` is part of the key only); ``before_m``
    and ``same_m`` (r, m) each count's counts in earlier bins and in its own (what its Coates
    weight depends on, :func:`coates_shares`). O(m^2)
    comparisons a draw, once; the same random numbers whatever the pulses (TABLE_SEED)."""
    args = (scale_s, jitter_s, bin_s, int(width), int(pre), int(length))
    return DRAWS.get(args, lambda: _draw(*args))


def _draw(scale_s, jitter_s, bin_s, width, pre, length) -> dict[str, np.ndarray]:
    """:func:`selection_draws` computed."""
    rng = np.random.default_rng(TABLE_SEED)
    out: dict[str, np.ndarray] = {}
    # the expected densest window of a low-flux pulse starts where Eq. 1's density is equal at
    # both its ends, x e^-x = (x + w) e^-(x + w): x = w / (e^w - 1) (w its width over s)
    w_s = width * bin_s / scale_s
    lead_s = scale_s * w_s / np.expm1(w_s)
    for m in range(1, TABLE_COUNTS + 1):
        r = TABLE_DRAWS if m <= SMALL_COUNTS else TABLE_DRAWS_MANY
        phase_s = rng.random((r, 1)) * bin_s  # the echo's start within its bin
        t = phase_s + scale_s * rng.standard_gamma(2.0, (r, m))
        t = t + jitter_s * rng.standard_normal((r, m))
        b = np.sort(np.floor(t / bin_s), axis=1)  # (r, m) each count's bin
        later = b[:, None, :] - b[:, :, None]  # [i, j]: b_j - b_i
        # the window of ``width`` bins from each occupied bin: the densest, the earliest on ties
        in_w = ((later >= 0) & (later < width)).sum(axis=2)
        first = np.argmax(in_w, axis=1)
        small = np.abs(b).max(initial=0.0) < 2**15
        out[f"bin_{m}"] = b.astype(np.int16 if small else np.int64)  # whole numbers: exact
        out[f"phase_{m}"] = phase_s[:, 0]
        out[f"first_{m}"] = first.astype(np.int16)
        before, same = _counts_before_and_same(b)
        out[f"before_{m}"], out[f"same_{m}"] = before.astype(np.int8), same.astype(np.int8)
        out[f"peak_{m}"] = in_w[np.arange(r), first].astype(np.int8)  # at most 48
        model_start = np.floor((phase_s[:, 0] + lead_s) / bin_s) - pre
        out[f"model_start_{m}"] = model_start.astype(np.int64)  # whole numbers: exact
    return out


def selection_shifts(
    table: Selection, mean_counts, n_pulses: int, k_t
) -> tuple[np.ndarray, np.ndarray]:
    """(n,) for pixels of ``mean_counts`` expected signal counts in their window (Binomial
    (N, mu / N) counts) and threshold ``k_t`` counts (scalar or (n,)): the detected pixels'
    mean error less the model's mean (the expected histogram's centroid) [s] (0 where mu >
    MU_MAX), and the median of the detected pixels' errors less the model's mean [s] (NaN
    where mu > MU_MAX: the Cornish-Fisher term stands there)."""
    mu = np.asarray(mean_counts, dtype=np.float64)
    k_all = np.broadcast_to(np.asarray(k_t, dtype=np.float64), mu.shape)
    d_mean = np.zeros(mu.shape)
    d_median = np.full(mu.shape, np.nan)
    use = (mu > 0) & (mu <= MU_MAX)
    for k in np.unique(k_all[use]):
        sel = use & (k_all == k)
        x, shift, median = _shift_nodes(table, n_pulses, float(k))
        d_mean[sel] = np.interp(np.log(mu[sel]), x, shift)
        d_median[sel] = np.interp(np.log(mu[sel]), x, median)
    return d_mean, d_median


NODES = np.geomspace(0.05, MU_MAX, 128)  # expected counts at which the shifts are summed


def _shift_nodes(table: Selection, n_pulses: int, k_t: float) -> tuple[np.ndarray, ...]:
    """On NODES (log): the detected pixels' mean error and their median error, each less the
    model's mean [s], summed over the counts' binomial law given m >= 1 (cached in memory and
    on disk, :data:`SHIFTS`, by the table's key, the pulses and the threshold)."""
    args = (*table.key, int(n_pulses), float(k_t))
    if not table.key:  # a table made by hand: no key to cache it under
        return _shift_nodes_computed(table, n_pulses, k_t)
    got = SHIFTS.get(
        args, lambda: dict(zip("xsm", _shift_nodes_computed(table, n_pulses, k_t), strict=True))
    )
    return got["x"], got["s"], got["m"]


def _shift_nodes_computed(table: Selection, n_pulses: int, k_t: float) -> tuple[np.ndarray, ...]:
    """:func:`_shift_nodes` computed."""
    top = table.err.shape[0]
    m = np.arange(1, top + 1)
    p = np.clip(NODES / n_pulses, 0.0, 1.0)[:, None]
    w_m = special.bdtr(m, n_pulses, p) - special.bdtr(m - 1, n_pulses, p)  # (g, top)
    w_m = w_m / np.maximum(w_m.sum(axis=1, keepdims=True), 1e-300)
    ok = np.isfinite(table.err)
    det = ok & (table.peak >= k_t)
    d_m = det.sum(axis=1) / table.draws
    c_m = np.where(det, table.err, 0.0).sum(axis=1) / np.maximum(det.sum(axis=1), 1)
    # the model's mean (a ratio of expectations, its window at its expected place): what the
    # detected pixels' mean and median are given against
    all_mean = (w_m @ table.num) / np.maximum(w_m @ table.den, 1e-300)
    seen = w_m @ d_m
    det_mean = (w_m * d_m) @ c_m / np.maximum(seen, 1e-300)
    node_median = _weighted_medians(table, det, w_m / table.draws[None, :])
    good = seen > 1e-6  # below: no pixel of the frame is detected
    return (
        np.log(NODES),
        np.where(good, det_mean - all_mean, 0.0),
        np.where(good, node_median - all_mean, 0.0),
    )


def _weighted_medians(table: Selection, det: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(g,) the weighted median of the detected draws' errors at each node: every detected draw
    of count m weighs ``weight[g, m]``; the least error (sorted) at which the cumulative weight
    reaches half the node's total. The cumulative weight after the first i + 1 sorted draws is
    sum_m weight[g, m] x (draws of m among them), found by bisection on i (log2 of the draws
    steps, each one sorted search per count): no node's weights of every draw at once."""
    flat_err = table.err[det]
    if not len(flat_err):
        return np.zeros(weight.shape[0])
    flat_m = np.broadcast_to(np.arange(det.shape[0])[:, None], det.shape)[det]
    order = np.argsort(flat_err)
    flat_err, flat_m = flat_err[order], flat_m[order]
    places = [np.flatnonzero(flat_m == m) for m in range(det.shape[0])]
    counts = np.array([len(pl) for pl in places], dtype=np.float64)
    half = 0.5 * (weight @ counts)

    def cumulative(i: np.ndarray) -> np.ndarray:  # (g,) the weight of sorted draws 0 .. i
        held = np.stack([np.searchsorted(pl, i, side="right") for pl in places], axis=1)
        return np.einsum("gm,gm->g", weight, held.astype(np.float64))

    lo = np.zeros(weight.shape[0], dtype=np.int64)  # the answer lies in lo .. hi
    hi = np.full(weight.shape[0], len(flat_err) - 1, dtype=np.int64)
    while np.any(lo < hi):
        mid = (lo + hi) // 2
        reached = cumulative(mid) >= half
        hi = np.where(reached, mid, hi)
        lo = np.where(reached, lo, mid + 1)
    return flat_err[lo]
