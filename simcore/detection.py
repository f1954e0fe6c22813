"""Detection probability and false alarms (Eqs. 27-28), and drawing them for one flash.

The model: docs/physics.md#eq-27, docs/physics.md#eq-28, docs/physics.md#statistical-model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .constants import C


def detection_probability(i_pk_a, threshold_a: float, sigma_pk_a):
    """Eq. 27 (ours): P_d = 0.5 + 0.5 erf((i_pk - V_T) / (sqrt 2 sigma_pk)).

    The threshold V_T = TNR sigma_n is set on signal-free noise; the peak carries its own shot noise
    in sigma_pk. A single look at the peak.
    """
    i = np.asarray(i_pk_a, dtype=np.float64)
    s = np.asarray(sigma_pk_a, dtype=np.float64)
    return 0.5 * special.erfc(-(i - threshold_a) / (np.sqrt(2.0) * s))


def detection_probability_paper(snr, tnr: float):
    """Eq. 27 as printed: 0.5 + 0.5 erf((SNR - TNR) / sqrt 2) (thermal noise only)."""
    return 0.5 * special.erfc(-(np.asarray(snr, dtype=np.float64) - tnr) / np.sqrt(2.0))


def rice_rate_hz(bandwidth_hz: float) -> float:
    """nu0 = sqrt(int f^2 |H|^2 df / int |H|^2 df) = sqrt(2/pi) B for the Gaussian band limit."""
    return np.sqrt(2.0 / np.pi) * bandwidth_hz


def false_alarms_per_pixel(tnr: float, gate_m: float, bandwidth_hz: float) -> float:
    """Eq. 28 (ours, Rice): expected false triggers per pixel per pulse in a gate of R_gate,
    (2 R_gate / c) nu0 exp(-TNR^2 / 2)."""
    return 2.0 * gate_m / C * rice_rate_hz(bandwidth_hz) * np.exp(-(tnr**2) / 2.0)


def false_alarms_per_pixel_paper(tnr: float, gate_m: float, df_hz: float) -> float:
    """Eq. 28 as printed: 2.2 (2 R_gate / c) df 0.5 erfc(TNR / sqrt 2)."""
    return 2.2 * (2.0 * gate_m / C) * df_hz * 0.5 * special.erfc(tnr / np.sqrt(2.0))


@dataclass(frozen=True, kw_only=True)
class Outliers:
    """False-alarm points: pixel (flat index) and range of each [m]."""

    pixel: np.ndarray  # (n_out,) int64
    range_m: np.ndarray  # (n_out,) float64


def draw_outliers(
    rng: np.random.Generator,
    n_pixels_total: int,
    n_false_per_pixel: float,
    gate_center_m: float,
    gate_m: float,
) -> Outliers:
    """Section 4 step 5: N_out ~ Poisson(N_pixels n_false); each on a uniform pixel, at a range
    uniform over the gate [R_st - R_gate/2, R_st + R_gate/2] clipped at 0."""
    n_out = rng.poisson(n_pixels_total * n_false_per_pixel)
    pixel = rng.integers(0, n_pixels_total, size=n_out)
    lo = max(0.0, gate_center_m - gate_m / 2.0)
    hi = gate_center_m + gate_m / 2.0
    return Outliers(pixel=pixel.astype(np.int64), range_m=rng.uniform(lo, hi, size=n_out))
