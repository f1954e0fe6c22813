"""The transmitted beam: irradiance per transmitted watt across the illuminated spot (Eqs. 4, 5).

The model: docs/physics.md#illumination.
"""

from __future__ import annotations

import numpy as np


def illumination_gain(directions, theta_ill_rad: float, model: str):
    """Irradiance per transmitted watt at unit range, E_in r^2 / (eta_t P0)   [1/sr].

    flat_top (Eq. 5): 4 / (pi theta^2) inside the cone of full angle theta, else 0.
    square: 1 / theta^2 where |x/z|, |y/z| <= tan(theta/2).
    gaussian (Eq. 4): 8 / (pi theta^2) exp(-8 alpha^2 / theta^2), theta the full 1/e^2 angle.

    directions : (..., 3) unit vectors in the sensor frame.
    """
    d = np.asarray(directions)
    cos_a = np.clip(d[..., 2], -1.0, 1.0)
    if model == "flat_top":
        lit = cos_a >= np.cos(theta_ill_rad / 2.0)
        return np.where(lit, 4.0 / (np.pi * theta_ill_rad**2), 0.0)
    if model == "square":
        t = np.tan(theta_ill_rad / 2.0)
        lit = (np.abs(d[..., 0]) <= t * d[..., 2]) & (np.abs(d[..., 1]) <= t * d[..., 2])
        return np.where(lit, 1.0 / theta_ill_rad**2, 0.0)
    if model == "gaussian":
        alpha = np.arccos(cos_a)
        return 8.0 / (np.pi * theta_ill_rad**2) * np.exp(-8.0 * alpha**2 / theta_ill_rad**2)
    raise ValueError(f"unknown illumination model {model!r}")
