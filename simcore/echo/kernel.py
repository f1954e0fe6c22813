"""The compiled echo kernel (numba): each pixel's band-limited echo y(t) = sum_k w_k p_B(t - t_k)
sampled on its own window and its features refined on exact values, in parallel over pixels
without the GIL (docs/physics.md#echo-kernel).

The pulse is evaluated exactly as :meth:`simcore.pulse.PulseShape.lookup` does (linear
interpolation of its fine table, the same operations in the same order), so delays are never
snapped to the time grid, and each pixel follows the steps of the numpy reference
(:func:`simcore.echo.features.features_numpy`) on the same samples: the two agree to rounding.

The compiled functions are cached on disk (numba's ``cache=True``): in ``$NUMBA_CACHE_DIR`` when
it is set, else in the project's cache folder (``simcore.cache.cache_dir()``, under ``numba/``),
else next to this file or in numba's user-wide folder, whichever is writable; where none is, they
are compiled in each process. The first call in a process loads them (or compiles them once, a few
seconds); importing this module compiles nothing.

Every input has been checked before it gets here: the kernel never sees NaN or inf (the scene's
keys are validated, misses carry weight 0).
"""

from __future__ import annotations

import math
import os
import threading
import warnings

import numba
import numpy as np
from numba import prange

from ..cache import cache_dir

__all__ = [
    "echo_features",
    "jit",
    "lock",
    "nearest_column",
    "nearest_surface_m",
    "sample_echoes",
    "set_threads",
]

# OpenMP (numba's threading layer where TBB is absent) keeps the threads of a finished parallel
# region spinning for a while by default; on a machine with more runnable threads than cores they
# take the cores from the next region and from the frame's other threads (measured, 2 cores at
# load 5-7: the cloud stage's ground truth at 256 x 256 x 4 12 ms passive against 40 ms spinning,
# the detection's stops 17-20 against 36-45 ms). Threads that sleep at once cost a wake-up of tens
# of microseconds. Read when OpenMP loads, at the first parallel region; a user's setting stays.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

if not numba.config.CACHE_DIR:  # $NUMBA_CACHE_DIR unset: the project's own cache folder
    _folder = cache_dir()
    if _folder is not None:
        numba.config.CACHE_DIR = str(_folder / "numba")


def jit(parallel: bool = False, **options):
    """numba.njit (nogil, numpy's error model, ``options`` passed on) with the on-disk cache, or
    without it where no cache folder is writable."""

    def wrap(fn):
        kw = {"nogil": True, "parallel": parallel, "error_model": "numpy", **options}
        try:
            return numba.njit(cache=True, **kw)(fn)
        except RuntimeError as exc:  # "cannot cache function ...: no locator available"
            warnings.warn(f"compiled kernel not cached on disk ({exc})", stacklevel=2)
            return numba.njit(**kw)(fn)

    return wrap


# The workqueue threading layer (numba's own, used where neither OpenMP nor TBB is installed) must
# not run two parallel regions at once: callers from several threads take this lock first.
lock = threading.Lock()


def set_threads(n: int) -> None:
    """Threads of the calling thread's parallel regions (numba.set_num_threads, thread-local)."""
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


@jit()
def _at(table, slope, t0_s, inv_step, t_s):
    """The pulse table at time t_s, linearly interpolated (PulseShape.lookup, scalar)."""
    x = (t_s - t0_s) * inv_step
    x = min(max(x, 0.0), len(table) - 2.0)
    i = np.int32(x)
    return (x - i) * slope[i] + table[i]


@jit()
def _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, t_s):
    """y(t_s) = sum_k w_k p(t_s - t_k) over the first n_el elements."""
    y = 0.0
    for k in range(n_el):
        y += weights[k] * _at(table, slope, t0_s, inv_step, t_s - arrivals[k])
    return y


@jit()
def _sample(y, g0_s, dt_s, arrivals, weights, n_el, table, slope, t0_s, inv_step):
    """y[j] = echo at g0_s + j dt_s, j = 0..len(y)-1."""
    for j in range(len(y)):
        y[j] = _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, g0_s + dt_s * j)


@jit()
def _parabola_offset(y0, y1, y2):
    """Vertex of the parabola through three equally spaced values, in steps (0 if not concave),
    clipped to one step."""
    den = y0 - 2.0 * y1 + y2
    off = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    return min(max(off, -1.0), 1.0)


@jit()
def _refined_peak(y, g0_s, dt_s, arrivals, weights, n_el, table, slope, t0_s, inv_step):
    """Peak of the sampled echo y: best sample, parabolic vertex, one more parabolic step on
    exact values a quarter sample either side, the exact value there."""
    n = len(y)
    j = 0
    for i in range(1, n):
        if y[i] > y[j]:
            j = i
    j = min(max(j, 1), n - 2)
    y1 = y[j]
    t_v = (g0_s + dt_s * j) + _parabola_offset(y[j - 1], y1, y[j + 1]) * dt_s
    h = dt_s / 4
    e0 = _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, t_v - h)
    e1 = _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, t_v)
    e2 = _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, t_v + h)
    t_v = t_v + _parabola_offset(e0, e1, e2) * h
    top = _echo_at(arrivals, weights, n_el, table, slope, t0_s, inv_step, t_v)
    return max(top, max(e1, y1))


@jit()
def _secant(ta, tb, fa, fb):
    """The secant (regula falsi) point of a bracket."""
    return ta - fa * (tb - ta) / (fb - fa if fb != fa else 1.0)


@jit()
def _illinois_step(ta, tb, fa, fb, side, tm, fm):
    """One Illinois step (features._illinois): the bracket after f(tm) = fm."""
    if fm < 0:
        if side == -1:
            fb = 0.5 * fb
        return tm, tb, fm, fb, -1
    if side == 1:
        fa = 0.5 * fa
    return ta, tm, fa, fm, 1


@jit()
def _pixel(
    a, w, n_el, tables, t0_s, inv_step, dt_s, cfd_delay_s, cfd_fraction, t_begin_s, span_s, steps
):
    """Features of one pixel's echo: peak, t_half, |slope|, raw peak, 3 shot levels."""
    filt, filt_slope, raw, raw_slope, shot, shot_slope = tables
    t_first, t_last = a[0], a[0]
    for k in range(1, n_el):
        t_first = min(t_first, a[k])
        t_last = max(t_last, a[k])
    n = np.int64(math.ceil((t_last - t_first + span_s) / dt_s)) + 2
    g0 = t_first + t_begin_s
    y = np.empty(n)
    _sample(y, g0, dt_s, a, w, n_el, filt, filt_slope, t0_s, inv_step)
    peak = _refined_peak(y, g0, dt_s, a, w, n_el, filt, filt_slope, t0_s, inv_step)

    # half-maximum crossing: bracket on the grid, then regula falsi on exact values
    half = 0.5 * peak
    jh = 0
    while jh < n and not y[jh] >= half:
        jh += 1
    jh = 1 if jh == n else max(jh, 1)
    ta, tb = g0 + dt_s * (jh - 1), g0 + dt_s * jh
    fa, fb = y[jh - 1] - half, y[jh] - half
    side = 0  # Illinois steps: the end moved last, -1 a, +1 b
    for _ in range(steps[0]):
        tm = min(max(_secant(ta, tb, fa, fb), ta), tb)
        fm = _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, tm) - half
        ta, tb, fa, fb, side = _illinois_step(ta, tb, fa, fb, side, tm, fm)
    t_half = _secant(ta, tb, fa, fb)

    # the CFD signal on the grid, s = (y(t - t_d) - k y(t)) / peak, y(t - t_d) by a fractional
    # shift of the samples; its last upward zero crossing in the firing window of Eq. 19
    norm = peak if peak > 0 else 1.0
    shift = cfd_delay_s / dt_s
    ns = np.int64(math.floor(shift))
    frac = shift - math.floor(shift)
    jpk = n - 1  # first local maximum of y from the half-max sample on
    for j in range(max(jh, 1), n - 1):
        if y[j] >= y[j - 1] and y[j] > y[j + 1]:
            jpk = j
            break
    lo, hi = t_half - cfd_delay_s, (g0 + dt_s * jpk) + cfd_delay_s + dt_s
    last = -1
    s_prev = 0.0
    for j in range(n):
        yd = 0.0
        if j >= ns:
            yd += (1.0 - frac) * y[j - ns]
        if j >= ns + 1:
            yd += frac * y[j - ns - 1]
        s = (yd - cfd_fraction * y[j]) / norm
        if j >= 1 and s_prev < 0 and s >= 0:
            t = g0 + dt_s * j
            if t >= lo and t <= hi:
                last = j
                sa, sb = s_prev, s
        s_prev = s
    h = 1e-3 * dt_s  # exact derivatives by central differences
    if last >= 1:
        ta, tb = g0 + dt_s * (last - 1), g0 + dt_s * last
        side = 0
        for _ in range(steps[1]):
            tm = min(max(_secant(ta, tb, sa, sb), ta), tb)
            sm = (
                _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, tm - cfd_delay_s)
                - cfd_fraction * _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, tm)
            ) / norm
            ta, tb, sa, sb, side = _illinois_step(ta, tb, sa, sb, side, tm, sm)
        t_fire = _secant(ta, tb, sa, sb)
        c = np.empty(2)
        for i, t in enumerate((t_fire + h, t_fire - h)):
            c[i] = (
                _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, t - cfd_delay_s)
                - cfd_fraction * _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, t)
            ) / norm
        slope_out = abs((c[0] - c[1]) / (2 * h))
    else:
        up = _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, t_half + h)
        down = _echo_at(a, w, n_el, filt, filt_slope, t0_s, inv_step, t_half - h)
        slope_out = abs((up - down) / (2 * h) / norm)
        t_fire = t_half + cfd_delay_s
    level0 = _echo_at(a, w, n_el, shot, shot_slope, t0_s, inv_step, t_fire - cfd_delay_s) / norm
    level1 = _echo_at(a, w, n_el, shot, shot_slope, t0_s, inv_step, t_fire) / norm
    level2 = (
        _echo_at(a, w, n_el, shot, shot_slope, t0_s, inv_step, t_fire - 0.5 * cfd_delay_s) / norm
    )
    peak_raw = 0.0
    if len(raw) > 0:  # the unfiltered echo's peak (Eq. 14's form), on the same grid
        _sample(y, g0, dt_s, a, w, n_el, raw, raw_slope, t0_s, inv_step)
        peak_raw = _refined_peak(y, g0, dt_s, a, w, n_el, raw, raw_slope, t0_s, inv_step)
    return peak, t_half, slope_out, peak_raw, level0, level1, level2


@jit(parallel=True)
def _features(
    arrivals, weights, tables, t0_s, inv_step, dt_s, cfd_delay_s, cfd_fraction, t_begin_s, span_s,
    steps, out,
):  # fmt: skip
    """Every pixel's features into out (n, 7); t_begin_s, span_s (K + 1,) by element count;
    steps: the Illinois steps of the half-maximum and CFD crossings."""
    n, k_max = arrivals.shape
    for p in prange(n):
        a = np.empty(k_max)
        w = np.empty(k_max)
        n_el = 0
        for k in range(k_max):  # the contributing elements, in their order
            if weights[p, k] > 0:
                a[n_el] = arrivals[p, k]
                w[n_el] = weights[p, k]
                n_el += 1
        if n_el == 0:
            for i in range(7):
                out[p, i] = 0.0
            continue
        f = _pixel(
            a, w, n_el, tables, t0_s, inv_step, dt_s, cfd_delay_s, cfd_fraction,
            t_begin_s[n_el], span_s[n_el], steps,
        )  # fmt: skip
        for i in range(7):
            out[p, i] = f[i]


_NONE = np.zeros(0)
_NONE.setflags(write=False)  # read-only as the pulse's tables: one compiled variant for both


def warm(shape) -> None:
    """Load (or compile) the functions a frame calls, on a one-pixel echo of ``shape``."""
    one = np.full((1, 1), 1e-6), np.ones((1, 1))
    echo_features(shape, *one, 4e-10, 2e-9, 0.5, False, np.full(2, -1e-8), (1, 1))


def echo_features(
    shape, arrivals_s, weights, dt_s, cfd_delay_s, cfd_fraction, raw_peak, begin, steps
):
    """(n, 7) features of every pixel (peak, t_half, |slope|, raw peak, 3 shot levels).

    shape : simcore.pulse.PulseShape; arrivals_s, weights : (n, K) float64 (weight 0: none);
    begin : (K + 1,) window start before the first arrival by element count [s];
    steps : (half-maximum, CFD) Illinois steps (simcore.echo.features.HALF_STEPS, CFD_STEPS)."""
    raw = (shape.raw, shape.raw_slope) if raw_peak else (_NONE, _NONE)
    tables = (shape.filtered, shape.filtered_slope, *raw, shape.shot, shape.shot_slope)
    span = shape.t_peak_s + cfd_delay_s - begin + 3 * dt_s
    out = np.empty((len(arrivals_s), 7))
    with lock:
        _features(
            np.ascontiguousarray(arrivals_s, dtype=np.float64),
            np.ascontiguousarray(weights, dtype=np.float64),
            tables, shape.t0_s, 1.0 / shape.step_s, float(dt_s), float(cfd_delay_s),
            float(cfd_fraction), begin, span, (int(steps[0]), int(steps[1])), out,
        )  # fmt: skip
    return out


@jit()
def _sample_row(out, row, col0, t_base_s, j0, j1, dt_s, a, w, table, slope, t0_s, inv_step, scale):
    """out[row, col0 + (j - j0)] += scale * y(t_base_s + j dt_s) for j0 <= j < j1: y summed in
    float64 over the elements of weight > 0, scaled, rounded to out's precision, added."""
    el_a = np.empty(len(a))
    el_w = np.empty(len(a))
    n_el = 0
    for k in range(len(a)):
        if w[k] > 0:
            el_a[n_el] = a[k]
            el_w[n_el] = w[k]
            n_el += 1
    cast = np.empty(1, out.dtype)
    for j in range(j0, j1):
        cast[0] = scale * _echo_at(
            el_a, el_w, n_el, table, slope, t0_s, inv_step, t_base_s + j * dt_s
        )
        out[row, col0 + j - j0] += cast[0]


@jit(parallel=True)
def _sample_rows(out, rows, col0, t_base_s, j0, j1, dt_s, a, w, table, slope, t0_s, inv, scale):
    for i in prange(len(rows)):
        _sample_row(
            out, rows[i], col0[i], t_base_s[i], j0[i], j1[i], dt_s, a[i], w[i], table, slope,
            t0_s, inv, scale,
        )  # fmt: skip


@jit()
def _sample_rows_serial(
    out, rows, col0, t_base_s, j0, j1, dt_s, a, w, table, slope, t0_s, inv, scale
):
    for i in range(len(rows)):
        _sample_row(
            out, rows[i], col0[i], t_base_s[i], j0[i], j1[i], dt_s, a[i], w[i], table, slope,
            t0_s, inv, scale,
        )  # fmt: skip


def sample_echoes(
    out, rows, col0, t_base_s, j0, j1, dt_s, arrivals_s, weights, table, slope, shape, scale=1.0,
    parallel=True,
):  # fmt: skip
    """Add ``scale`` times each pixel's echo, sampled on its own span, to rows of ``out``.

    out : (m, L) float32 or float64, added to in place
    rows, col0, j0, j1 : (n,) int64 -- pixel i adds to out[rows[i], col0[i] + (j - j0[i])] the echo
        at t_base_s[i] + j dt_s for j0[i] <= j < j1[i] (the columns must lie in out)
    t_base_s : (n,) float64 [s]; arrivals_s, weights : (n, K) float64 (weight 0: no element)
    table, slope : one of the pulse's tables (``shape.filtered``, ``shape.raw``) and its slopes
    parallel : False from a caller's own worker threads (a serial loop, the GIL released)
    """
    i64 = lambda v: np.ascontiguousarray(v, dtype=np.int64)  # noqa: E731
    args = (
        out, i64(rows), i64(col0), np.ascontiguousarray(t_base_s, dtype=np.float64), i64(j0),
        i64(j1), float(dt_s), np.ascontiguousarray(arrivals_s, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64), table, slope, shape.t0_s,
        1.0 / shape.step_s, float(scale),
    )  # fmt: skip
    if parallel:
        with lock:
            _sample_rows(*args)
    else:
        _sample_rows_serial(*args)


@jit(parallel=True)
def _nearest_surface(arrivals, weights, rows, range_m, gap_s, half_c, out):
    """out[i]: the range (half_c x delay) of the surface of pixel rows[i] nearest range_m[i];
    a pixel's surfaces are its lit elements sorted by delay (stable), a new one after each gap
    over gap_s, each at its energy-weighted delay (pointcloud.pixel_surfaces); NaN if none."""
    k_max = arrivals.shape[1]
    for i in prange(len(rows)):
        p = rows[i]
        a = np.empty(k_max)
        w = np.empty(k_max)
        n = 0
        for k in range(k_max):  # insertion sort of the lit elements: stable, as argsort's
            if weights[p, k] > 0:
                j = n
                while j > 0 and a[j - 1] > arrivals[p, k]:
                    a[j] = a[j - 1]
                    w[j] = w[j - 1]
                    j -= 1
                a[j] = arrivals[p, k]
                w[j] = weights[p, k]
                n += 1
        best = np.nan
        best_d = np.inf
        k = 0
        while k < n:  # each surface: a run of elements without a gap over gap_s
            weight = w[k]
            moment = w[k] * a[k]
            k += 1
            while k < n and not a[k] - a[k - 1] > gap_s:
                weight += w[k]
                moment += w[k] * a[k]
                k += 1
            surface = half_c * (moment / weight)
            d = abs(surface - range_m[i])
            if d < best_d or (best_d == np.inf and np.isnan(best)):
                best_d = d
                best = surface
        out[i] = best


def nearest_surface_m(arrivals_s, weights, rows, range_m, gap_s, half_c, threads):
    """(m,) the range [m] (``half_c`` x delay) of the surface of pixel ``rows[i]`` nearest
    ``range_m[i]``: :func:`simcore.pointcloud.pixel_surfaces`'s surfaces and the nearest of them,
    per point in parallel (the same sums in the same order: the same values).

    arrivals_s, weights : (n, K) float64 (weight 0: no light); rows : (m,) int64 rows of them;
    range_m : (m,) float64 [m]; gap_s : a new surface after a gap over this [s]."""
    out = np.empty(len(rows))
    set_threads(threads)
    with lock:
        _nearest_surface(
            np.ascontiguousarray(arrivals_s, dtype=np.float64),
            np.ascontiguousarray(weights, dtype=np.float64),
            np.ascontiguousarray(rows, dtype=np.int64),
            np.ascontiguousarray(range_m, dtype=np.float64), float(gap_s), float(half_c), out,
        )  # fmt: skip
    return out


@jit(parallel=True)
def _nearest_column(values, rows, target, out):
    n_cols = values.shape[1]
    for i in prange(len(rows)):
        p = rows[i]
        best = 0
        best_d = np.inf
        for k in range(n_cols):
            v = values[p, k]
            d = abs((v if np.isfinite(v) else np.inf) - target[i])
            if np.isnan(d):  # numpy's argmin: the first NaN
                best = k
                break
            if d < best_d:
                best_d = d
                best = k
        out[i] = best


def nearest_column(values, rows, target, threads) -> np.ndarray:
    """(m,) int64: ``argmin_k |values[rows[i], k] - target[i]|`` (non-finite values as inf;
    numpy's argmin: the first minimum, the first NaN if any), per row in parallel.

    values : (n, K) float; rows : (m,) int64; target : (m,) float64."""
    out = np.empty(len(rows), dtype=np.int64)
    set_threads(threads)
    with lock:
        _nearest_column(
            np.ascontiguousarray(values, dtype=np.float64),
            np.ascontiguousarray(rows, dtype=np.int64),
            np.ascontiguousarray(target, dtype=np.float64), out,
        )  # fmt: skip
    return out
