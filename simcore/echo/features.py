"""Echo features: peak, half-maximum time and CFD slope of each pixel's band-limited echo
(Eqs. 19, 25, 31), per joule of pulse energy, from exact delays (never snapped to the time grid)."""

from __future__ import annotations

import os
import threading
import warnings
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from .. import parallel
from ..pulse import PulseShape

NO_KERNEL_ENV = "LMAPD_NO_NUMBA"
_KERNEL: list[ModuleType | None] = []  # the kernel module once loaded (None: unavailable)
_NO_KERNEL = [""]  # why not
_PRELOAD: list[threading.Thread] = []


def preload(shape: PulseShape) -> None:
    """Load the compiled kernel on a background thread (a frame's first stages run meanwhile;
    the echo stage then waits for it): the import of numba and the functions read from the
    on-disk cache take 0.2-0.5 s. Nothing where the kernel is not to be used or already loaded."""
    if _KERNEL or _PRELOAD or os.environ.get(NO_KERNEL_ENV, "0").strip() not in ("", "0"):
        return

    def load():
        try:
            from . import kernel  # noqa: PLC0415

            kernel.warm(shape)
        except Exception:  # compiled_kernel() says why, on use
            pass

    _PRELOAD.append(threading.Thread(target=load, name="simcore-kernel", daemon=True))
    _PRELOAD[0].start()


def compiled_kernel() -> ModuleType | None:
    """The compiled echo kernel (:mod:`simcore.echo.kernel`, loaded on first use), or None where
    ``$LMAPD_NO_NUMBA`` is set (not 0) or numba cannot be imported: the echoes then take the
    numpy path, with a one-line warning the first time."""
    if not _KERNEL:
        if _PRELOAD:
            _PRELOAD[0].join()
        reason = ""
        if os.environ.get(NO_KERNEL_ENV, "0").strip() not in ("", "0"):
            reason = f"${NO_KERNEL_ENV} is set"
        else:
            try:
                from . import kernel  # noqa: PLC0415  (numba: 0.2 s to import)
            except Exception as exc:  # any failure to load: the numpy path
                reason = f"numba unavailable ({type(exc).__name__}: {exc})"
        if reason:
            _NO_KERNEL[0] = reason
            warnings.warn(f"echo features on the numpy path: {reason}", stacklevel=3)
        _KERNEL.append(None if reason else kernel)
    return _KERNEL[0]


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


# Illinois steps (regula falsi that halves the stale end's value) refining the half-maximum and
# CFD crossings within their one-sample brackets: plain regula falsi keeps one end fixed where the
# echo bends, and stalled up to 1.5 mm from the crossing on multi-surface pixels after 4 steps
HALF_STEPS = 8
CFD_STEPS = 6
# Fewer pixels than this take the compiled kernel on one thread: a 2-thread parallel region must
# wake a second thread, and on a busy machine that thread waits for a core, 3-6 ms whatever the
# work (measured: 64 x 64 frames' features 1.0 ms on one thread against 7.0 ms on two, load ~2.6
# on 2 cores); from about 2000 pixels (~3 ms of work) two threads win. Results do not depend on it.
SERIAL_BELOW_PIXELS = 2048


def _illinois(f, ta, tb, fa, fb, steps: int):
    """Root of f in [ta, tb] (fa = f(ta) < 0 <= fb = f(tb), arrays), after ``steps`` Illinois
    steps; the final secant point."""
    side = np.zeros(np.shape(ta), dtype=np.int8)  # the end moved last: -1 a, +1 b
    for _ in range(steps):
        tm = np.clip(ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0), ta, tb)
        fm = f(tm)
        left = fm < 0
        fb = np.where(left & (side == -1), 0.5 * fb, fb)
        fa = np.where(~left & (side == 1), 0.5 * fa, fa)
        ta, fa = np.where(left, tm, ta), np.where(left, fm, fa)
        tb, fb = np.where(left, tb, tm), np.where(left, fb, fm)
        side = np.where(left, -1, 1).astype(np.int8)
    return ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0)


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

    # half-maximum crossing: bracket on the grid, then Illinois steps on exact values
    half = 0.5 * peak
    jh = np.argmax(y >= half[:, None], axis=1)
    jh = np.maximum(jh, 1)
    ta, tb = grid[rows, jh - 1], grid[rows, jh]
    fa, fb = y[rows, jh - 1] - half, y[rows, jh] - half
    exact = lambda t: _eval_exact(shape, shape.filtered, arrivals, weights, t)  # noqa: E731
    t_half = _illinois(lambda t: exact(t) - half, ta, tb, fa, fb, HALF_STEPS)

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
    cfd = lambda t: (exact(t - cfd_delay_s) - cfd_fraction * exact(t)) / norm  # noqa: E731
    # the crossing: bracketed on the grid, then Illinois steps on the exact CFD signal
    sa, sb = s[rows, last - 1], s[rows, last]
    ta, tb = grid[rows, last - 1], grid[rows, last]
    t_star = _illinois(cfd, ta, tb, sa, sb, CFD_STEPS)
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
    backend: str | None = None,
) -> EchoFeatures:
    """Peak, half-maximum time and CFD slope of each pixel's band-limited echo.

    Each pixel is sampled at ``dt_s`` on its own window, from just before its first arrival to
    past its last arrival's peak plus the CFD delay (its depth plus the pulse), never the whole
    gate; then each mark is refined on exact values (docs/physics.md#echo).

    arrivals_s, weights : (n, K) -- two-way delays [s] and Eq. 30 weights (0 = no contribution)
    backend : "kernel" (the compiled kernel, :mod:`simcore.echo.kernel`), "numpy" (the reference
        it is tested against: array passes over groups of pixels) or None: the kernel where numba
        is available (see :func:`compiled_kernel`), else numpy.
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if backend not in (None, "kernel", "numpy"):
        raise ValueError(f"backend must be 'kernel', 'numpy' or None, got {backend!r}")
    if arrivals.shape != weights.shape or arrivals.ndim != 2:
        raise ValueError(f"arrivals_s {arrivals.shape} and weights {weights.shape}: (n, K) each")
    if not np.isfinite(weights).all() or (weights < 0).any():
        raise ValueError("weights must be finite and >= 0")
    if not np.isfinite(arrivals[weights > 0]).all():
        raise ValueError("arrivals_s must be finite where the weight is > 0")
    kernel = compiled_kernel() if backend != "numpy" else None
    if backend == "kernel" and kernel is None:
        raise RuntimeError(f"the compiled echo kernel is unavailable: {_NO_KERNEL[0]}")
    begin = window_begins_s(shape, arrivals.shape[1], dt_s)
    if kernel is not None:
        kernel.set_threads(parallel.threads_for(len(arrivals), SERIAL_BELOW_PIXELS))
        out = kernel.echo_features(
            shape, arrivals, weights, dt_s, cfd_delay_s, cfd_fraction, raw_peak, begin,
            (HALF_STEPS, CFD_STEPS),
        )  # fmt: skip
    else:
        out = features_numpy(
            shape, arrivals, weights, dt_s, cfd_delay_s, cfd_fraction, raw_peak, begin
        )
    return EchoFeatures(
        peak_w_per_j=out[:, 0],
        t_half_s=out[:, 1],
        cfd_slope_per_s=out[:, 2],
        peak_raw_w_per_j=out[:, 3] if raw_peak else None,
        cfd_shot_level=out[:, 4:7],
    )


def sample_echoes(shape: PulseShape, table: np.ndarray, arrivals_s, weights, t0_s, dt_s, n_samples):
    """Each pixel's echo sum_k w_k p(t - t_k) at t = t0_s + j dt_s, j < n_samples, p the pulse
    table ``table`` (``shape.filtered``, ``shape.raw`` or ``shape.shot``), by the compiled
    kernel where it is available.

    arrivals_s, weights : (n, K); t0_s : (n,) [s]. Returns (n, n_samples) float64.
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    t0 = np.broadcast_to(np.asarray(t0_s, dtype=np.float64), (len(arrivals),))
    out = np.zeros((len(arrivals), int(n_samples)))
    kernel = compiled_kernel()
    if kernel is not None:
        kernel.set_threads(parallel.threads())
        rows = np.arange(len(arrivals))
        zero = np.zeros(len(arrivals), dtype=np.int64)
        slope = shape.slope_of(table)
        kernel.sample_echoes(
            out, rows, zero, t0, zero, zero + int(n_samples), dt_s, arrivals, weights, table,
            slope, shape,
        )  # fmt: skip
        return out
    step = max(1, (1 << 22) // max(int(n_samples) * arrivals.shape[1], 1))
    offsets = dt_s * np.arange(int(n_samples))
    for c in range(0, len(arrivals), step):
        sl = slice(c, c + step)
        tau = (t0[sl, None] + offsets[None, :])[:, :, None] - arrivals[sl, None, :]
        out[sl] = np.einsum("nlk,nk->nl", shape.lookup(table, tau), weights[sl])
    return out


_BEGINS: dict[tuple[int, int, float], tuple[PulseShape, np.ndarray]] = {}


def window_begins_s(shape: PulseShape, k_max: int, dt_s: float) -> np.ndarray:
    """(k_max + 1,) :func:`window_begin_s` by element count, each count rounded up to a power of
    two as the numpy path grouped pixels before the kernel (so the samples fall where they fell).
    Kept per pulse, count and step: each mark reads the whole pulse table, and a frame's five took
    0.3 ms on the calling thread alone (while the other threads waited)."""
    key = (id(shape), int(k_max), float(dt_s))
    hit = _BEGINS.get(key)
    if hit is not None and hit[0] is shape:
        return hit[1].copy()  # (writable, as the compiled kernel's signature has it)
    buckets = 2 ** np.ceil(np.log2(np.maximum(np.arange(k_max + 1), 1))).astype(np.int64)
    begin = np.array([window_begin_s(shape, int(k), dt_s) for k in buckets])
    if len(_BEGINS) >= 64:  # a few pulses and element counts in use at a time
        _BEGINS.clear()
    _BEGINS[key] = (shape, begin)
    return begin.copy()


def window_begin_s(shape: PulseShape, n_elements: int, dt_s: float) -> float:
    """Start of the sampled window of an echo of ``n_elements`` elements, from its first arrival
    [s]: where the pulse is below 0.4 / K of its peak, y there is at most 0.4/K sum(w) p_max,
    below half of max(y) >= max_k(w_k) p_max >= sum(w)/K p_max. Capped at 10 % and two samples
    early, so that the CFD's delayed copy exists around its crossing."""
    return shape.rising_time_s(min(0.4 / n_elements, 0.1)) - 2 * dt_s


def features_numpy(
    shape, arrivals, weights, dt_s, cfd_delay_s, cfd_fraction, raw_peak, begin, max_elements=1 << 20
) -> np.ndarray:
    """The numpy path: (n, 7) features as :func:`simcore.echo.kernel.echo_features` gives them.

    Pixels are grouped by their count of contributing elements (moved to the front), then in
    chunks of at most ``max_elements`` (pixels x samples x elements) by window length, each
    chunk sampled on its longest window."""
    n = len(arrivals)
    out = np.zeros((n, 7))
    has = weights > 0
    count = has.sum(axis=1)
    order = np.argsort(~has, axis=1, kind="stable")  # contributions first
    arr = np.take_along_axis(arrivals, order, axis=1)
    wts = np.take_along_axis(weights, order, axis=1)
    for k in np.unique(count[count > 0]):
        rows = np.flatnonzero(count == k)
        for pixels, args in _jobs(shape, arr[rows, :k], wts[rows, :k], rows, dt_s, cfd_delay_s,
                                  begin[k], max_elements):  # fmt: skip
            chunk = _features_chunk(shape, *args, cfd_fraction, raw_peak)  # type: ignore[call-arg]
            for i, v in enumerate(chunk):
                if v is not None:
                    out[pixels, i] = v
    return out


def _jobs(shape, arrivals, weights, pixel, dt_s, cfd_delay_s, t_begin, max_elements) -> list:
    """Chunks (pixel, the arguments of _features_chunk up to t_begin) of pixels with k
    contributing elements each, grouped by window length."""
    k = arrivals.shape[1]
    t_first = arrivals.min(axis=1)
    t_last = arrivals.max(axis=1)
    span = shape.t_peak_s + cfd_delay_s - t_begin + 3 * dt_s
    n_samples = np.ceil((t_last - t_first + span) / dt_s).astype(np.int64) + 2
    # chunks of pixels sorted by window length, each sampled on its longest window (at most
    # 50 % longer than its shortest unless that leaves fewer than 512 pixels): few large array
    # passes (the per-pass overhead dominates small ones), little padding
    order = np.argsort(n_samples, kind="stable")
    n_samples = n_samples[order]
    jobs = []
    i = 0
    while i < len(order):
        j = int(np.searchsorted(n_samples, 1.5 * n_samples[i], side="right"))
        j = min(max(j, i + 512), len(order))
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
