"""Noisy currents through the band limit (docs/physics.md#mc-noise): the white current
samples of the one-sided noise density, the signal current, the Gaussian h_B convolution."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ....pulse import band_limit_sigma_s
from ..apd import Q_E, ReceiverModel

KERNEL_HALF_WIDTH_SIGMA = 6.0  # h_B truncated at +-6 sigma_h: 2e-9 of its area is lost


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

    def shifted_taps(self, n_sub: int, ends: bool = False) -> np.ndarray:
        """Taps of ``h_B`` delayed by q dt / n_sub, q = 1..n_sub-1: (n_sub - 1, 2 m + 1) [1];
        with ``ends`` q = 0..n_sub: (n_sub + 1, 2 m + 1).

        With them ``y(t_j + q dt / n_sub) = sum_l taps_q[l] x[j + 2 m - l]`` on the padded input
        ``x`` (the same sum as the sampled output, at a fractional delay)."""
        m = self.half_width
        q = np.arange(0, n_sub + 1) if ends else np.arange(1, n_sub)
        lag = np.arange(-m, m + 1)[None, :] + (q[:, None] / n_sub)
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


def noisy_band_limited(
    rng: np.random.Generator | None,
    x: np.ndarray,
    receiver: ReceiverModel | None,
    band: BandLimit,
    noise: bool,
    add_signal: bool = True,
    row_scale: np.ndarray | None = None,
    photon=None,
    stream0: int = 0,
    key: int | None = None,
    white_level: np.ndarray | None = None,
    signal_rows: np.ndarray | None = None,
    out: np.ndarray | None = None,
    rows_written: np.ndarray | None = None,
) -> np.ndarray:
    """Add the white current noise to the padded signal ``x`` IN PLACE, band-limit it.

    x : (n, L + 2 m) signal current i_s [A] with m = band.half_width samples either side of the
        output window; becomes signal + white noise (the input of h_B).
    Returns y : (n, L) band-limited current [A] ('valid' convolution: y[j] is at x's sample j + m).
    With ``add_signal=False`` y holds the band-limited noise only (its shot part still follows x):
    the caller adds the band-limited signal itself (the gate adds it in closed form).
    ``row_scale`` (n,): each row's signal-free noise over sigma_n (a pixel's background light
    adds its shot noise, 2 q i_bg0 M^2 F F_chain to S: docs/physics.md#background-noise); None: 1.
    ``photon`` (a :class:`.photon.PhotonNoise`): the shot and bulk dark noise
    drawn photon by photon with McIntyre gains instead (docs/physics.md#mcintyre); a row's
    background shot noise (``row_scale``) is then added as Gaussian noise.

    Gaussian noise is drawn by the compiled noise kernel (:mod:`.noise`) where numba loads: the
    signal-free white noise on every r-th sample (:func:`.noise.white_step`, r = 2 at the default
    step; docs/physics.md#mc-noise-draw), row i from its own stream ``stream0 + i`` under
    ``key`` (a 64-bit number; None: drawn from ``rng``), filtered by the polyphase taps; the
    shot noise on the fine grid. Without numba (and with ``photon``) every sample is drawn from
    ``rng`` and filtered by FFT. ``white_level`` (n,), for the kernel: a row without signal whose
    band-limited noise stays below its level keeps x without the white noise (a caller that
    reads x only near higher samples saves writing it); None: x gets it in every row.
    ``signal_rows`` (n,) bool: the rows that may hold a signal (None: any); ``out`` (n, L): a
    buffer for y (the kernel writes every sample of it); ``rows_written`` (n,) bool: set False
    by the kernel where a row's noise stayed below its ``white_level`` (left as it is otherwise).

    The white sample variance ``S(t) / (2 dt)`` is drawn as a signal-free part for every sample
    plus an independent shot part where i_s > 0: the same normal law. The convolution is linear,
    so h_B * (i_s + n) is computed as h_B * n over the whole rows (the kernel's filter or an
    FFT, in x's dtype) plus h_B * i_s in float64 on each signal row's own span: an FFT spreads
    its rounding error, ~1e-7 of the largest value in float32, over the whole row, and an echo
    of SNR 1e3 is 1e5 sigma_n high.
    """
    dt = band.dt_s
    m = band.half_width
    n_cols = x.shape[1]
    taps = band.taps.astype(x.dtype)[None, :]
    kernel = _noise_kernel() if noise and photon is None else None
    # the rows with a signal (a pass over x: the kernel finds its shot noise's samples itself)
    need_rows = add_signal or (noise and kernel is None)
    rows = np.flatnonzero((x > 0).any(axis=1)) if need_rows else np.zeros(0, np.int64)
    filtered = _filtered_signal(x, rows, band) if add_signal and len(rows) else None
    if kernel is not None:
        assert rng is not None and receiver is not None  # noise needs both
        r = kernel.white_step(dt, band.sigma_h_s)
        sigma_w = receiver.sigma_n_a / math.sqrt(2.0 * dt * receiver.bandwidth_hz)
        scale = np.full(x.shape[0], math.sqrt(r) * sigma_w)
        if row_scale is not None:
            scale *= np.asarray(row_scale, dtype=np.float64)
        if key is None:
            key = int(rng.integers(1 << 63))
        shot_per_a = _shot_density_per_a(receiver) / (2.0 * dt)
        y = kernel.noise_rows(
            x, key, stream0, scale, shot_per_a, band.taps, r, white_level, signal_rows, out,
            rows_written,
        )  # fmt: skip
        white = None  # x holds signal + white noise already
    elif noise and photon is not None:  # photon statistics (montecarlo.photon.PhotonNoise)
        assert rng is not None and receiver is not None  # noise needs both
        white = rng.standard_normal(x.shape, dtype=x.dtype)
        white *= x.dtype.type(photon.gaussian_sigma_a(receiver, dt))
        photon.add_noise(rng, white, x, dt, receiver)
        if row_scale is not None:  # the background's shot noise stays Gaussian here
            extra = np.sqrt(np.maximum(np.asarray(row_scale, dtype=np.float64) ** 2 - 1.0, 0.0))
            sigma_w = receiver.sigma_n_a / math.sqrt(2.0 * dt * receiver.bandwidth_hz)
            white += (rng.standard_normal(x.shape) * (sigma_w * extra)[:, None]).astype(x.dtype)
        y = signal.fftconvolve(white, taps, mode="valid", axes=1)
    elif noise:
        assert rng is not None and receiver is not None  # noise needs both
        white = rng.standard_normal(x.shape, dtype=x.dtype)
        white *= x.dtype.type(receiver.sigma_n_a / math.sqrt(2.0 * dt * receiver.bandwidth_hz))
        if row_scale is not None:
            white *= np.asarray(row_scale, dtype=x.dtype)[:, None]
        if len(rows):
            idx = np.flatnonzero(x[rows] > 0)
            r, c = rows[idx // n_cols], idx % n_cols
            shot_var = _shot_density_per_a(receiver) * x[r, c].astype(np.float64) / (2.0 * dt)
            white[r, c] += np.sqrt(shot_var) * rng.standard_normal(len(idx))
        y = signal.fftconvolve(white, taps, mode="valid", axes=1)
    else:
        white = None
        y = np.zeros((x.shape[0], n_cols - 2 * m), dtype=x.dtype)
    if filtered is not None:
        r_sig, j_sig, values = filtered
        y[r_sig, j_sig] += values.astype(y.dtype)
    if white is not None:
        x += white
    return y


def _filtered_signal(x: np.ndarray, rows: np.ndarray, band: BandLimit):
    """h_B * i_s of the signal rows of the padded input x, in float64 on each row's own span:
    (row, output column, value) of every output sample it reaches."""
    m = band.half_width
    n_out = x.shape[1] - 2 * m
    nz = x[rows] > 0
    n_cols = x.shape[1]
    first = np.argmax(nz, axis=1)
    last = n_cols - 1 - np.argmax(nz[:, ::-1], axis=1)
    span = int((last - first).max()) + 1
    cols = np.minimum(first[:, None] + np.arange(span)[None, :], n_cols - 1)
    block = np.where(cols <= last[:, None], x[rows[:, None], cols], 0.0).astype(np.float64)
    conv = signal.fftconvolve(block, band.taps[None, :], mode="full", axes=1)
    # full-convolution output o of a block starting at column a is y[a - 2m + o]
    j = first[:, None] - 2 * m + np.arange(conv.shape[1])[None, :]
    ok = (j >= 0) & (j < n_out)
    r = np.broadcast_to(rows[:, None], j.shape)
    return r[ok], j[ok], conv[ok]


def _noise_kernel():
    """The compiled noise kernel (:mod:`.noise`), or None where the echo kernel runs on numpy
    (numba unavailable or ``$LMAPD_NO_NUMBA``)."""
    from ....echo.features import compiled_kernel  # noqa: PLC0415  (loads numba on first use)

    if compiled_kernel() is None:
        return None
    from . import noise  # noqa: PLC0415  (numba)

    return noise


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
    """Band-limited noisy current of each waveform (docs/physics.md#mc-noise).

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
        Time step [s]; docs/physics.md#time-step asks ``dt <= min(tau / 10, 1 / (20 B))``.
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
    return noisy_band_limited(rng, x, receiver, band, noise)
