"""The waveform Monte Carlo model (PHYSICS.md section 5): noisy currents through the band limit and
the constant-fraction discriminator itself, over the whole range gate of every pixel.

It checks the statistical model (Eqs. 24-28) by simulating what it summarises:

1. Signal current ``i_s(t) = R_resp P_r(t)`` (Eqs. 7, 29-30) sampled at ``dt``; white current
   samples ``N(0, S(t) / (2 dt))`` with the one-sided density
   ``S(t) = F_chain [2 q_e (i_s(t) M F + I_ds + I_db M^2 F) + 4 k_B T / R_L]`` are added to it
   BEFORE the band limit; the sum is convolved with the Gaussian ``h_B`` (unit area).
2. A discriminator over the whole gate: it arms where ``y`` crosses ``V_T = TNR sigma_n`` upwards
   and fires by the Eq. 19 rule (last upward zero crossing of ``s(t) = y(t - t_d) - k_att y(t)`` in
   ``[t_a - t_d, t_pk + t_d]``). Multi-stop by default, with a re-arm hold-off of one pulse FWHM.
3. A stop inside ``[min 2 r_k / c - tau, max 2 r_k / c + 2 tau]`` is a detection, any other stop a
   false alarm. Time of flight ``(t*_stop + e1) - (t*_ref + e2)`` with ``e1, e2 ~ U(-T_t/2, T_t/2)``
   (Eq. 26); ``t*_ref`` is the emitted pulse through the same band limit and discriminator.

Arming is continuous-time. The model's current is a continuous function,
``y(t) = sum_i x_i h_B(t - t_i) dt`` (``x_i`` the white + signal samples), so the comparator sees
every excursion above ``V_T``, also one that starts and ends between two samples: such pairs of
samples (both below ``V_T`` but within 15 % of it) are re-evaluated exactly at ``dt / 8`` from the
same ``x_i``. A comparator that looks at the samples only misses them and counts 3 % (TNR 3) to
9 % (TNR 6) fewer false alarms than the Rice rate at the default step (``arming="sampled"``
reproduces that; the exact count of sampled up-crossings is in the tests).

Where it differs from the statistical model (measured in tests/test_montecarlo.py and
scripts/plot_mc_agreement.py):

- P_d: Eq. 27 is a single look at the peak. The discriminator also arms on noise inside the
  detection window and on any sample of the pulse top: up to +0.24 at SNR = TNR = 2, +0.16 at
  TNR 3, +0.10 at TNR 4, below 0.1 from TNR 5 up. A noise stop shortly before an echo blocks it
  for the hold-off (P_d 0.97 at SNR 50, TNR 2).
- Range noise: Eq. 25 (ours) puts the shot noise of the peak into both CFD terms; the delayed
  copy is sampled at half the peak, where it is lower, so with shot noise the MC jitter is up to
  18 % below Eq. 25 (SNR 20); :func:`cfd_sigma_shot_aware_m` follows the MC.
- Waveform bias: for a multi-surface pixel the CFD fires on the first surface that crosses V_T;
  Eq. 31 times the half maximum of the strongest. Single surfaces agree to a few millimetres
  (sampling: the pulse-onset kink, the linear delayed copy and the linear crossing).
- False alarms: the Rice rate for up-crossings; the hold-off drops re-triggers within one FWHM
  (-4 % at TNR 2, nothing measurable from TNR 3).

Every pixel of the array is simulated over the whole gate, lit or not, in chunks of pixels whose
working set is at most ``max_bytes`` per worker thread, so memory stays bounded whatever the pixel
count. Chunks draw from independent child generators spawned from the caller's generator: a run is
reproducible for a given seed and ``max_bytes`` (the chunking), whatever the number of threads.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import constants as sc
from scipy import signal

from .detection import Outliers
from .echo import A_FWHM, PulseShape, band_limit_sigma_s, default_time_step_s, pulse_shape
from .receiver import Q_E, ReceiverModel
from .timing import cfd_delay_s

C = sc.c  # speed of light [m/s] (exact)
KERNEL_HALF_WIDTH_SIGMA = 6.0  # h_B truncated at +-6 sigma_h: 2e-9 of its area is lost
ARMING_REFINE = 8  # between-sample excursions are looked for at dt / 8
ARMING_MARGIN = 0.15  # pairs of samples within 15 % below V_T may hide an excursion...
ARMING_CURVATURE = 0.25  # ...if their curvature can lift them to V_T (see _refined_crossings)
ARMING_SLACK = 0.02  # fraction of V_T added to that reach
RAW_TAIL = 1e-9  # the emitted pulse is cut where it falls below 1e-9 of its peak
_THREADS = max(1, min(2, os.cpu_count() or 1))
_DEFAULT_MAX_BYTES = 64 << 20  # working set per worker thread [bytes]
_BYTES_PER_SAMPLE = 36  # float32 input, output, FFT buffers and masks per sample of a chunk


# ----------------------------------------------------------------------------------------------
# band limit and noisy currents
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BandLimit:
    """The Gaussian impulse response ``h_B`` sampled at ``dt``, normalised to unit area.

    taps : (2 m + 1,) float64 -- ``h_B(l dt) dt`` for l = -m..m, summing to 1 [1]
    """

    dt_s: float
    sigma_h_s: float
    taps: np.ndarray

    @property
    def half_width(self) -> int:
        """m, the number of taps either side of the centre."""
        return (len(self.taps) - 1) // 2

    def shifted_taps(self, n_sub: int) -> np.ndarray:
        """Taps of ``h_B`` delayed by q dt / n_sub, q = 1..n_sub-1: (n_sub - 1, 2 m + 1) [1].

        With them ``y(t_j + q dt / n_sub) = sum_l taps_q[l] x[j + 2 m - l]`` on the padded input
        ``x`` (the same sum as the sampled output, at a fractional delay)."""
        m = self.half_width
        lag = np.arange(-m, m + 1)[None, :] + (np.arange(1, n_sub)[:, None] / n_sub)
        g = np.exp(-0.5 * (lag * (self.dt_s / self.sigma_h_s)) ** 2)
        norm = np.exp(-0.5 * (np.arange(-m, m + 1) * (self.dt_s / self.sigma_h_s)) ** 2).sum()
        return g / norm


def band_limit(dt_s: float, bandwidth_hz: float) -> BandLimit:
    """``h_B`` of noise-equivalent bandwidth B (sigma_h = 1 / (4 sqrt(pi) B)) sampled at dt_s."""
    if not dt_s > 0:
        raise ValueError(f"time step dt_s = {dt_s!r} must be positive")
    sigma = band_limit_sigma_s(bandwidth_hz)
    m = max(1, math.ceil(KERNEL_HALF_WIDTH_SIGMA * sigma / dt_s))
    g = np.exp(-0.5 * (np.arange(-m, m + 1) * (dt_s / sigma)) ** 2)
    taps = g / g.sum()
    taps.setflags(write=False)
    return BandLimit(float(dt_s), float(sigma), taps)


def noise_density_a2_hz(i_signal_a, receiver: ReceiverModel):
    """One-sided current noise density at the discriminator, input-referred [A^2/Hz]:
    ``S = F_chain [2 q (i_s M F + I_ds + I_db M^2 F) + 4 k T / R_L]`` (Eqs. 10-13, 18).

    The signal-free part is ``sigma_n^2 / B``; the shot part ``2 q M F i_s F_chain`` (Eq. 10).
    i_signal_a : (...) signal current i_s = R_resp P_r [A] (negative values count as 0)
    """
    i = np.maximum(np.asarray(i_signal_a, dtype=np.float64), 0.0)
    return receiver.sigma_n_a**2 / receiver.bandwidth_hz + _shot_density_per_a(receiver) * i


def _shot_density_per_a(receiver: ReceiverModel) -> float:
    """dS/di_s = F_chain 2 q M F   [A^2/Hz per A]."""
    return receiver.chain_noise_factor * 2.0 * Q_E * receiver.gain * receiver.excess_noise


def _noisy_band_limited(
    rng: np.random.Generator | None,
    x: np.ndarray,
    receiver: ReceiverModel | None,
    band: BandLimit,
    noise: bool,
) -> np.ndarray:
    """Add the white current noise to the padded signal ``x`` IN PLACE, band-limit it.

    x : (n, L + 2 m) signal current i_s [A] with m = band.half_width samples either side of the
        output window; becomes signal + white noise (the input of h_B).
    Returns y : (n, L) band-limited current [A] ('valid' convolution: y[j] is at x's sample j + m).

    The white sample variance ``S(t) / (2 dt)`` is drawn as a signal-free part for every sample
    plus an independent shot part where i_s > 0: the same normal law. The convolution is linear,
    so h_B * (i_s + n) is computed as h_B * n over the whole rows (FFT, in x's dtype) plus
    h_B * i_s in float64 on each signal row's own span: an FFT spreads its rounding error,
    ~1e-7 of the largest value in float32, over the whole row, and an echo of SNR 1e3 is 1e5
    sigma_n high.
    """
    dt = band.dt_s
    m = band.half_width
    n_cols = x.shape[1]
    taps = band.taps.astype(x.dtype)[None, :]
    rows = np.flatnonzero((x > 0).any(axis=1))
    if noise:
        white = rng.standard_normal(x.shape, dtype=x.dtype)
        white *= x.dtype.type(receiver.sigma_n_a / math.sqrt(2.0 * dt * receiver.bandwidth_hz))
        if len(rows):
            idx = np.flatnonzero(x[rows] > 0)
            r, c = rows[idx // n_cols], idx % n_cols
            shot_var = _shot_density_per_a(receiver) * x[r, c].astype(np.float64) / (2.0 * dt)
            white[r, c] += np.sqrt(shot_var) * rng.standard_normal(len(idx))
        y = signal.fftconvolve(white, taps, mode="valid", axes=1)
    else:
        white = None
        y = np.zeros((x.shape[0], n_cols - 2 * m), dtype=x.dtype)
    if len(rows):
        nz = x[rows] > 0
        first = np.argmax(nz, axis=1)
        last = n_cols - 1 - np.argmax(nz[:, ::-1], axis=1)
        span = int((last - first).max()) + 1
        cols = np.minimum(first[:, None] + np.arange(span)[None, :], n_cols - 1)
        block = np.where(cols <= last[:, None], x[rows[:, None], cols], 0.0).astype(np.float64)
        conv = signal.fftconvolve(block, band.taps[None, :], mode="full", axes=1)
        # full-convolution output o of a block starting at column a is y[a - 2m + o]
        j = first[:, None] - 2 * m + np.arange(conv.shape[1])[None, :]
        ok = (j >= 0) & (j < y.shape[1])
        r = np.broadcast_to(rows[:, None], j.shape)
        y[r[ok], j[ok]] += conv[ok].astype(y.dtype)
    if white is not None:
        x += white
    return y


def simulate_current_waveforms(
    rng: np.random.Generator,
    i_signal_a,
    dt_s: float,
    receiver: ReceiverModel,
    *,
    n_samples: int | None = None,
    noise: bool = True,
    dtype=np.float64,
) -> np.ndarray:
    """Band-limited noisy current of each waveform (PHYSICS.md section 5).

    White current samples ``N(0, S(t) / (2 dt))`` (``S`` from :func:`noise_density_a2_hz`) are
    added to the signal current BEFORE the band limit, then the sum is convolved with ``h_B``
    (unit area, sigma_h = 1 / (4 sqrt(pi) B)). The noise is stationary from the first sample: it
    is drawn over m = ceil(6 sigma_h / dt) extra samples either side, where the signal is 0.

    Parameters
    ----------
    rng : numpy.random.Generator
    i_signal_a : (n, L) float, or a callable ``f(t_s) -> (n, L)``
        Signal current ``i_s = R_resp P_r(t)`` before the band limit [A] at ``t_s = j dt_s``,
        j = 0..L-1 (zeros for noise only); a callable is evaluated on that grid.
    dt_s : float
        Time step [s]; PHYSICS.md asks ``dt <= min(tau / 10, 1 / (20 B))``.
    receiver : ReceiverModel
        Gain, excess noise, chain noise factor, bandwidth and the signal-free sigma_n.
    n_samples : int, optional
        L, required when ``i_signal_a`` is a callable.
    noise : bool
        False gives the noise-free band-limited signal through the same filter.
    dtype : numpy float dtype
        float32 halves memory and time (the gate simulation uses it).

    Returns
    -------
    y_a : (n, L) dtype -- band-limited current at the discriminator, input-referred [A]
    """
    band = band_limit(dt_s, receiver.bandwidth_hz)
    m = band.half_width
    if callable(i_signal_a):
        if n_samples is None:
            raise ValueError("n_samples is required when i_signal_a is a callable")
        i_signal_a = i_signal_a(dt_s * np.arange(n_samples))
    sig = np.asarray(i_signal_a, dtype=np.float64)
    if sig.ndim != 2:
        raise ValueError(f"i_signal_a must be (n, L), got shape {sig.shape}")
    n, length = sig.shape
    x = np.zeros((n, length + 2 * m), dtype=dtype)
    x[:, m : m + length] = sig
    return _noisy_band_limited(rng, x, receiver, band, noise)


# ----------------------------------------------------------------------------------------------
# the discriminator (Eq. 19)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Stops:
    """Discriminator output, sorted by row then time.

    row : (s,) int64 -- waveform row of each stop
    t_s : (s,) float64 -- stop time t* [s] (same time origin as the waveform's ``t0_s``)
    t_arm_s : (s,) float64 -- the arming crossing t_a [s]
    fired : (s,) bool -- False where s(t) had no upward zero crossing in the Eq. 19 window (then
        t* = t_a: the zero-crossing comparator was already high when the arming one latched)
    """

    row: np.ndarray
    t_s: np.ndarray
    t_arm_s: np.ndarray
    fired: np.ndarray


def _sample_crossings(y, thr):
    """Upward crossings of ``thr`` between consecutive samples (not at column 0).

    Returns row, j (first sample at or above thr), t_a in samples (interpolated)."""
    n, length = y.shape
    flat = np.flatnonzero(y >= thr)
    col = flat % length
    prev_above = np.zeros(len(flat), dtype=bool)
    prev_above[1:] = flat[1:] - 1 == flat[:-1]
    idx = flat[~prev_above & (col > 0)]
    yf = y.reshape(-1)
    y0 = yf[idx - 1].astype(np.float64)
    y1 = yf[idx].astype(np.float64)
    j = idx % length
    return idx // length, j, (j - 1) + (thr - y0) / (y1 - y0)


def _refined_crossings(y, thr, x_padded, band: BandLimit, n_sub: int):
    """Excursions above ``thr`` that start and end between two samples both below it.

    Between samples j and j+1 the curve rises above their chord by at most dt^2 / 8 max|y''|. For
    band-limited noise (autocorrelation exp(-t^2 / (4 sigma_h^2))) near level u sigma_n the
    second derivative is N(-u / (2 sigma_h^2), 0.71 / sigma_h^2) in units of sigma_n, so at the
    default dt = 0.35 sigma_h the rise stays below 0.0157 (u / 2 + 5 x 0.71) sigma_n: 0.07 at
    TNR 2, 0.12 at TNR 8, below ARMING_MARGIN x TNR. An echo whose peak barely reaches V_T
    rises by at most ~0.5 % of its peak above the chord. Of the pairs whose larger sample is
    within that margin below ``thr``, those that can reach it by their own curvature (larger
    sample + ARMING_CURVATURE x the larger |second difference| + ARMING_SLACK x thr, twice the
    Taylor bound dt^2/8 |y''| plus slack for y'' varying within the pair) are evaluated exactly
    at q dt / n_sub from the input samples. The tests check that this pre-selection finds the
    same crossings as evaluating every pair within the margin.

    Returns row, j (first sample after the excursion's start), t_a in samples.
    """
    n, length = y.shape
    near = np.flatnonzero((y >= (1.0 - ARMING_MARGIN) * thr) & (y < thr))
    if len(near) == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    col = near % length
    # pairs (j, j+1) with j = col - 1 or col, both samples in the row and both below thr
    starts = np.sort(np.concatenate([near[col > 0] - 1, near[col < length - 1]]))
    starts = starts[np.append(True, starts[1:] != starts[:-1])]
    yf = y.reshape(-1)
    ya = yf[starts].astype(np.float64)
    yb = yf[starts + 1].astype(np.float64)
    j = starts % length
    # curvature of the pair from the second differences at both samples (dt^2 y'')
    yp = yf[np.where(j > 0, starts - 1, starts)].astype(np.float64)
    yn = yf[np.where(j + 2 < length, starts + 2, starts + 1)].astype(np.float64)
    d2 = np.maximum(np.abs(yp - 2.0 * ya + yb), np.abs(ya - 2.0 * yb + yn))
    reach = np.maximum(ya, yb) + ARMING_CURVATURE * d2 + ARMING_SLACK * thr
    keep = (ya < thr) & (yb < thr) & (reach >= thr)
    starts, ya, yb = starts[keep], ya[keep], yb[keep]
    row, j = starts // length, starts % length
    m = band.half_width
    taps = band.shifted_taps(n_sub).astype(x_padded.dtype)  # (n_sub - 1, 2m + 1)
    out_row, out_j, out_t = [], [], []
    step = max(1, (1 << 22) // (2 * m + 1))
    offsets = 2 * m - np.arange(2 * m + 1)
    for c in range(0, len(starts), step):
        r, jj = row[c : c + step], j[c : c + step]
        window = x_padded[r[:, None], jj[:, None] + offsets[None, :]]  # (p, 2m + 1)
        sub = (window @ taps.T).astype(np.float64)  # (p, n_sub - 1): y(t_j + q dt / n_sub)
        vals = np.concatenate([ya[c : c + step, None], sub, yb[c : c + step, None]], axis=1)
        hit = vals[:, 1:-1] >= thr
        any_hit = hit.any(axis=1)
        if not any_hit.any():
            continue
        q = np.argmax(hit, axis=1)[any_hit] + 1  # first sub-point at or above thr
        v = vals[any_hit]
        rows = np.arange(len(v))
        v0, v1 = v[rows, q - 1], v[rows, q]
        out_row.append(r[any_hit])
        out_j.append(jj[any_hit] + 1)
        out_t.append(jj[any_hit] + (q - 1 + (thr - v0) / (v1 - v0)) / n_sub)
    if not out_row:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    return np.concatenate(out_row), np.concatenate(out_j), np.concatenate(out_t)


def _first_local_max(y, row, start):
    """First sample index i >= start where y stops rising (y[i + 1] < y[i]); L-1 if none."""
    length = y.shape[1]
    jpk = np.full(len(row), length - 1, dtype=np.int64)
    todo = np.arange(len(row))
    pos = start.astype(np.int64).copy()
    width = 32
    while len(todo):
        idx = np.minimum(pos[todo, None] + np.arange(width + 1)[None, :], length - 1)
        block = y[row[todo, None], idx]
        falls = (block[:, 1:] < block[:, :-1]) & (idx[:, 1:] > idx[:, :-1])
        found = falls.any(axis=1)
        jpk[todo[found]] = idx[found, 0] + np.argmax(falls[found], axis=1)
        pos[todo] += width
        todo = todo[~found & (pos[todo] < length - 1)]
        width *= 2
    return jpk


def _batches(cost, budget: int):
    """Index batches, cheapest first, each of total (count x its largest cost) <= budget."""
    order = np.argsort(cost, kind="stable")
    sorted_cost = cost[order]
    c = 0
    while c < len(order):
        count = max(1, budget // max(1, int(sorted_cost[c])))
        count = max(
            1, min(count, budget // max(1, int(sorted_cost[min(len(order), c + count) - 1])))
        )
        yield order[c : c + count]
        c += count


def _cfd_stop(y, row, t_a, jpk, t_d, k_att):
    """Eq. 19: the last upward zero crossing of s(t) = y(t - t_d) - k_att y(t) in
    [t_a - t_d, t_pk + t_d].

    All times in samples. y(t - t_d) is linear between samples; a crossing is interpolated
    linearly between the two samples that bracket it. Returns t* (samples) and fired (bool).
    """
    length = y.shape[1]
    ns = math.floor(t_d)
    frac = t_d - ns
    lo = t_a - t_d
    hi = jpk + t_d
    i0 = np.floor(lo).astype(np.int64)
    i1 = np.ceil(hi).astype(np.int64)
    n_win = i1 - i0 + 1
    t_star = t_a.copy()
    fired = np.zeros(len(row), dtype=bool)
    for sel in _batches(n_win, 1 << 22):
        w = int(n_win[sel].max())
        i = i0[sel, None] + np.arange(w)[None, :]  # (p, w) sample indices
        r = row[sel, None]
        yv = y[r, np.clip(i, 0, length - 1)].astype(np.float64)
        yd = (1.0 - frac) * y[r, np.clip(i - ns, 0, length - 1)].astype(np.float64)
        yd += frac * y[r, np.clip(i - ns - 1, 0, length - 1)]
        s = yd - k_att * yv
        s0, s1 = s[:, :-1], s[:, 1:]
        up = (s0 < 0) & (s1 >= 0)
        tc = i[:, :-1] + s0 / np.where(up, s0 - s1, -1.0)
        ok = up & (tc >= lo[sel, None]) & (tc <= hi[sel, None]) & (i[:, 1:] <= i1[sel, None])
        has = ok.any(axis=1)
        last = w - 2 - np.argmax(ok[:, ::-1], axis=1)
        rows = np.arange(len(sel))
        t_star[sel[has]] = tc[rows, last][has]
        fired[sel[has]] = True
    return t_star, fired


def _apply_holdoff(row, t_a, t_star, holdoff, first_stop):
    """Which arming crossings become stops: after a stop the discriminator is dead from t_a to
    max(t_a, t*) + hold-off; with first_stop only the first stop of a row is kept.

    row, t_a sorted by (row, t_a). Returns accepted (bool)."""
    m = len(row)
    accepted = np.zeros(m, dtype=bool)
    if m == 0:
        return accepted
    first = np.ones(m, dtype=bool)
    first[1:] = row[1:] != row[:-1]
    start = np.flatnonzero(first)
    rank = np.arange(m) - np.repeat(start, np.diff(np.append(start, m)))
    if first_stop:
        accepted[start] = True
        return accepted
    dead_until = np.full(int(row.max()) + 1, -np.inf)
    order = np.argsort(rank, kind="stable")
    bounds = np.cumsum(np.bincount(rank))
    lo = 0
    for hi in bounds:
        sel = order[lo:hi]
        lo = hi
        ok = t_a[sel] >= dead_until[row[sel]]
        sel = sel[ok]
        accepted[sel] = True
        dead_until[row[sel]] = np.maximum(t_a[sel], t_star[sel]) + holdoff
    return accepted


def discriminate(
    y_a,
    dt_s: float,
    threshold_a: float,
    t_d_s: float,
    k_att: float,
    *,
    holdoff_s: float = 0.0,
    first_stop: bool = False,
    t0_s=0.0,
    x_padded_a=None,
    band: BandLimit | None = None,
) -> Stops:
    """Arming comparator + constant-fraction discriminator over whole waveforms (Eq. 19).

    The discriminator arms where y crosses ``threshold_a`` upwards (t_a, interpolated) and fires
    at the last upward zero crossing of ``s(t) = y(t - t_d) - k_att y(t)`` in
    ``[t_a - t_d, t_pk + t_d]``, t_pk the first local maximum of y after t_a. Every arming
    crossing is a stop unless it falls in the dead time of the previous stop (from its t_a to
    ``max(t_a, t*) + holdoff_s``); ``first_stop`` keeps only the first stop of each waveform.

    Parameters
    ----------
    y_a : (n, L) float -- band-limited current [A] at ``t0_s + j dt_s``
    dt_s : float -- sample step [s]
    threshold_a : float -- arming level V_T [A]
    t_d_s, k_att : float -- CFD delay [s] and attenuation [1] (Eq. 19)
    holdoff_s : float -- re-arm hold-off after a stop [s] (the gate simulation uses one FWHM)
    first_stop : bool -- keep only each waveform's first stop
    t0_s : float or (n,) float -- time of each row's sample 0 [s]
    x_padded_a : (n, L + 2 m) float, optional -- the input of h_B (signal + white noise) that
        made ``y_a``; with ``band`` the arming is continuous-time (between-sample excursions
        found exactly); without, only crossings between samples arm (a sampled comparator).
    band : BandLimit, optional

    Returns
    -------
    Stops
    """
    y = np.asarray(y_a)
    if y.ndim != 2:
        raise ValueError(f"y_a must be (n, L), got shape {y.shape}")
    thr = float(threshold_a)
    row, j, t_a = _sample_crossings(y, thr)
    if x_padded_a is not None and band is not None:
        r2, j2, t2 = _refined_crossings(y, thr, np.asarray(x_padded_a), band, ARMING_REFINE)
        row, j, t_a = np.concatenate([row, r2]), np.concatenate([j, j2]), np.concatenate([t_a, t2])
        order = np.lexsort((t_a, row))
        row, j, t_a = row[order], j[order], t_a[order]
    jpk = _first_local_max(y, row, j)
    t_d = t_d_s / dt_s
    t_star, fired = _cfd_stop(y, row, t_a, jpk, t_d, k_att)
    accepted = _apply_holdoff(row, t_a, t_star, holdoff_s / dt_s, first_stop)
    row, t_a, t_star, fired = row[accepted], t_a[accepted], t_star[accepted], fired[accepted]
    t0 = np.broadcast_to(np.asarray(t0_s, dtype=np.float64), (y.shape[0],))
    return Stops(row.astype(np.int64), t0[row] + t_star * dt_s, t0[row] + t_a * dt_s, fired)


def reference_stop_s(
    shape: PulseShape, band: BandLimit, t_d_s: float, k_att: float, dtype=np.float32
) -> float:
    """t*_ref: the emitted pulse (t = 0 at its start, Eq. 1) sampled at j dt, band-limited by the
    same taps and timed by the same discriminator, noise-free, armed at half its peak [s]."""
    dt = band.dt_s
    m = band.half_width
    pre = m + math.ceil(t_d_s / dt) + 4
    t_end = _raw_end_s(shape) + t_d_s
    t = dt * (np.arange(pre + math.ceil(t_end / dt) + m + 4) - pre)
    x = np.zeros((1, len(t) + 2 * m), dtype=dtype)
    x[0, m : m + len(t)] = shape.raw_at(t)
    y = _noisy_band_limited(None, x, None, band, noise=False)  # the echoes' own signal path
    stops = discriminate(
        y, dt, 0.5 * float(y.max()), t_d_s, k_att, t0_s=t[0], x_padded_a=x, band=band
    )
    if len(stops.t_s) != 1 or not stops.fired[0]:
        raise RuntimeError("the reference pulse did not give exactly one CFD stop")
    return float(stops.t_s[0])


def _raw_end_s(shape: PulseShape) -> float:
    """Time after the pulse start when the emitted pulse falls below RAW_TAIL of its peak [s]."""
    above = np.flatnonzero(shape.raw > RAW_TAIL * shape.raw.max())
    return float(shape.t0_s + shape.step_s * (above[-1] + 1))


def pulse_fwhm_s(shape: PulseShape) -> float:
    """FWHM of the emitted pulse of Eq. 1: tau for a = A_FWHM, 0.699 tau for the paper's a."""
    return shape.tau_s * A_FWHM / shape.a


# ----------------------------------------------------------------------------------------------
# the whole gate of the whole array
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class McResult:
    """One flash through the waveform Monte Carlo model.

    pixel : (n,) int64 -- flat index of each echo pixel (as EchoStage.pixel)
    detected : (n,) bool -- a stop fell in the pixel's detection window
    range_m : (n,) float64 -- range of the first detection stop [m], NaN if none
    n_stops : (n,) int64 -- all stops of the pixel's gate (detections and false alarms)
    false_alarm_pixel : (f,) int64 -- flat pixel index of every false-alarm stop (all pixels)
    false_alarm_range_m : (f,) float64 -- its range [m]
    n_pixels_total : int -- pixels simulated (the whole array)
    gate_s : (float, float) -- first and last sample time of the gate [s]
    reference_stop_s : float -- t*_ref [s]
    threshold_a : float -- V_T = TNR sigma_n [A]
    dt_s : float
    n_unfired : int -- stops at t_a because s(t) had no upward zero crossing in the window
    timings_s : dict -- wall time of the run and thread-seconds per part [s]
    """

    pixel: np.ndarray
    detected: np.ndarray
    range_m: np.ndarray
    n_stops: np.ndarray
    false_alarm_pixel: np.ndarray
    false_alarm_range_m: np.ndarray
    n_pixels_total: int
    gate_s: tuple[float, float]
    reference_stop_s: float
    threshold_a: float
    dt_s: float
    n_unfired: int
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def outliers(self) -> Outliers:
        """The false alarms as detection.Outliers (pixel, range), for the point cloud."""
        return Outliers(self.false_alarm_pixel, self.false_alarm_range_m)

    @property
    def n_false_alarms(self) -> int:
        return len(self.false_alarm_pixel)


@dataclass(frozen=True)
class _GateSetup:
    shape: PulseShape
    band: BandLimit
    receiver: ReceiverModel
    energy_j: float
    t_lo: float  # time of gate sample 0 [s]
    n_samples: int
    threshold_a: float
    t_d_s: float
    k_att: float
    holdoff_s: float
    first_stop: bool
    resolution_s: float
    t_ref_s: float
    raw_end_s: float
    tau_s: float
    noise: bool
    continuous: bool
    lit_of_pixel: np.ndarray  # (n_total,) index into the echo arrays, -1 if unlit
    arrivals: np.ndarray  # (n_lit, K)
    weights: np.ndarray  # (n_lit, K), per joule
    window_lo: np.ndarray  # (n_lit,) detection window [s]
    window_hi: np.ndarray


def _signal_into(x: np.ndarray, setup: _GateSetup, lit: np.ndarray, local_rows: np.ndarray):
    """Write i_s = R_resp E sum_k w_k P0(t - t_k) (Eqs. 7, 29, 30) of the lit rows into the
    padded input x, on each pixel's own window (delays exact, never snapped)."""
    any_weight = (setup.weights[lit] > 0).any(axis=1)
    lit, local_rows = lit[any_weight], local_rows[any_weight]
    if len(lit) == 0:
        return
    dt, m = setup.band.dt_s, setup.band.half_width
    width = x.shape[1]
    arr, w = setup.arrivals[lit], setup.weights[lit]
    has = w > 0
    t_first = np.where(has, arr, np.inf).min(axis=1)
    t_last = np.where(has, arr, -np.inf).max(axis=1)
    arr = np.where(has, arr, t_first[:, None])
    scale = setup.receiver.responsivity_a_w * setup.energy_j
    # padded column c holds the sample at t_lo + (c - m) dt
    c0 = np.clip(np.floor((t_first - setup.t_lo) / dt).astype(np.int64) + m, 0, width)
    t_end = t_last + setup.raw_end_s - setup.t_lo
    c1 = np.clip(np.ceil(t_end / dt).astype(np.int64) + m + 1, 0, width)
    n_cols = c1 - c0
    k = arr.shape[1]
    for sel in _batches(np.maximum(n_cols, 1) * k, 1 << 21):
        wmax = int(n_cols[sel].max())
        if wmax <= 0:
            continue
        cols = c0[sel, None] + np.arange(wmax)[None, :]
        t = setup.t_lo + (cols - m) * dt
        p = np.einsum("pwk,pk->pw", setup.shape.raw_at(t[:, :, None] - arr[sel, None, :]), w[sel])
        inside = cols < c1[sel, None]
        r = np.broadcast_to(local_rows[sel, None], cols.shape)
        x[r[inside], cols[inside]] = (scale * p[inside]).astype(x.dtype)


def _gate_chunk(setup: _GateSetup, p0: int, p1: int, rng: np.random.Generator):
    """Simulate pixels p0..p1-1 over the whole gate; return their stops and the part timings."""
    t0 = time.perf_counter()
    n = p1 - p0
    m = setup.band.half_width
    x = np.zeros((n, setup.n_samples + 2 * m), dtype=np.float32)
    lit = setup.lit_of_pixel[p0:p1]
    local = np.flatnonzero(lit >= 0)
    _signal_into(x, setup, lit[local], local)
    y = _noisy_band_limited(rng, x, setup.receiver, setup.band, setup.noise)
    t1 = time.perf_counter()
    stops = discriminate(
        y,
        setup.band.dt_s,
        setup.threshold_a,
        setup.t_d_s,
        setup.k_att,
        holdoff_s=setup.holdoff_s,
        first_stop=setup.first_stop,
        t0_s=setup.t_lo,
        x_padded_a=x if setup.continuous else None,
        band=setup.band if setup.continuous else None,
    )
    del x, y
    # Eq. 26: e1 per stop, e2 per pixel (each pixel's TDC registers the start once)
    half = 0.5 * setup.resolution_s
    e2 = rng.uniform(-half, half, size=n)
    e1 = rng.uniform(-half, half, size=len(stops.row))
    tof = (stops.t_s + e1) - (setup.t_ref_s + e2[stops.row])
    pixel = stops.row + p0
    lit_idx = setup.lit_of_pixel[pixel]
    is_lit = lit_idx >= 0
    in_window = np.zeros(len(pixel), dtype=bool)
    li = lit_idx[is_lit]
    t_lit = stops.t_s[is_lit]
    in_window[is_lit] = (t_lit >= setup.window_lo[li]) & (t_lit <= setup.window_hi[li])
    out = {
        "pixel": pixel,
        "lit": lit_idx,
        "t_s": stops.t_s,
        "range_m": 0.5 * C * tof,
        "detection": is_lit & in_window,
        "unfired": int(np.count_nonzero(~stops.fired)),
    }
    return out, (t1 - t0, time.perf_counter() - t1)


def gate_samples(gate_center_m: float, gate_m: float, dt_s: float) -> tuple[float, int]:
    """Time of the first gate sample [s] and the sample count of the range gate
    [R_st - R_gate / 2, R_st + R_gate / 2] (clipped at 0)."""
    lo = max(0.0, gate_center_m - 0.5 * gate_m)
    hi = gate_center_m + 0.5 * gate_m
    t_lo, t_hi = 2.0 * lo / C, 2.0 * hi / C
    return t_lo, int(math.floor((t_hi - t_lo) / dt_s)) + 1


def montecarlo_gate(
    rng: np.random.Generator,
    *,
    pixel,
    arrivals_s,
    weights_per_j,
    shape: PulseShape,
    dt_s: float,
    receiver: ReceiverModel,
    pulse_energy_j: float,
    n_pixels_total: int,
    gate_center_m: float,
    gate_m: float,
    tnr: float,
    t_d_s: float,
    k_att: float,
    resolution_s: float,
    first_stop: bool = False,
    holdoff_s: float | None = None,
    noise: bool = True,
    arming: str = "continuous",
    max_bytes: int = _DEFAULT_MAX_BYTES,
    n_threads: int = _THREADS,
) -> McResult:
    """Waveform Monte Carlo of one flash over the whole gate of every pixel (PHYSICS.md s. 5).

    Parameters
    ----------
    rng : numpy.random.Generator -- children are spawned from it, one per chunk of pixels
    pixel : (n,) int -- flat index of each echo pixel, in [0, n_pixels_total)
    arrivals_s, weights_per_j : (n, K) float -- Eq. 29-30 two-way delays [s] and weights (per
        joule of pulse energy: P_r(t) = E sum_k w_k P0(t - t_k)); weight 0 = no element
    shape : PulseShape -- the emitted pulse (Eq. 1)
    dt_s : float -- time step [s]
    receiver : ReceiverModel -- gain, noise, responsivity (Eqs. 7-18)
    pulse_energy_j : float -- E [J]
    n_pixels_total : int -- pixels of the array; the unlit ones see noise only
    gate_center_m, gate_m : float -- range gate R_st and R_gate [m]
    tnr : float -- V_T = tnr sigma_n
    t_d_s, k_att : float -- CFD delay [s] and fraction (Eq. 19)
    resolution_s : float -- timing resolution T_t [s] (Eq. 26)
    first_stop : bool -- keep only each pixel's first stop
    holdoff_s : float, optional -- re-arm hold-off; default one FWHM of the emitted pulse
    noise : bool -- False: noise-free waveforms through the same discriminator
    arming : "continuous" (an analog comparator) or "sampled" (crossings between samples only)
    max_bytes : int -- working set per worker thread [bytes]
    n_threads : int -- worker threads (numpy and scipy.fft release the GIL)

    Returns
    -------
    McResult
    """
    if arming not in ("continuous", "sampled"):
        raise ValueError(f"arming must be 'continuous' or 'sampled', got {arming!r}")
    t_start = time.perf_counter()
    pixel = np.asarray(pixel, dtype=np.int64).reshape(-1)
    arrivals = np.atleast_2d(np.asarray(arrivals_s, dtype=np.float64))
    weights = np.atleast_2d(np.asarray(weights_per_j, dtype=np.float64))
    if arrivals.shape != weights.shape or arrivals.shape[0] != len(pixel):
        raise ValueError(
            f"arrivals_s {arrivals.shape} and weights_per_j {weights.shape} must be (n, K) "
            f"with n = len(pixel) = {len(pixel)}"
        )
    if len(pixel) and (pixel.min() < 0 or pixel.max() >= n_pixels_total):
        raise ValueError(f"pixel indices must lie in [0, {n_pixels_total})")
    band = band_limit(dt_s, receiver.bandwidth_hz)
    t_ref = reference_stop_s(shape, band, t_d_s, k_att)
    t_lo, n_samples = gate_samples(gate_center_m, gate_m, dt_s)
    lit_of_pixel = np.full(n_pixels_total, -1, dtype=np.int64)
    lit_of_pixel[pixel] = np.arange(len(pixel))
    has = weights > 0
    tau = shape.tau_s
    window_lo = np.where(has, arrivals, np.inf).min(axis=1, initial=np.inf) - tau
    window_hi = np.where(has, arrivals, -np.inf).max(axis=1, initial=-np.inf) + 2.0 * tau
    setup = _GateSetup(
        shape=shape,
        band=band,
        receiver=receiver,
        energy_j=float(pulse_energy_j),
        t_lo=t_lo,
        n_samples=n_samples,
        threshold_a=float(tnr) * receiver.sigma_n_a,
        t_d_s=float(t_d_s),
        k_att=float(k_att),
        holdoff_s=pulse_fwhm_s(shape) if holdoff_s is None else float(holdoff_s),
        first_stop=first_stop,
        resolution_s=float(resolution_s),
        t_ref_s=t_ref,
        raw_end_s=_raw_end_s(shape),
        tau_s=tau,
        noise=noise,
        continuous=arming == "continuous",
        lit_of_pixel=lit_of_pixel,
        arrivals=arrivals,
        weights=weights,
        window_lo=window_lo,
        window_hi=window_hi,
    )
    rows = max(1, int(max_bytes) // (_BYTES_PER_SAMPLE * (n_samples + 2 * band.half_width)))
    bounds = [(p, min(p + rows, n_pixels_total)) for p in range(0, n_pixels_total, rows)]
    children = rng.spawn(len(bounds))
    jobs = [(p0, p1, g) for (p0, p1), g in zip(bounds, children, strict=True)]
    t_setup = time.perf_counter() - t_start

    parts = []
    t_wave = t_disc = 0.0
    work: Callable[[Any], Any] = lambda job: _gate_chunk(setup, *job)  # noqa: E731
    with ThreadPoolExecutor(max_workers=max(1, min(n_threads, len(jobs)))) as pool:
        for out, (tw, td) in pool.map(work, jobs):
            parts.append(out)
            t_wave += tw
            t_disc += td

    t_collect = time.perf_counter()
    cat = {k: np.concatenate([p[k] for p in parts]) for k in ("pixel", "lit", "t_s", "range_m")}
    detection = np.concatenate([p["detection"] for p in parts])
    n_lit = len(pixel)
    lit = cat["lit"]
    n_stops = np.bincount(lit[lit >= 0], minlength=n_lit).astype(np.int64)
    det_lit, det_t, det_r = lit[detection], cat["t_s"][detection], cat["range_m"][detection]
    order = np.lexsort((det_t, det_lit))
    first_lit, first_at = np.unique(det_lit[order], return_index=True)
    detected = np.zeros(n_lit, dtype=bool)
    detected[first_lit] = True
    range_m = np.full(n_lit, np.nan)
    range_m[first_lit] = det_r[order][first_at]
    fa = ~detection
    timings = {
        "setup": t_setup,
        "waveforms_thread_s": t_wave,
        "discriminator_thread_s": t_disc,
        "collect": time.perf_counter() - t_collect,
        "total": time.perf_counter() - t_start,
    }
    return McResult(
        pixel=pixel,
        detected=detected,
        range_m=range_m,
        n_stops=n_stops,
        false_alarm_pixel=cat["pixel"][fa],
        false_alarm_range_m=cat["range_m"][fa],
        n_pixels_total=int(n_pixels_total),
        gate_s=(t_lo, t_lo + (n_samples - 1) * dt_s),
        reference_stop_s=t_ref,
        threshold_a=setup.threshold_a,
        dt_s=float(dt_s),
        n_unfired=sum(p["unfired"] for p in parts),
        timings_s=timings,
    )


def montecarlo_detection(
    rng: np.random.Generator,
    echo_stage,
    receiver_model: ReceiverModel,
    scene,
    first_stop: bool = False,
    **options,
) -> McResult:
    """The Monte Carlo detection stage for the pipeline: one flash of ``scene``.

    Parameters
    ----------
    rng : numpy.random.Generator
    echo_stage : pipeline.EchoStage -- uses pixel, arrivals_s, weights, shape, dt_s, cfd_delay_s
    receiver_model : ReceiverModel
    scene : Scene -- detector.pixels, laser.pulse_energy_j, timing (tnr, resolution_s,
        cfd_fraction, range_gate_m) and gate_center_m
    first_stop : bool -- keep only each pixel's first stop (default: multi-stop)
    **options -- passed to :func:`montecarlo_gate` (holdoff_s, noise, arming, max_bytes,
        n_threads)

    Returns
    -------
    McResult -- per echo pixel (in echo_stage.pixel order): detected, range_m, n_stops; the
    false alarms of every pixel of the array; timings.
    """
    t = scene.timing
    return montecarlo_gate(
        rng,
        pixel=echo_stage.pixel,
        arrivals_s=echo_stage.arrivals_s,
        weights_per_j=echo_stage.weights,
        shape=echo_stage.shape,
        dt_s=echo_stage.dt_s,
        receiver=receiver_model,
        pulse_energy_j=scene.laser.pulse_energy_j,
        n_pixels_total=scene.detector.pixels**2,
        gate_center_m=scene.gate_center_m,
        gate_m=t.range_gate_m,
        tnr=t.tnr,
        t_d_s=echo_stage.cfd_delay_s,
        k_att=t.cfd_fraction,
        resolution_s=t.resolution_s,
        first_stop=first_stop,
        **options,
    )


# ----------------------------------------------------------------------------------------------
# cross-check: the CFD jitter with the signal's own shot noise at the instants the CFD compares
# ----------------------------------------------------------------------------------------------
def cfd_sigma_shot_aware_m(
    shape: PulseShape,
    receiver: ReceiverModel,
    i_pk_a: float,
    t_d_s: float,
    k_att: float,
) -> float:
    """Linearised CFD range jitter of a single-surface echo with time-dependent shot noise [m].

    Eq. 25 (ours) puts the noise of the peak, sigma_pk (with the peak's shot noise), into both
    terms of ``s = y(t - t_d) - k y(t)``. The CFD fires near the peak of y(t) while the delayed
    copy is at half its peak, where the shot noise is smaller. With the noise covariance
    ``Cov(t1, t2) = sigma_n^2 rho_n(t1 - t2) + F_chain q M F int h_B(t1 - u) h_B(t2 - u) i_s(u) du``
    the jitter is ``(c/2) sqrt(Var(n(t* - t_d) - k n(t*))) / |ds/dt(t*)|``. Without shot noise
    it equals Eq. 25 exactly.

    i_pk_a : band-limited peak signal current [A]; t_d_s, k_att : Eq. 19 delay [s] and fraction.
    """
    scale = i_pk_a / shape.peak_w_per_j  # [A per (W/J)]
    sigma = shape.sigma_h_s

    def mu(t):
        return scale * shape.filtered_at(t)

    # t*: noise-free CFD crossing of the continuous echo, between its half-maximum and peak + t_d
    grid = np.linspace(shape.t_half_s, shape.t_peak_s + t_d_s, 20001)
    s = mu(grid - t_d_s) - k_att * mu(grid)
    i = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))[-1]
    t_star = grid[i] - s[i] * (grid[i + 1] - grid[i]) / (s[i + 1] - s[i])
    h = 1e-3 * sigma
    slope = (
        (mu(t_star - t_d_s + h) - mu(t_star - t_d_s - h)) / (2 * h)
        - k_att * (mu(t_star + h) - mu(t_star - h)) / (2 * h)
    )[()]
    u = np.linspace(shape.t0_s, _raw_end_s(shape), 200001)
    du = u[1] - u[0]
    i_s = scale * shape.raw_at(u)  # the unfiltered signal current [A]

    def h_b(t):
        return np.exp(-0.5 * (t / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)

    shot = receiver.chain_noise_factor * Q_E * receiver.gain * receiver.excess_noise

    def cov(t1, t2):
        white = receiver.sigma_n_a**2 * np.exp(-((t1 - t2) ** 2) / (4 * sigma**2))
        return white + shot * np.sum(h_b(t1 - u) * h_b(t2 - u) * i_s) * du

    t1, t2 = t_star - t_d_s, t_star
    var = cov(t1, t1) + k_att**2 * cov(t2, t2) - 2 * k_att * cov(t1, t2)
    return float(0.5 * C * np.sqrt(var) / abs(slope))


def scene_gate(
    rng: np.random.Generator,
    scene,
    receiver: ReceiverModel,
    arrivals_s,
    weights_per_j,
    *,
    tnr: float,
    gate_m: float,
    n_pixels_total: int | None = None,
    **options,
) -> McResult:
    """:func:`montecarlo_gate` for synthetic echoes, its pulse, band limit, CFD, timing and gate
    centre (the target distance) taken from ``scene``; pixels are numbered 0..n-1. ``options``
    pass on (holdoff_s, noise, arming, first_stop, max_bytes, n_threads, or resolution_s to
    override the scene's)."""
    tau, b_hz = scene.laser.pulse_width_s, scene.detector.bandwidth_hz
    shape = pulse_shape(tau, A_FWHM, b_hz)
    n = len(arrivals_s)
    return montecarlo_gate(
        rng,
        pixel=np.arange(n),
        arrivals_s=arrivals_s,
        weights_per_j=weights_per_j,
        shape=shape,
        dt_s=default_time_step_s(tau, b_hz),
        receiver=receiver,
        pulse_energy_j=scene.laser.pulse_energy_j,
        n_pixels_total=n if n_pixels_total is None else n_pixels_total,
        gate_center_m=scene.pose.distance_m,
        gate_m=gate_m,
        tnr=tnr,
        t_d_s=cfd_delay_s(shape),
        k_att=scene.timing.cfd_fraction,
        resolution_s=options.pop("resolution_s", scene.timing.resolution_s),
        **options,
    )
