"""The waveform Monte Carlo's compiled noise kernel (numba; docs/physics.md#mc-noise-draw): the
white current drawn on every ``r``-th sample of the waveform grid, one random stream per pixel,
band-limited by a polyphase filter, the signal's shot noise added on the fine grid where the
signal is.

The white noise of the model is ``y(t) = sum_i x_i h_B(t - t_i) dt``. Drawn as impulses of
``sqrt(r)`` times the fine grid's standard deviation on every ``r``-th sample (zeros between),
``y`` keeps its covariance to within ``2 exp(-pi^2 sigma_h^2 / (r dt)^2)`` of the fine draw's
(Poisson summation; :func:`white_step`), and a pixel's white noise costs ``r`` times fewer
normal draws and filter taps. The signal's shot noise (where the sampled signal current is
positive) stays on the fine grid, as the model draws it.

Random numbers: each pixel has its own xoshiro256** stream, seeded by splitmix64 from a 64-bit
key (drawn once per flash from the caller's ``numpy.random.Generator``) and the pixel's index,
and turned into normal deviates by a 128-layer ziggurat (exact: rejection from the normal
density; the tail beyond r by Marsaglia's exponential method). A pixel's noise is therefore
the same whatever the chunking of the array and the threads that run it.

The functions are compiled on first use and cached on disk as the echo kernel's are
(:mod:`simcore.echo.kernel`); they release the GIL and run serially in the caller's thread (the
gate runs its chunks of pixels on the frame's threads).
"""

from __future__ import annotations

import math

import numpy as np

from ....echo.kernel import jit

__all__ = [
    "NONSTATIONARITY",
    "ZIGGURAT",
    "noise_rows",
    "normals",
    "phase_taps",
    "white_step",
]

NONSTATIONARITY = 1e-8  # the white step keeps y's covariance within this (relative)
_BLOCK = 1024  # filter outputs accumulated at a time (stay in the L1 cache)

# 128-layer ziggurat for exp(-x^2 / 2) (Marsaglia and Tsang, J. Stat. Softw. 5(8), 2000):
# the base strip's right edge R and the common area V of the layers
_LAYERS = 128
_R = 3.442619855899
_V = 9.91256303526217e-3


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray]:
    """Layer edges x_0 > x_1 = R > ... > x_128 = 0 (x_0 = V / f(R), the base strip's virtual
    width) and f(x_i) = exp(-x_i^2 / 2)."""
    x = np.zeros(_LAYERS + 1)
    f = np.zeros(_LAYERS + 1)
    x[1], f[1] = _R, math.exp(-0.5 * _R * _R)
    x[0], f[0] = _V / f[1], 0.0
    for i in range(1, _LAYERS - 1):
        f[i + 1] = f[i] + _V / x[i]
        x[i + 1] = math.sqrt(-2.0 * math.log(f[i + 1]))
    x[_LAYERS], f[_LAYERS] = 0.0, 1.0
    return x, f


ZIGGURAT = _ziggurat_tables()
_ZX, _ZF = ZIGGURAT
_ZX.setflags(write=False)
_ZF.setflags(write=False)


def white_step(dt_s: float, sigma_h_s: float) -> int:
    """r >= 1: the white noise drawn on every r-th sample, the largest r with
    ``2 exp(-pi^2 sigma_h^2 / (r dt)^2) <= NONSTATIONARITY`` (docs/physics.md#mc-noise-draw)."""
    widest = math.pi * sigma_h_s / math.sqrt(math.log(2.0 / NONSTATIONARITY))
    return max(1, int(math.floor(widest / dt_s * (1.0 + 1e-12))))


def phase_taps(taps: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The filter ``taps`` (2 m + 1, symmetric) split into its r phases: output j = r q + p sums
    ``P[p, t] z[q + e0[p] + t]`` for t < n[p], z the impulses on the samples r i of the padded
    input. Returns P (r, max n), n (r,), e0 (r,)."""
    m = (len(taps) - 1) // 2
    e0 = np.array([0 if p == 0 else 1 for p in range(r)], dtype=np.int64)
    n = np.array([(2 * m + p) // r - e0[p] + 1 for p in range(r)], dtype=np.int64)
    out = np.zeros((r, int(n.max())), dtype=taps.dtype)
    for p in range(r):
        out[p, : n[p]] = taps[r * (e0[p] + np.arange(n[p])) - p]
    return out, n, e0


_U = np.uint64
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@jit(inline="always")
def _rotl(v, k):
    return (v << _U(k)) | (v >> _U(64 - k))


@jit(inline="always")
def _splitmix(v):
    """splitmix64: the next state and its output."""
    v = v + _U(0x9E3779B97F4A7C15)
    z = v
    z = (z ^ (z >> _U(30))) * _U(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _U(27))) * _U(0x94D049BB133111EB)
    return v, z ^ (z >> _U(31))


@jit()
def _seed(key, stream):
    """xoshiro256** state (4 words) of stream ``stream`` under ``key`` (splitmix64 of both)."""
    v, h = _splitmix(_U(stream))
    v = _U(key) ^ h
    v, s0 = _splitmix(v)
    v, s1 = _splitmix(v)
    v, s2 = _splitmix(v)
    v, s3 = _splitmix(v)
    return s0, s1, s2, s3


@jit(inline="always")
def _next(s0, s1, s2, s3):
    """xoshiro256**: 64 random bits and the next state (kept in local variables: a state in
    an array made each draw many times slower)."""
    out = _rotl(s1 * _U(5), 7) * _U(9)
    t = s1 << _U(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    return out, s0, s1, s2, s3


@jit(inline="always")
def _unit(v):
    """Uniform on (0, 1) from the high 53 bits of v."""
    return (np.float64(v >> _U(11)) + 0.5) * _TO_UNIT


@jit()
def _fill(out, scale, s0, s1, s2, s3, zx, zf):
    """out[k] = scale x a standard normal deviate (ziggurat), k = 0, 1, ...; the next state.
    The layer and sign come from the low 8 bits of a 64-bit draw, the position in the layer
    from its high 53 bits. (One loop whose retries go round it again: a function returning one
    deviate made each draw several times slower.)"""
    k = 0
    n = len(out)
    while k < n:
        u, s0, s1, s2, s3 = _next(s0, s1, s2, s3)
        i = np.int64(u & _U(127))
        x = np.float64(u >> _U(11)) * _TO_UNIT * zx[i]
        if x >= zx[i + 1]:  # outside the layer's rectangle under the curve
            if i == 0:  # the tail beyond R (Marsaglia 1964)
                r = zx[1]
                while True:
                    v, s0, s1, s2, s3 = _next(s0, s1, s2, s3)
                    t = -math.log(_unit(v)) / r
                    v, s0, s1, s2, s3 = _next(s0, s1, s2, s3)
                    if -2.0 * math.log(_unit(v)) >= t * t:
                        break
                x = r + t
            else:  # the wedge: accept under the curve
                v, s0, s1, s2, s3 = _next(s0, s1, s2, s3)
                if zf[i] + _unit(v) * (zf[i + 1] - zf[i]) >= math.exp(-0.5 * x * x):
                    continue
        out[k] = scale * (-x if (u >> _U(7)) & _U(1) else x)
        k += 1
    return s0, s1, s2, s3


@jit()
def _normals(out, key, stream, zx, zf):
    s0, s1, s2, s3 = _seed(key, stream)
    _fill(out, 1.0, s0, s1, s2, s3, zx, zf)


def normals(size: int, key: int, stream: int) -> np.ndarray:
    """(size,) float64: the first ``size`` normal deviates of stream ``stream`` under ``key``
    (what a pixel's white noise is made of, before scaling)."""
    out = np.empty(int(size))
    _normals(out, np.uint64(key), np.uint64(stream), _ZX, _ZF)
    return out


@jit()
def _polyphase(z, ptaps, n_taps, e0, r, yrow, acc):
    """yrow[r q + p] = sum_t ptaps[p, t] z[q + e0[p] + t], in blocks of len(acc) outputs."""
    length = len(yrow)
    block = len(acc)
    for p in range(r):
        nq = (length - p + r - 1) // r
        for q0 in range(0, nq, block):
            nb = min(block, nq - q0)
            for q in range(nb):
                acc[q] = 0.0
            for t in range(n_taps[p]):
                c = ptaps[p, t]
                zz = z[q0 + e0[p] + t : q0 + e0[p] + t + nb]
                for q in range(nb):
                    acc[q] += c * zz[q]
            for q in range(nb):
                yrow[r * (q0 + q) + p] = acc[q]


@jit()
def _noise_rows(
    x, y, key, stream0, scale, shot_per_a, ptaps, n_taps, e0, r, taps, z, acc, zx, zf, level,
    signal, written,
):  # fmt: skip
    """Every row: white impulses on samples r i, the filter into y, the shot noise where x > 0
    (scattered through ``taps``; looked for in the rows with ``signal``), all of it added to x;
    the impulses only where the row has a signal or its noise reaches level[row] somewhere."""
    n, width = x.shape
    length = y.shape[1]
    two_m = width - length
    nz = (width + r - 1) // r
    shot = np.empty(width, np.float64)
    for row in range(n):
        s0, s1, s2, s3 = _seed(key, stream0 + row)
        s0, s1, s2, s3 = _fill(z[:nz], scale[row], s0, s1, s2, s3, zx, zf)
        _polyphase(z[:nz], ptaps, n_taps, e0, r, y[row], acc)
        xr = x[row]
        n_lit = 0
        if signal[row]:
            for c in range(width):
                n_lit += xr[c] > 0
        if shot_per_a > 0:
            if n_lit:
                s0, s1, s2, s3 = _fill(shot[:n_lit], 1.0, s0, s1, s2, s3, zx, zf)
                k = 0
                for c in range(width):
                    v = xr[c]
                    if v > 0:
                        w = math.sqrt(shot_per_a * v) * shot[k]
                        k += 1
                        for j in range(max(0, c - two_m), min(length - 1, c) + 1):
                            y[row, j] += taps[c - j] * w
                        xr[c] = v + w
        if n_lit == 0:
            above = 0  # (a count, not a max: the loop vectorises)
            yr = y[row]
            lv = level[row]
            for j in range(length):
                above += yr[j] >= lv
            if above == 0:
                written[row] = False
                continue
        written[row] = True
        for k in range(nz):
            xr[r * k] += z[k]


def noise_rows(
    x: np.ndarray,
    key: int,
    stream0: int,
    scale: np.ndarray,
    shot_per_a: float,
    taps: np.ndarray,
    r: int,
    level: np.ndarray | None = None,
    signal: np.ndarray | None = None,
    out: np.ndarray | None = None,
    written: np.ndarray | None = None,
) -> np.ndarray:
    """Band-limited white and shot noise of each row of the padded signal ``x``, IN PLACE.

    x : (n, L + 2 m) float32 or float64, C-contiguous -- the signal current [A] on the fine grid
        (m = the filter's half width); becomes signal + white noise (the input of h_B)
    key, stream0 : row i draws from stream ``stream0 + i`` under ``key`` (the pixel's index)
    scale : (n,) each row's white impulse sd [A]: sqrt(r) x the fine grid's white sd
    shot_per_a : the shot noise variance of a fine sample per ampere of signal [A]
        (F_chain 2 q M F / (2 dt)); 0: none
    taps : (2 m + 1,) the filter h_B dt (unit sum); r : the white step (:func:`white_step`)
    level : (n,) optional -- a row without signal whose noise stays below its level everywhere
        keeps x without the white impulses (who asks x only near a crossing of a higher level
        need not pay for writing them); None: every row gets them
    signal : (n,) bool, optional -- the rows that may hold a signal (the others are not searched
        for shot noise); None: every row
    out : (n, L) x.dtype, optional -- y is written into it (a buffer kept between calls)
    written : (n,) bool, optional -- set to which rows got the white impulses in x (the others'
        noise stays below their level everywhere)

    Returns y : (n, L) x.dtype -- the band-limited noise at the output samples ('valid': y[j] is
    at x's sample j + m).
    """
    dtype = x.dtype
    taps = np.ascontiguousarray(taps, dtype=dtype)
    ptaps, n_taps, e0 = phase_taps(taps, r)
    n, width = x.shape
    length = width - (len(taps) - 1)
    y = np.empty((n, length), dtype=dtype) if out is None else out
    z = np.empty((width + r - 1) // r, dtype=dtype)
    acc = np.empty(_BLOCK, dtype=dtype)
    level = np.full(n, -np.inf) if level is None else np.asarray(level, dtype=np.float64)
    signal = np.ones(n, dtype=bool) if signal is None else np.asarray(signal, dtype=bool)
    written = np.empty(n, dtype=bool) if written is None else written
    _noise_rows(
        x, y, np.uint64(key), np.uint64(stream0), np.ascontiguousarray(scale, dtype=dtype),
        float(shot_per_a), ptaps, n_taps, e0, int(r), taps, z, acc, _ZX, _ZF, level, signal,
        written,
    )  # fmt: skip
    return y
