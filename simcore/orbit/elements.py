"""Orbital elements: the Earth's constants, the paper's Table 3 orbits and Kepler's equation.

The orbits package (``simcore.orbit``) models the target and the imaging satellite: these elements,
their propagation to ECI states (``orbit.propagation``), the attitudes and the relative pose series
of a fly-around (``orbit.attitude``), and the UTC epochs and two-line element sets a scene gives
(``orbit.epoch``, ``orbit.tle``; docs/physics.md#table-3).

Frames
------
ECI
    Earth-centred inertial; the elements are referred to its equator and x axis.
Target body (= target LVLH)
    z towards the Earth's centre (-r_hat), y = -(orbit normal), x = y x z (along the velocity for a
    circular orbit). Three-axis stabilised: the target body frame IS its LVLH frame.
Lidar sensor
    z = boresight (towards the target's body origin), x = image right (columns), y = image down
    (rows), right-handed. Roll: y is the part of the nadir direction perpendicular to z.

Everything is SI (metres, seconds, radians) except names ending in ``_deg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike, NDArray

# ----------------------------------------------------------------------------------------------
# Constants
# ----------------------------------------------------------------------------------------------
MU_EARTH_M3_S2 = 3.986004418e14  # [m^3/s^2] Earth's GM, WGS84 (G-2/EGM96 value)
R_EARTH_M = 6378137.0  # [m] Earth's equatorial radius, WGS84 semi-major axis
J2 = 1.08262668e-3  # [-] unnormalised second zonal harmonic, WGS84 / EGM96

_KEPLER_TOL_RAD = 1e-14  # [rad] Newton step below which Kepler's equation counts as solved
_KEPLER_MAX_ITER = 60  # [-] iteration cap; monotone Newton needs < 10 for e <= 0.99 in practice

FloatArray = NDArray[np.float64]


class OrbitError(ValueError):
    """Invalid orbital input: the message names the offending argument or element and its range."""


# ----------------------------------------------------------------------------------------------
# Elements
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Elements:
    """Classical (Keplerian) elements of a closed orbit about the Earth, referred to ECI.

    Parameters
    ----------
    semi_major_axis_m : float
        Semi-major axis a [m]; must exceed R_EARTH_M.
    eccentricity : float
        e, 0 <= e < 1 (parabolic and hyperbolic orbits are not supported).
    inclination_deg : float
        i [deg], 0 <= i <= 180.
    raan_deg : float
        Right ascension of the ascending node [deg], any finite value (periodic).
    arg_perigee_deg : float
        Argument of perigee [deg], any finite value (periodic).
    mean_anomaly_deg : float
        Mean anomaly at t = 0 [deg], any finite value (periodic).

    Notes
    -----
    Only a > R_EARTH_M is enforced: a perigee a*(1 - e) below the surface is allowed (textbook
    examples use such orbits); it is the caller's business.
    """

    semi_major_axis_m: float
    eccentricity: float
    inclination_deg: float
    raan_deg: float
    arg_perigee_deg: float
    mean_anomaly_deg: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise OrbitError(f"{f.name} must be a real number, got {value!r}") from None
            if isinstance(value, bool) or not math.isfinite(number):
                raise OrbitError(f"{f.name} must be a finite real number, got {value!r}")
            object.__setattr__(self, f.name, number)
        if not self.semi_major_axis_m > R_EARTH_M:
            raise OrbitError(
                f"semi_major_axis_m must be > R_EARTH_M = {R_EARTH_M} m (an orbit above the "
                f"Earth's surface), got {self.semi_major_axis_m} m (did you give kilometres?)"
            )
        if not 0.0 <= self.eccentricity < 1.0:
            raise OrbitError(
                f"eccentricity must be in [0, 1) (closed orbits only; parabolic and hyperbolic "
                f"orbits are not supported), got {self.eccentricity}"
            )
        if not 0.0 <= self.inclination_deg <= 180.0:
            raise OrbitError(f"inclination_deg must be in [0, 180] deg, got {self.inclination_deg}")

    @property
    def period_s(self) -> float:
        """Two-body (Keplerian) orbital period 2*pi*sqrt(a**3/mu) [s] for MU_EARTH_M3_S2."""
        return 2.0 * math.pi * math.sqrt(self.semi_major_axis_m**3 / MU_EARTH_M3_S2)


# Table 3 of the paper (a in km there). Columns of the paper: a, e, i, argp, RAAN, M.
PAPER_TARGET = Elements(
    semi_major_axis_m=7073.22e3,
    eccentricity=0.001521,
    inclination_deg=98.105,
    raan_deg=314.880,
    arg_perigee_deg=60.047,
    mean_anomaly_deg=164.242,
)
PAPER_IMAGING = Elements(
    semi_major_axis_m=7073.22e3,
    eccentricity=0.001535,
    inclination_deg=98.104,
    raan_deg=314.881,
    arg_perigee_deg=59.904,
    mean_anomaly_deg=164.385,
)
# The paper's orbital period (from its orbit software). The two-body period of Table 3's a with
# MU_EARTH_M3_S2 is 5920.20 s: the paper's value is 4.32 s (0.073 %) longer. With the first-order
# secular J2 rates below, this orbit's anomalistic period is 5923.88 s and its nodal period
# 5927.41 s, so the paper's figure fits a model with J2 (its a may also be a mean, not osculating,
# value).
PAPER_PERIOD_S = 5924.521


# ----------------------------------------------------------------------------------------------
# Kepler's equation
# ----------------------------------------------------------------------------------------------
def solve_kepler(mean_anomaly_rad: ArrayLike, e: ArrayLike) -> FloatArray:
    """Eccentric anomaly E solving Kepler's equation E - e*sin(E) = M.

    Parameters
    ----------
    mean_anomaly_rad : (...) float
        Mean anomaly M [rad], any finite value.
    e : (...) float
        Eccentricity, 0 <= e < 1; broadcast against ``mean_anomaly_rad``.

    Returns
    -------
    (...) float
        Eccentric anomaly E [rad], on the same revolution as M (E - M is in [-pi, pi]).

    Notes
    -----
    M is reduced to m in [-pi, pi] and solved for abs(m) in [0, pi], where
    f(E) = E - e*sin(E) - abs(m) is increasing and convex (f'' = e*sin(E) >= 0). Newton's method
    started at E0 = min(abs(m) + e, pi), where f(E0) >= 0, then converges monotonically from above
    for every 0 <= e < 1 (no overshoot, no divergence near e -> 1), quadratically near the root.
    It stops once every step is below 1e-14 rad (cap: 60 iterations). For e = 0 it returns M
    exactly.
    """
    m_all = np.asarray(mean_anomaly_rad, dtype=float)
    e_all = np.asarray(e, dtype=float)
    if not np.all(np.isfinite(m_all)):
        raise OrbitError("mean_anomaly_rad must be finite")
    if not np.all(np.isfinite(e_all)) or np.any(e_all < 0.0) or np.any(e_all >= 1.0):
        raise OrbitError("e (eccentricity) must be finite and in [0, 1)")
    m_all, e_all = np.broadcast_arrays(m_all, e_all)
    m_red = np.remainder(m_all + np.pi, 2.0 * np.pi) - np.pi  # [-pi, pi)
    m_abs = np.abs(m_red)
    ecc_anomaly = np.minimum(m_abs + e_all, np.pi)
    for _ in range(_KEPLER_MAX_ITER):
        step = (ecc_anomaly - e_all * np.sin(ecc_anomaly) - m_abs) / (
            1.0 - e_all * np.cos(ecc_anomaly)
        )
        ecc_anomaly = ecc_anomaly - step
        if not np.any(np.abs(step) > _KEPLER_TOL_RAD):
            break
    return np.copysign(ecc_anomaly, m_red) + (m_all - m_red)
