"""A Geiger-mode frame's histograms and what is read from them (docs/physics.md#gm-histogram):
the sparse per-pixel histogram of event bins, the peak window, Coates' pile-up correction and
the centroid range estimator.

Memory: a histogram is kept sparse, one (pixel, bin, count) row per occupied bin (at most one per
avalanche), never dense over the gate. The peak search runs on it directly; only the detected
pixels get a dense analysis window of a few tens of bins, in blocks of bounded size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .events import Events

ESTIMATOR_BLOCK = 8192  # detected pixels per dense analysis block
BLOCK_VALUES = 1 << 22  # bins of a dense analysis block at most (32 MB of float64 per array)


@dataclass(frozen=True, kw_only=True)
class Histogram:
    """The sparse histograms of every pixel: one row per occupied (pixel, bin).

    pixel : (u,) int64, ascending; bin : (u,) int64, ascending within a pixel; count : (u,) int64
    n_bins : bins of the gate; n_pulses : pulses accumulated
    """

    pixel: np.ndarray
    bin: np.ndarray
    count: np.ndarray
    n_bins: int
    n_pulses: int

    @property
    def stride(self) -> int:
        """Key spacing between pixels: a window of up to n_bins never reaches the next pixel."""
        return 2 * self.n_bins

    @property
    def key(self) -> np.ndarray:
        return self.pixel * self.stride + self.bin

    def pixel_counts(self, pixel: int) -> tuple[np.ndarray, np.ndarray]:
        """One pixel's occupied bins and counts."""
        lo, hi = np.searchsorted(self.pixel, [pixel, pixel + 1])
        return self.bin[lo:hi], self.count[lo:hi]


def histogram(events: Events, n_bins: int, n_pulses: int) -> Histogram:
    """The sparse histogram of ``events`` (sorted by pixel, then bin)."""
    pixel = events.pixel.astype(np.int64)
    b = events.bin.astype(np.int64)
    if len(pixel) == 0:
        empty = np.zeros(0, np.int64)
        return Histogram(pixel=empty, bin=empty, count=empty, n_bins=n_bins, n_pulses=n_pulses)
    new = np.r_[True, (pixel[1:] != pixel[:-1]) | (b[1:] != b[:-1])]
    first = np.flatnonzero(new)
    count = np.diff(np.r_[first, len(pixel)])
    return Histogram(
        pixel=pixel[first], bin=b[first], count=count, n_bins=n_bins, n_pulses=n_pulses
    )


@dataclass(frozen=True, kw_only=True)
class Peaks:
    """The densest window of ``width`` bins of every pixel that has events.

    pixel : (q,) int64; start_bin : (q,) int64 first bin of the window; count : (q,) its counts
    """

    pixel: np.ndarray
    start_bin: np.ndarray
    count: np.ndarray


def peak_windows(h: Histogram, width: int) -> Peaks:
    """Each pixel's window of ``width`` bins with the most counts (the box-car matched filter of
    a pulse as wide as the window; the earliest on ties). The best window can always start at an
    occupied bin, so only those are tried: O(u log u) on the sparse histogram."""
    if len(h.pixel) == 0:
        empty = np.zeros(0, np.int64)
        return Peaks(pixel=empty, start_bin=empty, count=empty)
    key = h.key
    cum = np.r_[0, np.cumsum(h.count)]
    j = np.searchsorted(key, key + width)
    in_window = cum[j] - cum[:-1]
    first = np.flatnonzero(np.r_[True, h.pixel[1:] != h.pixel[:-1]])
    best = np.maximum.reduceat(in_window, first)
    seg = np.repeat(np.arange(len(first)), np.diff(np.r_[first, len(key)]))
    at_best = np.flatnonzero(in_window == best[seg])
    _, first_best = np.unique(seg[at_best], return_index=True)
    i = at_best[first_best]
    return Peaks(pixel=h.pixel[i], start_bin=h.bin[i], count=in_window[i])


def counts_below(h: Histogram, pixel: np.ndarray, bin_: np.ndarray) -> np.ndarray:
    """(q,) events of each ``pixel`` in bins below ``bin_`` (C(j) of the dead-time sums)."""
    key = h.key
    cum = np.r_[0, np.cumsum(h.count)]
    at = np.searchsorted(key, pixel * h.stride + np.clip(bin_, 0, h.n_bins))
    start = np.searchsorted(key, pixel * h.stride)
    return cum[at] - cum[start]


def dense_window(h: Histogram, pixel: np.ndarray, start_bin: np.ndarray, length: int):
    """(q, length) counts of bins start_bin .. start_bin + length - 1 of each pixel (bins
    outside the gate count 0)."""
    out = np.zeros((len(pixel), length), dtype=np.float64)
    key = h.key
    lo = np.searchsorted(key, pixel * h.stride + np.maximum(start_bin, 0))
    hi = np.searchsorted(key, pixel * h.stride + np.maximum(start_bin + length, 0))
    n = hi - lo
    row = np.repeat(np.arange(len(pixel)), n)
    idx = np.arange(int(n.sum())) + np.repeat(lo - (np.cumsum(n) - n), n)
    out[row, h.bin[idx] - start_bin[row]] = h.count[idx]
    return out


def armed_pulses(h: Histogram, pixel, start_bin, counts, dead_bins: int) -> np.ndarray:
    """(q, L) pulses in which the pixel is armed at the start of each bin of the window: N minus
    the pulses whose pixel fired within the dead time before it (events in bins [j - m, j - 1],
    m = dead_bins; every earlier bin when the dead time outlasts the gate)."""
    length = counts.shape[1]
    before = counts_below(h, pixel, start_bin)[:, None] + np.cumsum(counts, axis=1) - counts
    if dead_bins < h.n_bins:
        shifted = start_bin - dead_bins
        c2 = dense_window(h, pixel, shifted, length)
        below2 = counts_below(h, pixel, shifted)[:, None] + np.cumsum(c2, axis=1) - c2
        before = before - below2
    return h.n_pulses - before


def coates_rate(counts, armed) -> np.ndarray:
    """Coates' correction (Coates 1968): the mean primary events per pulse in each bin,
    Lambda_j = -ln(1 - n_j / A_j), A_j the pulses armed at bin j. Where every armed pulse fired
    (n_j = A_j, the estimate is infinite) n_j is taken as A_j - 1/2."""
    a = np.maximum(armed, 1.0)
    ratio = np.minimum(counts, a - 0.5) / a
    return np.where(armed > 0, -np.log1p(-ratio), 0.0)


@dataclass(frozen=True, kw_only=True)
class Estimate:
    """The centroid estimate of each detected pixel's echo: t_s the centroid time from the gate's
    opening [s] (NaN where the window holds no excess over the background) and the window's
    background-subtracted signal events (raw counts) and mean primary events per pulse."""

    t_s: np.ndarray
    signal_counts: np.ndarray


def centroid_times(
    h: Histogram,
    pixel,
    window_start_bin,
    length: int,
    bin_s: float,
    background_per_bin,
    dead_bins: int,
    coates: bool,
) -> Estimate:
    """The centroid of each pixel's echo over its analysis window of ``length`` bins:
    sum_j v_j t_j / sum_j v_j with t_j the bin centre and v_j the Coates rate less the
    background's (``coates``), or the raw counts less the background's N r b (not corrected).

    background_per_bin : (q,) mean primary background events per pulse and bin, r b [1]
    """
    q = len(pixel)
    t_s = np.full(q, np.nan)
    signal = np.zeros(q)
    block = max(1, min(ESTIMATOR_BLOCK, BLOCK_VALUES // max(int(length), 1)))
    for lo in range(0, q, block):
        sl = slice(lo, lo + block)
        p, s0 = pixel[sl], window_start_bin[sl]
        counts = dense_window(h, p, s0, length)
        bg = background_per_bin[sl][:, None]
        if coates:
            armed = armed_pulses(h, p, s0, counts, dead_bins)
            v = coates_rate(counts, armed) - bg
        else:
            v = counts - h.n_pulses * bg
        t_bin = (s0[:, None] + np.arange(length)[None, :] + 0.5) * bin_s
        total = v.sum(axis=1)
        ok = total > 0
        t_s[sl] = np.where(ok, (v * t_bin).sum(axis=1) / np.where(ok, total, 1.0), np.nan)
        signal[sl] = np.maximum((counts - h.n_pulses * bg).sum(axis=1), 0.0)
    return Estimate(t_s=t_s, signal_counts=signal)
