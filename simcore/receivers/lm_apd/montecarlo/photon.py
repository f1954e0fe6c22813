"""Photon statistics for the waveform Monte Carlo, ``fidelity.noise_model = "photon"``
(docs/physics.md#mcintyre): Poisson primary electrons, each multiplied by a gain drawn from
McIntyre's distribution (McIntyre, "The distribution of gains in uniformly multiplying avalanche
photodiodes: theory", IEEE Trans. Electron Devices ED-19, 703-713, 1972) for the APD's
ionisation ratio k and mean gain M, instead of Gaussian shot noise.

What changes against the Gaussian Monte Carlo (``montecarlo``):

- the signal's shot noise: the photoelectrons of each time sample are Poisson with mean
  ``i_s dt / (q M)`` and each carries a McIntyre gain; the sample's current is ``q sum g / dt``;
- the bulk dark current, multiplied like the signal: Poisson primaries at ``I_db / q`` per second
  over the whole gate of every pixel, each a McIntyre gain, its mean ``I_db M`` removed (the
  Gaussian model's noise has zero mean too);
- what stays Gaussian: the surface dark current and thermal noise (not multiplied), and the
  amplifiers' added share of the multiplied noise, ``(F_chain - 1)`` times its density.

Second moments are the Gaussian model's exactly (Eqs. 10-13, 17); the higher moments are the
skewed gain's. Gains are drawn exactly, by inverting the tabulated distribution; the sum of more
than :data:`EXACT_SUM` gains in one sample is drawn from the normal law with its mean and variance
(its skewness falls as 1 / sqrt(n); at such counts the Gaussian model is right anyway).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special

from ..apd import Q_E, ReceiverModel

EXACT_SUM = 64  # photoelectrons per sample whose gains are summed one by one
TAIL_MASS = 1e-12  # the table stops where less than this much probability is left
MAX_TABLE = 1 << 22  # gains tabulated at most (32 MB)
MAX_TRUNCATED = 1e-6  # refused if the table must leave more of the tail than this
# Poisson means above this are drawn from the normal law (skewness 1 / sqrt(mean) = 3e-8):
# numpy's Poisson refuses means past about 9.2e18, which a joule-class pulse at a metre reaches
# (a sample's primaries), and its counts no longer fit an int64
EXACT_POISSON = 1e15


def mcintyre_log_pmf(n, gain: float, k: float):
    """log P(n), n >= 1 electrons out of one injected electron, for mean gain M and ionisation
    ratio k: McIntyre's distribution (1972), written as the generalised negative binomial

        P(n) = (1/n) C(n / (1 - k), n - 1) theta^(n-1) (1 - theta)^(1 + k n / (1 - k)),
        theta = (1 - k)(M - 1) / M,

    (C the binomial coefficient through Gamma functions): normalised, mean M, excess noise factor
    E[n^2] / M^2 = k M + (1 - k)(2 - 1/M) (Eq. 11); at k = 0 the geometric law of a
    single-carrier avalanche, P(n) = (1/M)(1 - 1/M)^(n-1)."""
    n = np.asarray(n, dtype=np.float64)
    if gain <= 1.0:
        return np.where(n == 1.0, 0.0, -np.inf)
    m = 1.0 / (1.0 - k)
    theta = (1.0 - k) * (gain - 1.0) / gain
    t = m * n
    return (
        -np.log(n)
        + special.gammaln(t + 1.0)
        - special.gammaln(n)
        - special.gammaln(t - n + 2.0)
        + (n - 1.0) * math.log(theta)
        + (t - n + 1.0) * math.log1p(-theta)
    )


@lru_cache(maxsize=8)
def mcintyre_cdf(gain: float, k: float) -> np.ndarray:
    """CDF of McIntyre's distribution at n = 1, 2, ... up to where the tail left is below
    TAIL_MASS (renormalised to end at 1). Raises ValueError where more than MAX_TRUNCATED of it
    lies beyond MAX_TABLE gains (M k of several hundred: such APDs are not linear-mode)."""
    if not 0.0 <= k < 1.0:
        raise ValueError(f"McIntyre's distribution needs 0 <= k < 1, got k = {k!r}")
    size = 1 << 12
    while True:
        n = np.arange(1, size + 1, dtype=np.float64)
        cdf = np.cumsum(np.exp(mcintyre_log_pmf(n, gain, k)))
        left = 1.0 - cdf[-1]
        if left < TAIL_MASS or size >= MAX_TABLE:
            break
        size *= 4
    if left > MAX_TRUNCATED:
        raise ValueError(
            f"McIntyre's distribution at gain {gain:.4g} and k = {k:g} has {left:.2g} of its "
            f"probability beyond {size} electrons: too wide to draw"
        )
    cdf /= cdf[-1]
    cdf.setflags(write=False)
    return cdf


def sample_gains(rng: np.random.Generator, size: int, gain: float, k: float) -> np.ndarray:
    """(size,) gains drawn from McIntyre's distribution by inverting its CDF (exact to the
    table's TAIL_MASS)."""
    cdf = mcintyre_cdf(float(gain), float(k))
    return (np.searchsorted(cdf, rng.random(size), side="right") + 1).astype(np.float64)


def poisson_counts(rng: np.random.Generator, mean) -> np.ndarray:
    """Poisson counts of ``mean`` (float64 where a mean passes EXACT_POISSON, drawn from the
    normal law of the same mean and variance, rounded, never below 0; otherwise numpy's exact
    int64 draws, the same stream as ``rng.poisson(mean)``)."""
    mean = np.asarray(mean, dtype=np.float64)
    large = mean > EXACT_POISSON
    if not large.any():
        return rng.poisson(mean)
    counts = np.empty(mean.shape)
    counts[~large] = rng.poisson(mean[~large])
    big = mean[large]
    counts[large] = np.maximum(0.0, np.rint(big + np.sqrt(big) * rng.standard_normal(big.shape)))
    return counts


def sum_of_gains(rng: np.random.Generator, counts, gain: float, k: float) -> np.ndarray:
    """Sum of ``counts[i]`` independent McIntyre gains for each i: drawn one by one up to
    EXACT_SUM, from the normal law of mean n M and variance n M^2 (F - 1) above."""
    counts = np.asarray(counts)  # int64, or float64 past what an int64 holds
    out = np.zeros(len(counts))
    few = np.flatnonzero((counts > 0) & (counts <= EXACT_SUM))
    if len(few):
        n_few = counts[few].astype(np.int64)
        g = sample_gains(rng, int(n_few.sum()), gain, k)
        owner = np.repeat(few, n_few)
        out += np.bincount(owner, weights=g, minlength=len(counts))
    many = np.flatnonzero(counts > EXACT_SUM)
    if len(many):
        f = k * gain + (1.0 - k) * (2.0 - 1.0 / gain)
        n = counts[many].astype(np.float64)
        out[many] = n * gain + np.sqrt(n * gain * gain * (f - 1.0)) * rng.standard_normal(len(n))
    return out


@dataclass(frozen=True)
class PhotonNoise:
    """The photon-level noise of one receiver: its gain M, ionisation ratio k and the primary
    bulk dark current I_db [A]."""

    k: float
    dark_bulk_a: float

    def gaussian_sigma_a(self, receiver: ReceiverModel, dt_s: float) -> float:
        """The white samples' std of what stays Gaussian [A]: S / (2 dt) with the density of
        sigma_n less the bulk dark shot noise that is drawn photon by photon, plus the
        amplifiers' (F_chain - 1) share of it."""
        m, f = receiver.gain, receiver.excess_noise
        dark_density = 2.0 * Q_E * self.dark_bulk_a * m * m * f  # [A^2/Hz]
        density = receiver.sigma_n_a**2 / receiver.bandwidth_hz - dark_density
        return math.sqrt(max(density, 0.0) / (2.0 * dt_s))

    def add_noise(self, rng, white, x, dt_s: float, receiver: ReceiverModel) -> None:
        """Add, IN PLACE to ``white`` (n, L) (which holds the Gaussian part), the signal's
        photon noise where the signal current ``x`` (n, L) [A] is positive and the photon-level
        bulk dark current over every sample (module docstring)."""
        m, f, fc = receiver.gain, receiver.excess_noise, receiver.chain_noise_factor
        r, c = np.nonzero(x > 0)
        if len(r):
            i_s = x[r, c].astype(np.float64)
            primaries = poisson_counts(rng, i_s * dt_s / (Q_E * m))
            current = Q_E * sum_of_gains(rng, primaries, m, self.k) / dt_s
            excess_var = (fc - 1.0) * 2.0 * Q_E * m * f * i_s / (2.0 * dt_s)
            white[r, c] += current - i_s + np.sqrt(excess_var) * rng.standard_normal(len(r))
        rate_hz = self.dark_bulk_a / Q_E
        if rate_hz > 0:
            n_rows, n_cols = white.shape
            counts = rng.poisson(rate_hz * n_cols * dt_s, size=n_rows)
            total = int(counts.sum())
            rows = np.repeat(np.arange(n_rows), counts)
            cols = rng.integers(0, n_cols, size=total)
            gains = sample_gains(rng, total, m, self.k)
            np.add.at(white, (rows, cols), (Q_E / dt_s * gains).astype(white.dtype))
            white -= white.dtype.type(self.dark_bulk_a * m)
