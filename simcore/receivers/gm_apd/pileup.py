"""Geiger-mode pile-up: what the histogram's range estimators give at any flux, and the
first-photon (pile-up) correction (docs/physics.md#gm-pileup).

The parts: :mod:`.expected` (the expected histogram and its centroid), :mod:`.coates`
(the moments of Coates' estimate), :mod:`.first_photon` (the correction); here, the
prediction for every lit pixel of a frame.
"""

from __future__ import annotations

import numpy as np

from ... import parallel
from ...stage import Cancelled, stop_check
from .expected import (
    BLOCK_VALUES,
    Prediction,
    Timing,
    coates_centroid,
    expected_histogram,
    expected_windows,
    fine_cells_per_bin,
)
from .first_photon import predict_fit

MAX_BINS = 512  # bins of a modelled window at most (finer TDC bins are merged)


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
    :func:`expected_windows`; ``min_counts``: each pixel's detection threshold in counts;
    None, for the centroid only: ``sd_s`` holds the variance before the threshold's factor,
    which :func:`.expected.with_threshold` applies, so that a threshold change re-uses it).
    In blocks of pixels of at most BLOCK_VALUES fine cells, on the frame's threads; a window
    of more than MAX_BINS bins (TDC bins far finer than the pulse and the jitter) is modelled
    on bins merged by g to at most MAX_BINS (each merged bin's hazard is then still small, so
    Coates' estimate of it is the sum of its parts')."""
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
    if min_counts is None and correction == "fit":
        raise ValueError("the first-photon fit's prediction needs the thresholds (min_counts)")
    if min_counts is not None:
        min_counts = np.broadcast_to(np.asarray(min_counts, dtype=np.float64), (n,))
    span = 2 * (pre + width + length) + 16
    cells = (span + 8 * length) * fine_cells_per_bin(t) + 4096
    rows = max(1, int(BLOCK_VALUES // max(cells, 1.0)))
    stop = stop_check()  # a frame no longer wanted ends between blocks

    def block(lo: int) -> Prediction:
        if stop is not None and stop():
            raise Cancelled("stopped while predicting the pixels' histograms")
        sl = slice(lo, lo + rows)
        return _predict_block(
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
            None if min_counts is None else min_counts[sl],
        )

    # the blocks on the frame's threads (numpy releases the GIL): each the same as in turn
    parts = parallel.map_threads(block, range(0, n, rows))
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
