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

import numpy as np
from scipy import special

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
    """

    err: np.ndarray
    peak: np.ndarray
    draws: np.ndarray
    num: np.ndarray
    den: np.ndarray


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
    ``coates``). Each draw's m counts are read from their sorted bins (no dense histogram):
    O(m^2) comparisons a draw. Deterministic (TABLE_SEED)."""
    rng = np.random.default_rng(TABLE_SEED)
    top = int(min(TABLE_COUNTS, n_pulses))
    err = np.full((top, TABLE_DRAWS), np.nan)
    peak_counts = np.zeros((top, TABLE_DRAWS))
    draws = np.zeros(top, dtype=np.int64)
    num, den = np.zeros(top), np.zeros(top)
    # the expected densest window of a low-flux pulse starts where Eq. 1's density is equal at
    # both its ends, x e^-x = (x + w) e^-(x + w): x = w / (e^w - 1) (w its width over s)
    w_s = width * bin_s / scale_s
    lead_s = scale_s * w_s / np.expm1(w_s)
    for m in range(1, top + 1):
        r = TABLE_DRAWS if m <= SMALL_COUNTS else TABLE_DRAWS_MANY
        draws[m - 1] = r
        phase_s = rng.random((r, 1)) * bin_s  # the echo's start within its bin
        t = phase_s + scale_s * rng.standard_gamma(2.0, (r, m))
        t = t + jitter_s * rng.standard_normal((r, m))
        b = np.sort(np.floor(t / bin_s), axis=1)  # (r, m) each count's bin
        later = b[:, None, :] - b[:, :, None]  # [i, j]: b_j - b_i
        # the window of ``width`` bins from each occupied bin: the densest, the earliest on ties
        in_w = ((later >= 0) & (later < width)).sum(axis=2)
        first = np.argmax(in_w, axis=1)
        rows = np.arange(r)
        peak_counts[m - 1, :r] = in_w[rows, first]
        if coates:  # first photon: a bin's armed pulses are N less every count before it
            before = (later > 0).sum(axis=1)  # [j]: counts i with b_i < b_j
            same = (later == 0).sum(axis=1)  # counts in b_j's bin
            armed = n_pulses - before
            a = np.maximum(armed, 1.0)
            v = np.where(armed > 0, -np.log1p(-np.minimum(same, a - 0.5) / a), 0.0)
            share = v / same  # each count its share of its bin's estimate
        else:
            share = np.ones_like(b)
        e_bin = (b + 0.5) * bin_s - 2.0 * scale_s - phase_s  # each count's bin, from the start
        # the frame's estimator: the window from the densest one found in the counts
        ws = b[rows, first][:, None] - pre
        w = np.where((b >= ws) & (b < ws + length), share, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            err[m - 1, :r] = (w * e_bin).sum(axis=1) / w.sum(axis=1)
        # the model's: the window at its expected place
        ws = np.floor((phase_s + lead_s) / bin_s) - pre
        w = np.where((b >= ws) & (b < ws + length), share, 0.0)
        num[m - 1] = (w * e_bin).sum(axis=1).mean()
        den[m - 1] = w.sum(axis=1).mean()
    err.setflags(write=False)
    peak_counts.setflags(write=False)
    return Selection(err=err, peak=peak_counts, draws=draws, num=num, den=den)


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
NODES_AT_ONCE = 8  # nodes whose detected pixels' medians are found together (memory: see below)


@lru_cache(maxsize=64)
def _shift_nodes(table: Selection, n_pulses: int, k_t: float) -> tuple[np.ndarray, ...]:
    """On NODES (log): the detected pixels' mean error and their median error, each less the
    model's mean [s], summed over the counts' binomial law given m >= 1."""
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
    # the detected pixels' median: every detected draw weighted by its count's chance
    flat_err = table.err[det]
    flat_m = np.broadcast_to(np.arange(top)[:, None], det.shape)[det]
    order = np.argsort(flat_err)
    flat_err, flat_m = flat_err[order], flat_m[order]
    node_median = np.zeros(len(NODES))
    if len(flat_err):
        # a few nodes at a time: every node's weights of every detected draw at once took 250 MB
        # (128 nodes x ~245,000 draws, twice) on top of a frame's own memory
        draws_m = table.draws[flat_m]
        for g in range(0, len(NODES), NODES_AT_ONCE):
            cw = np.cumsum(w_m[g : g + NODES_AT_ONCE, flat_m] / draws_m, axis=1)
            i = np.minimum((cw < 0.5 * cw[:, -1:]).sum(axis=1), len(flat_err) - 1)
            node_median[g : g + NODES_AT_ONCE] = flat_err[i]
    good = seen > 1e-6  # below: no pixel of the frame is detected
    return (
        np.log(NODES),
        np.where(good, det_mean - all_mean, 0.0),
        np.where(good, node_median - all_mean, 0.0),
    )
