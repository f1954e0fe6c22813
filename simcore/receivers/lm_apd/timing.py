"""Timing: half-maximum ranging, the constant-fraction discriminator and range errors
(Eqs. 19, 24-26, 31).

The model: docs/physics.md#detection (docs/physics.md#eq-19, docs/physics.md#eq-24,
docs/physics.md#eq-25, docs/physics.md#eq-26, docs/physics.md#eq-31).

"""

from __future__ import annotations

import numpy as np

from ...constants import C
from ...pulse import PulseShape
from ...pulse import cfd_delay_s as cfd_delay_s  # the pulse's own timing (the echo stage's too)


def range_from_half_max_m(t_half_echo_s, t_half_ref_s: float):
    """Eq. 31 (corrected order): R = (c/2) (t_half[y] - t_half[y0])   [m]."""
    return 0.5 * C * (np.asarray(t_half_echo_s) - t_half_ref_s)


def noise_autocorrelation(lag_s: float, sigma_h_s: float) -> float:
    """rho_n(lag) of white noise through the Gaussian band limit: exp(-lag^2 / (4 sigma_h^2))."""
    return float(np.exp(-(lag_s**2) / (4.0 * sigma_h_s**2)))


def sigma_cfd_per_sample_m(
    i_pk_a,
    sigma_delayed_a,
    sigma_prompt_a,
    slope_per_s,
    cfd_fraction: float,
    delay_s: float,
    sigma_h_s: float,
    sigma_mid_a=None,
):
    """Eq. 25 (ours), each CFD sample with its own noise   [m]:

    (c/2) sqrt(sig_a^2 + k^2 sig_b^2 - 2 k rho_n(t_d) sig_m^2) / (i_pk |ds/dt|)

    with sig_a the noise of the delayed sample y(t* - t_d), sig_b that of y(t*), k the CFD
    fraction and rho_n(t_d) the noise autocorrelation at the CFD delay ``delay_s`` [s]. The
    noise of s = y(t - t_d) - k y(t) is n(t* - t_d) - k n(t*); the crossing moves by its rms over
    the slope. The covariance of the two samples is rho_n sig_m^2: for white noise through the
    Gaussian h_B, shot noise included, sig_m is the noise of the current midway between the
    samples (``sigma_mid_a``); without it sig_m^2 = sig_a sig_b (PHYSICS row 25's form, 5-13 %
    above the Monte Carlo at SNR 20-200 with the default receiver). With sig_a = sig_b = sig_m
    = i_pk / SNR it is :func:`sigma_cfd_m` exactly.

    i_pk_a : (n,) band-limited peak signal current [A]
    sigma_delayed_a, sigma_prompt_a : (n,) noise currents at the two samples [A rms] (each with
        the shot noise of its own current, and any other per-pixel noise the caller adds, such
        as a background's)
    sigma_mid_a : (n,) noise current midway between the samples [A rms], optional
    slope_per_s : (n,) |ds/dt| of the peak-normalised CFD signal at its firing time [1/s]
    Zero current or slope gives inf (the pixel is then not detected anyway).
    """
    rho = noise_autocorrelation(delay_s, sigma_h_s)
    sa = np.asarray(sigma_delayed_a, dtype=np.float64)
    sb = np.asarray(sigma_prompt_a, dtype=np.float64)
    k = cfd_fraction
    cov = sa * sb if sigma_mid_a is None else np.asarray(sigma_mid_a, dtype=np.float64) ** 2
    var = np.maximum(sa**2 + k**2 * sb**2 - 2.0 * k * rho * cov, 0.0)
    den = np.asarray(i_pk_a, dtype=np.float64) * np.asarray(slope_per_s, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, 0.5 * C * np.sqrt(var) / np.where(den > 0, den, 1.0), np.inf)


def sigma_cfd_m(snr, slope_per_s, cfd_fraction: float, delay_s: float, sigma_h_s: float):
    """Eq. 25 with equal noise at both CFD samples (the paper form ``eq25_equal_noise``):
    (c/2) sqrt(1 + k^2 - 2 k rho_n(t_d)) / (SNR |ds/dt|)   [m], k the CFD fraction, t_d =
    ``delay_s`` the CFD delay [s]. The noise of the peak at both samples: pessimistic where the
    signal's shot noise matters (docs/physics.md#paper-form-eq25_equal_noise).

    snr : (n,) SNR_na; slope_per_s : (n,) |ds/dt| of the peak-normalised CFD signal at its firing
    time. Zero SNR or slope gives inf (the pixel is then not detected anyway).
    """
    rho = noise_autocorrelation(delay_s, sigma_h_s)
    num = 0.5 * C * np.sqrt(1.0 + cfd_fraction**2 - 2.0 * cfd_fraction * rho)
    den = np.asarray(snr, dtype=np.float64) * np.asarray(slope_per_s, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)


def sigma_cfd_paper_m(snr, cfd_fraction: float, rise_time_s: float):
    """Eq. 25 as printed: c tau_r sqrt(1 + k^2) / (SNR (1 - k))   [m] (with c, not c/2)."""
    snr = np.asarray(snr, dtype=np.float64)
    k = cfd_fraction
    num = C * rise_time_s * np.sqrt(1.0 + k**2) / (1.0 - k) if k < 1 else np.inf
    with np.errstate(divide="ignore"):
        return np.where(snr > 0, num / np.where(snr > 0, snr, 1.0), np.inf)


def rise_time_10_90_s(shape: PulseShape) -> float:
    """10-90 % rise time of the band-limited pulse, the signal the discriminator sees: the tau_r
    of the paper's Eq. 25 (2.76 ns for 5 ns at 120 MHz; with it the paper's form is 2.4x ours
    even with c/2, docs/physics.md#eq-25)."""
    return shape.rise_time_10_90_s


def sigma_quantisation_m(resolution_s: float) -> float:
    """Eq. 26: c T_t / (2 sqrt 6), start and stop each uniform over T_t (6.12 mm at 100 ps)."""
    return C * resolution_s / (2.0 * np.sqrt(6.0))


def range_sigma_m(sigma_cfd, sigma_t: float):
    """Eq. 24: total range noise sqrt(sigma_cfd^2 + sigma_t^2)   [m]."""
    return np.sqrt(np.asarray(sigma_cfd) ** 2 + sigma_t**2)
