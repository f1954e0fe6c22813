"""Echo features: peak, half-maximum time and CFD slope of each pixel's band-limited echo
(Eqs. 19, 25, 31), per joule of pulse energy, from exact delays (never snapped to the time grid)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import parallel
from ..pulse import PulseShape


@dataclass(frozen=True, kw_only=True)
class EchoFeatures:
    """Per-pixel features of the noise-free band-limited echo y (per joule).

    peak_w_per_j : (n,) peak of y [W/J]
    t_half_s : (n,) first time y reaches half its peak (Eq. 31), absolute since emission [s]
    cfd_slope_per_s : (n,) |ds/dt| of the normalised CFD signal s = y_n(t - t_d) - k y_n(t) at its
        firing time (Eq. 25; t_d the CFD delay, k the CFD fraction) [1/s]
    peak_raw_w_per_j : (n,) peak of the unfiltered echo P_r (paper's Eq. 14 form), or None
    cfd_shot_level : (n, 3) the signal current whose shot noise the CFD's samples carry, over
        the band-limited peak [1]: the echo through h_B^2 (unit area) at the delayed sample
        t* - t_d, at the prompt sample t*, and midway, t* - t_d / 2 (the two samples' shot-noise
        covariance); t* the firing time (t_half + t_d where the CFD signal has no crossing).
        For a single surface with the defaults 0.55, 1.09, 0.94. Eq. 25 (ours) gives each
        sample the shot noise of its own current with them.
    """

    peak_w_per_j: np.ndarray
    t_half_s: np.ndarray
    cfd_slope_per_s: np.ndarray
    peak_raw_w_per_j: np.ndarray | None
    cfd_shot_level: np.ndarray


def _eval_exact(shape: PulseShape, table, arrivals, weights, t):
    """y(t) = sum_k w_k p(t - t_k) at one time per pixel. arrivals, weights: (n, K); t: (n,)."""
    return np.einsum("nk,nk->n", weights, shape.lookup(table, t[:, None] - arrivals))


def _refined_peak(shape, table, arrivals, weights, grid, y, dt_s):
    """Peak of each row of y: best sample, parabolic vertex, exact value there."""
    rows = np.arange(len(y))
    j = np.clip(np.argmax(y, axis=1), 1, y.shape[1] - 2)
    y0, y1, y2 = y[rows, j - 1], y[rows, j], y[rows, j + 1]
    den = y0 - 2 * y1 + y2
    off = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    t_v = grid[rows, j] + np.clip(off, -1, 1) * dt_s
    # one more parabolic step on exact values, a quarter sample either side
    h = dt_s / 4
    e0, e1, e2 = (_eval_exact(shape, table, arrivals, weights, t_v + s * h) for s in (-1, 0, 1))
    den = e0 - 2 * e1 + e2
    off = np.where(den < 0, 0.5 * (e0 - e2) / np.where(den < 0, den, -1.0), 0.0)
    t_v = t_v + np.clip(off, -1, 1) * h
    return np.maximum(_eval_exact(shape, table, arrivals, weights, t_v), np.maximum(e1, y1))


def _features_chunk(
    shape, arrivals, weights, t_first, n_samples, dt_s, cfd_delay_s, t_begin, cfd_fraction, raw
):
    n = len(arrivals)
    grid = t_first[:, None] + t_begin + dt_s * np.arange(n_samples)[None, :]  # (n, L)
    y = np.einsum("nlk,nk->nl", shape.filtered_at(grid[:, :, None] - arrivals[:, None, :]), weights)
    rows = np.arange(n)

    peak = _refined_peak(shape, shape.filtered, arrivals, weights, grid, y, dt_s)

    # half-maximum crossing: bracket on the grid, then regula falsi on exact values
    half = 0.5 * peak
    jh = np.argmax(y >= half[:, None], axis=1)
    jh = np.maximum(jh, 1)
    ta, tb = grid[rows, jh - 1], grid[rows, jh]
    fa, fb = y[rows, jh - 1] - half, y[rows, jh] - half
    for _ in range(4):
        tm = ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0)
        tm = np.clip(tm, ta, tb)
        fm = _eval_exact(shape, shape.filtered, arrivals, weights, tm) - half
        left = fm < 0
        ta, fa = np.where(left, tm, ta), np.where(left, fm, fa)
        tb, fb = np.where(left, tb, tm), np.where(left, fb, fm)
    t_half = ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0)

    # CFD signal on the grid: y(t - cfd_delay_s) by a fractional shift of the samples
    shift = cfd_delay_s / dt_s
    ns, frac = int(np.floor(shift)), shift - np.floor(shift)
    yd = np.zeros_like(y)
    if ns < n_samples:
        yd[:, ns:] += (1.0 - frac) * y[:, : n_samples - ns]
    if ns + 1 < n_samples:
        yd[:, ns + 1 :] += frac * y[:, : n_samples - ns - 1]
    s = (yd - cfd_fraction * y) / np.where(peak > 0, peak, 1.0)[:, None]
    # first local maximum of y after the half-max crossing, then the firing window of Eq. 19
    is_max = np.zeros_like(y, dtype=bool)
    is_max[:, 1:-1] = (y[:, 1:-1] >= y[:, :-2]) & (y[:, 1:-1] > y[:, 2:])
    after = np.arange(n_samples)[None, :] >= jh[:, None]
    jpk = np.argmax(is_max & after, axis=1)
    jpk = np.where((is_max & after).any(axis=1), jpk, n_samples - 1)
    t_pk1 = grid[rows, jpk]
    up = np.zeros_like(y, dtype=bool)
    up[:, 1:] = (s[:, :-1] < 0) & (s[:, 1:] >= 0)
    window = (grid >= (t_half - cfd_delay_s)[:, None]) & (
        grid <= (t_pk1 + cfd_delay_s + dt_s)[:, None]
    )
    cand = up & window
    last = np.maximum(n_samples - 1 - np.argmax(cand[:, ::-1], axis=1), 1)
    found = cand.any(axis=1)
    norm = np.where(peak > 0, peak, 1.0)
    exact = lambda t: _eval_exact(shape, shape.filtered, arrivals, weights, t)  # noqa: E731
    cfd = lambda t: (exact(t - cfd_delay_s) - cfd_fraction * exact(t)) / norm  # noqa: E731
    # the crossing: linear on the grid, then secant steps on the exact CFD signal
    sa, sb = s[rows, last - 1], s[rows, last]
    ta, tb = grid[rows, last - 1], grid[rows, last]
    for _ in range(3):
        tm = np.clip(ta - sa * (tb - ta) / np.where(sb != sa, sb - sa, 1.0), ta, tb)
        sm = cfd(tm)
        left = sm < 0
        ta, sa = np.where(left, tm, ta), np.where(left, sm, sa)
        tb, sb = np.where(left, tb, tm), np.where(left, sb, sm)
    t_star = ta - sa * (tb - ta) / np.where(sb != sa, sb - sa, 1.0)
    h = 1e-3 * dt_s  # exact derivatives by central differences
    slope_cfd = (cfd(t_star + h) - cfd(t_star - h)) / (2 * h)
    slope_half = (exact(t_half + h) - exact(t_half - h)) / (2 * h) / norm
    slope = np.abs(np.where(found, slope_cfd, slope_half))
    t_fire = np.where(found, t_star, t_half + cfd_delay_s)
    shot = lambda t: _eval_exact(shape, shape.shot, arrivals, weights, t) / norm  # noqa: E731
    level = (shot(t_fire - cfd_delay_s), shot(t_fire), shot(t_fire - 0.5 * cfd_delay_s))

    peak_raw = None
    if raw:
        yr = np.einsum("nlk,nk->nl", shape.raw_at(grid[:, :, None] - arrivals[:, None, :]), weights)
        peak_raw = _refined_peak(shape, shape.raw, arrivals, weights, grid, yr, dt_s)
    return peak, t_half, slope, peak_raw, *level


def echo_features(
    shape: PulseShape,
    arrivals_s,
    weights,
    dt_s: float,
    cfd_delay_s: float,
    cfd_fraction: float,
    raw_peak: bool = False,
    max_elements: int = 1 << 20,
) -> EchoFeatures:
    """Peak, half-maximum time and CFD slope of each pixel's band-limited echo.

    A pixel lit by one element echoes the reference pulse, shifted and scaled: its features are
    the pulse's own, found once. The others are sampled at ``dt_s`` on their own window, from just
    before the first arrival to past the last arrival's peak plus the CFD delay (their depth plus
    the pulse), never the whole gate. Each pixel's contributing elements are moved to the front
    and pixels are grouped by element count and window length, in chunks of at most
    ``max_elements`` (pixels x samples x elements) so that memory stays bounded.

    arrivals_s, weights : (n, K) -- two-way delays [s] and Eq. 30 weights (0 = no contribution)
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    n = len(arrivals)
    has = weights > 0
    count = has.sum(axis=1)
    peak = np.zeros(n)
    t_half = np.zeros(n)
    slope = np.zeros(n)
    level = np.zeros((n, 3))
    peak_raw = np.zeros(n) if raw_peak else None

    single = np.flatnonzero(count == 1)
    if len(single):
        j = np.argmax(has[single], axis=1)
        w, t = weights[single, j], arrivals[single, j]
        one = _single_element(shape, dt_s, cfd_delay_s, cfd_fraction, raw_peak)
        peak[single], t_half[single], slope[single] = w * one[0], t + one[1], one[2]
        level[single] = one[4:7]
        if raw_peak:
            peak_raw[single] = w * one[3]

    two = np.flatnonzero(count == 2)
    if len(two):
        table = _pair_table(shape, dt_s, cfd_delay_s, cfd_fraction, raw_peak)
        t1, t2, w1, w2 = _pair_elements(arrivals[two], weights[two], has[two])
        close = t2 - t1 <= table.max_separation_s
        sel = two[close]
        w = w1[close] + w2[close]
        out = table.features(t2[close] - t1[close], w1[close] / w)
        peak[sel], t_half[sel], slope[sel] = w * out[0], t1[close] + out[1], out[2]
        level[sel] = np.stack(out[4:7], axis=1)
        if raw_peak:
            peak_raw[sel] = w * out[3]
        count = count.copy()
        count[sel] = 0  # done

    multi = np.flatnonzero(count > 1)
    if len(multi):
        order = np.argsort(~has[multi], axis=1, kind="stable")  # contributions first
        arr = np.take_along_axis(arrivals[multi], order, axis=1)
        wts = np.take_along_axis(weights[multi], order, axis=1)
        width = _bucket_counts(count[multi])
        threaded = int(np.sum(width)) * 64 > _THREAD_MIN_ELEMENTS  # ~64 samples per window
        jobs = []
        pending = np.zeros(0, np.int64)
        for k in np.unique(width):  # element counts up to a power of two, small groups padded
            pending = np.concatenate([pending, np.flatnonzero(width == k)])
            if len(pending) >= 256 or k == width.max():
                a, w, p = arr[pending, :k], wts[pending, :k], multi[pending]
                jobs += _jobs(shape, a, w, p, dt_s, cfd_delay_s, max_elements, threaded)
                pending = pending[:0]

        def work(job):
            pixels, args = job
            return pixels, _features_chunk(shape, *args, cfd_fraction, raw_peak)

        # numpy releases the GIL in these array passes: two threads use both cores, when the work
        # is large enough to repay starting them
        if threaded:
            outputs = parallel.map_threads(work, jobs)
        else:
            outputs = [work(job) for job in jobs]
        for sel, out in outputs:
            peak[sel], t_half[sel], slope[sel] = out[0], out[1], out[2]
            level[sel] = np.stack(out[4:7], axis=1)
            if raw_peak:
                peak_raw[sel] = out[3]
    return EchoFeatures(
        peak_w_per_j=peak,
        t_half_s=t_half,
        cfd_slope_per_s=slope,
        peak_raw_w_per_j=peak_raw,
        cfd_shot_level=level,
    )


def _jobs(
    shape, arrivals, weights, pixel, dt_s, cfd_delay_s, max_elements, threaded=False
) -> list[tuple]:
    """Chunks (pixel, the arguments of _features_chunk up to t_begin) of pixels with k elements
    each (contributing or of weight 0), grouped by window length (at least one chunk per thread
    if ``threaded``)."""
    k = arrivals.shape[1]
    has = weights > 0
    t_first = np.where(has, arrivals, np.inf).min(axis=1)
    t_last = np.where(has, arrivals, -np.inf).max(axis=1)
    arrivals = np.where(has, arrivals, t_first[:, None])  # keep lookups in range
    # Each window starts where the pulse is below 0.4 / k of its peak: y there is at most
    # 0.4/k sum(w) p_max, below half of max(y) >= max_k(w_k) p_max >= sum(w)/k p_max. Capped at
    # 10 % and two samples early, so that the CFD's delayed copy exists around its crossing.
    t_begin = shape.rising_time_s(min(0.4 / k, 0.1)) - 2 * dt_s
    span = shape.t_peak_s + cfd_delay_s - t_begin + 3 * dt_s
    n_samples = np.ceil((t_last - t_first + span) / dt_s).astype(np.int64) + 2
    # chunks of pixels sorted by window length, each sampled on its longest window (at most
    # 50 % longer than its shortest unless that leaves fewer than 512 pixels): few large array
    # passes (the per-pass overhead dominates small ones), little padding
    order = np.argsort(n_samples, kind="stable")
    n_samples = n_samples[order]
    cap = -(-len(order) // parallel.threads()) if threaded else len(order)
    jobs = []
    i = 0
    while i < len(order):
        j = int(np.searchsorted(n_samples, 1.5 * n_samples[i], side="right"))
        j = min(max(j, i + 512), i + cap, len(order))
        while j > i + 1 and (j - i) * int(n_samples[j - 1]) * k > max_elements:
            j = i + max(1, min(j - i - 1, max_elements // (int(n_samples[j - 1]) * k)))
        sel = order[i:j]
        length = int(n_samples[j - 1])
        jobs.append(
            (
                pixel[sel],
                (arrivals[sel], weights[sel], t_first[sel], length, dt_s, cfd_delay_s, t_begin),
            )
        )
        i = j
    return jobs


_SINGLE: dict[tuple, tuple] = {}
_PAIRS: dict[tuple, PairTable] = {}


def _pair_elements(arrivals, weights, has):
    """The two contributing elements of each row, earlier first: t1, t2, w1, w2 (each (n,))."""
    k = arrivals.shape[1]
    i = np.argmax(has, axis=1)
    j = k - 1 - np.argmax(has[:, ::-1], axis=1)
    rows = np.arange(len(arrivals))
    ta, tb, wa, wb = arrivals[rows, i], arrivals[rows, j], weights[rows, i], weights[rows, j]
    swap = tb < ta
    return (
        np.where(swap, tb, ta),
        np.where(swap, ta, tb),
        np.where(swap, wb, wa),
        np.where(swap, wa, wb),
    )


@dataclass(frozen=True)
class PairTable:
    """Features of the two-element echo (weights q, 1 - q at delays 0 and d) on a grid of
    separations d in [0, max_separation_s] and shares q in [0, 1], bilinearly interpolated. A
    two-element echo of total weight W at t1, t2 has peak W P(d, q), half-maximum t1 + T(d, q) and
    CFD slope S(d, q) and shot levels L (the normalised CFD signal does not scale with W)."""

    max_separation_s: float
    grid: tuple  # (P, T, S, R, L_d, L_p, L_m) arrays (n_d, n_q); R (raw peak) or None

    def features(self, d, q) -> tuple:
        n_d, n_q = self.grid[0].shape
        x = np.clip(d / self.max_separation_s, 0.0, 1.0) * (n_d - 1)
        y = np.clip(q, 0.0, 1.0) * (n_q - 1)
        i = np.minimum(x.astype(np.int64), n_d - 2)
        j = np.minimum(y.astype(np.int64), n_q - 2)
        fx, fy = x - i, y - j

        def at(m):
            return (m[i, j] * (1 - fx) + m[i + 1, j] * fx) * (1 - fy) + (
                m[i, j + 1] * (1 - fx) + m[i + 1, j + 1] * fx
            ) * fy

        return tuple(at(m) if m is not None else None for m in self.grid)


# the pair table's reach and resolution: separations up to half the 10-90 % rise time (merged
# sub-ray echoes are at most a quarter apart), 65 x 65 nodes (interpolation error ~7 um in range,
# 1e-5 in peak: measured against the sampled features)
PAIR_REACH = 0.5
PAIR_NODES = 65


def _pair_table(
    shape: PulseShape, dt_s: float, cfd_delay_s: float, cfd_fraction: float, raw: bool
) -> PairTable:
    """The pulse's two-element features, computed like any echo's once and kept."""
    key = (shape.tau_s, shape.a, shape.sigma_h_s, dt_s, cfd_delay_s, cfd_fraction, raw)
    if key not in _PAIRS:
        if len(_PAIRS) > 64:
            _PAIRS.clear()
        reach = PAIR_REACH * shape.rise_time_10_90_s
        d, q = np.meshgrid(
            np.linspace(0.0, reach, PAIR_NODES), np.linspace(0.0, 1.0, PAIR_NODES), indexing="ij"
        )
        arrivals = np.stack([np.zeros(d.size), d.ravel()], axis=1)
        weights = np.stack([q.ravel(), 1.0 - q.ravel()], axis=1)
        jobs = _jobs(shape, arrivals, weights, np.arange(d.size), dt_s, cfd_delay_s, 1 << 22)
        grid = [np.zeros(d.size) for _ in range(7)]
        for pixels, args in jobs:
            for g, v in zip(grid, _features_chunk(shape, *args, cfd_fraction, raw), strict=True):
                if v is not None:
                    g[pixels] = v
        grid = [g.reshape(d.shape) for g in grid]
        _PAIRS[key] = PairTable(reach, (*grid[:3], grid[3] if raw else None, *grid[4:]))
    return _PAIRS[key]


def _single_element(
    shape: PulseShape, dt_s: float, cfd_delay_s: float, cfd_fraction: float, raw: bool
) -> tuple:
    """Features (peak, t_half, slope, raw peak, 3 CFD shot levels) of the reference pulse
    arriving at t = 0 with unit weight, computed like any echo's and kept: a one-element echo is
    this pulse shifted and scaled (its half-maximum and CFD crossings move with the arrival; the
    slope of the normalised CFD signal and its shot levels do not change)."""
    key = (shape.tau_s, shape.a, shape.sigma_h_s, dt_s, cfd_delay_s, cfd_fraction, raw)
    if key not in _SINGLE:
        if len(_SINGLE) > 64:
            _SINGLE.clear()
        ((_, args),) = _jobs(
            shape, np.zeros((1, 1)), np.ones((1, 1)), np.zeros(1), dt_s, cfd_delay_s, 1 << 20
        )
        out = _features_chunk(shape, *args, cfd_fraction, raw)
        _SINGLE[key] = tuple(float(v[0]) if v is not None else None for v in out)
    return _SINGLE[key]


def _bucket_counts(count: np.ndarray) -> np.ndarray:
    """Element counts rounded up to a power of two (pixels then share a few array shapes)."""
    return 2 ** np.ceil(np.log2(np.maximum(count, 1))).astype(np.int64)


# below this (pixels x samples x elements), a thread pool costs more than it saves: the many
# small array passes then contend for the GIL (measured: 3200 pixels of ~3 elements ran in 13 ms
# on one thread, 23 ms on two)
_THREAD_MIN_ELEMENTS = 1 << 21
