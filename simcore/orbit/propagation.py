"""Orbital elements <-> ECI states (two-body, optionally with the secular J2 drift) and their
propagation over time (docs/physics.md#table-3). Everything is SI except names ending in ``_deg``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .elements import (
    J2,
    MU_EARTH_M3_S2,
    R_EARTH_M,
    Elements,
    FloatArray,
    OrbitError,
    solve_kepler,
)
from .inputs import time_array, vector3

_CIRCULAR_TOL = 1e-12  # [-] |e| below which state_to_elements reports a circular orbit (e = 0)
_EQUATORIAL_TOL = 1e-12  # [-] sin(i) below which state_to_elements reports an equatorial orbit


def _true_to_mean_anomaly_rad(nu_rad: float, e: float) -> float:
    """Mean anomaly [rad] of true anomaly ``nu_rad`` [rad] on an ellipse of eccentricity e."""
    ecc_anomaly = 2.0 * math.atan2(
        math.sqrt(1.0 - e) * math.sin(nu_rad / 2.0), math.sqrt(1.0 + e) * math.cos(nu_rad / 2.0)
    )
    return ecc_anomaly - e * math.sin(ecc_anomaly)


# ----------------------------------------------------------------------------------------------
# Elements <-> state
# ----------------------------------------------------------------------------------------------
def _states(
    a_m: FloatArray,
    e: FloatArray,
    i_rad: FloatArray,
    raan_rad: FloatArray,
    argp_rad: FloatArray,
    mean_anomaly_rad: FloatArray,
    mu_m3_s2: float,
) -> tuple[FloatArray, FloatArray]:
    """ECI position (n, 3) [m] and velocity (n, 3) [m/s] from (n,) arrays of elements (radians)."""
    ecc_anomaly = solve_kepler(mean_anomaly_rad, e)
    cos_e, sin_e = np.cos(ecc_anomaly), np.sin(ecc_anomaly)
    root = np.sqrt(1.0 - e * e)
    radius_m = a_m * (1.0 - e * cos_e)
    x_pf, y_pf = a_m * (cos_e - e), a_m * root * sin_e  # perifocal position [m]
    speed_scale = np.sqrt(mu_m3_s2 * a_m) / radius_m
    vx_pf, vy_pf = -speed_scale * sin_e, speed_scale * root * cos_e  # perifocal velocity [m/s]

    co, so = np.cos(raan_rad), np.sin(raan_rad)
    cw, sw = np.cos(argp_rad), np.sin(argp_rad)
    ci, si = np.cos(i_rad), np.sin(i_rad)
    # P (towards perigee) and Q (90 deg ahead in the orbit plane) in ECI: R3(-raan) R1(-i) R3(-argp)
    p_hat = np.stack([co * cw - so * sw * ci, so * cw + co * sw * ci, sw * si], axis=-1)
    q_hat = np.stack([-co * sw - so * cw * ci, -so * sw + co * cw * ci, cw * si], axis=-1)
    r_m = x_pf[..., None] * p_hat + y_pf[..., None] * q_hat
    v_m_s = vx_pf[..., None] * p_hat + vy_pf[..., None] * q_hat
    return r_m, v_m_s


def elements_to_state(el: Elements, mu: float = MU_EARTH_M3_S2) -> tuple[FloatArray, FloatArray]:
    """ECI position and velocity at the epoch of the elements (two-body).

    Parameters
    ----------
    el : Elements
        Orbit; its mean anomaly places the satellite.
    mu : float
        Gravitational parameter [m^3/s^2].

    Returns
    -------
    r_m : (3,) float
        Position [m].
    v_m_s : (3,) float
        Velocity [m/s].
    """
    a_m, e, i_rad, raan_rad, argp_rad, m_rad = (np.array([x]) for x in _elements_rad(el))
    r_m, v_m_s = _states(a_m, e, i_rad, raan_rad, argp_rad, m_rad, mu)
    return r_m[0], v_m_s[0]


def _elements_rad(el: Elements) -> tuple[float, float, float, float, float, float]:
    """(a [m], e, i, raan, argp, M [rad]) of ``el``."""
    return (
        el.semi_major_axis_m,
        el.eccentricity,
        math.radians(el.inclination_deg),
        math.radians(el.raan_deg),
        math.radians(el.arg_perigee_deg),
        math.radians(el.mean_anomaly_deg),
    )


def _angle_about(a: FloatArray, b: FloatArray, axis: FloatArray) -> float:
    """Angle [rad] from unit vector a to unit vector b, positive about unit ``axis``; [0, 2 pi)."""
    return math.atan2(float(axis @ np.cross(a, b)), float(a @ b)) % (2.0 * math.pi)


def state_to_elements(r: ArrayLike, v: ArrayLike, mu: float = MU_EARTH_M3_S2) -> Elements:
    """Classical elements of an ECI state (two-body osculating elements).

    Parameters
    ----------
    r : (3,) float
        Position [m].
    v : (3,) float
        Velocity [m/s].
    mu : float
        Gravitational parameter [m^3/s^2].

    Returns
    -------
    Elements
        Angles in [0, 360) deg.

    Raises
    ------
    OrbitError
        Non-finite or mis-shaped input, a rectilinear state (r x v = 0), an open orbit (e >= 1), or
        elements that ``Elements`` rejects (e.g. a <= R_EARTH_M).

    Notes
    -----
    Conventions for the singular cases (the state is always reproduced exactly by
    ``elements_to_state``):

    - circular, e < 1e-12: eccentricity is reported as 0, arg_perigee_deg = 0 and the mean anomaly
      is the argument of latitude (angle from the ascending node);
    - equatorial, sin(i) < 1e-12: raan_deg = 0 (the node is taken on the ECI x axis), so
      arg_perigee_deg is the longitude of perigee for i = 0 and its negative for i = 180 deg;
    - both: raan_deg = arg_perigee_deg = 0 and the mean anomaly is the true longitude (i = 0).
    """
    r_m = vector3(r, "r")
    v_m_s = vector3(v, "v")
    radius_m = float(np.linalg.norm(r_m))
    if radius_m == 0.0:
        raise OrbitError("r must be non-zero")
    h_vec = np.cross(r_m, v_m_s)
    h_norm = float(np.linalg.norm(h_vec))
    if h_norm <= 1e-12 * radius_m * float(np.linalg.norm(v_m_s)):
        raise OrbitError("r and v are parallel (rectilinear orbit): no orbit plane")
    h_hat = h_vec / h_norm
    speed2 = float(v_m_s @ v_m_s)
    inv_a = 2.0 / radius_m - speed2 / mu
    e_vec = ((speed2 - mu / radius_m) * r_m - float(r_m @ v_m_s) * v_m_s) / mu
    e = float(np.linalg.norm(e_vec))
    if inv_a <= 0.0 or e >= 1.0:
        raise OrbitError(
            f"eccentricity of this state is {e:.6g} >= 1 (parabolic or hyperbolic): not supported"
        )

    inclination = math.atan2(math.hypot(h_vec[0], h_vec[1]), h_vec[2])
    node = np.array([-h_vec[1], h_vec[0], 0.0])  # z_hat x h
    node_norm = float(np.linalg.norm(node))
    if node_norm <= _EQUATORIAL_TOL * h_norm:
        raan = 0.0
        node_hat = np.array([1.0, 0.0, 0.0])
    else:
        raan = math.atan2(node[1], node[0]) % (2.0 * math.pi)
        node_hat = node / node_norm
    if e < _CIRCULAR_TOL:
        e = 0.0
        argp = 0.0
        perigee_hat = node_hat
    else:
        perigee_hat = e_vec / e
        argp = _angle_about(node_hat, perigee_hat, h_hat)
    nu = _angle_about(perigee_hat, r_m / radius_m, h_hat)
    mean_anomaly = _true_to_mean_anomaly_rad(nu, e) % (2.0 * math.pi)
    return Elements(
        semi_major_axis_m=1.0 / inv_a,
        eccentricity=e,
        inclination_deg=math.degrees(inclination),
        raan_deg=math.degrees(raan) % 360.0,
        arg_perigee_deg=math.degrees(argp) % 360.0,
        mean_anomaly_deg=math.degrees(mean_anomaly) % 360.0,
    )


# ----------------------------------------------------------------------------------------------
# Propagation
# ----------------------------------------------------------------------------------------------
def j2_secular_rates_rad_s(el: Elements) -> tuple[float, float, float]:
    """First-order secular J2 rates of RAAN, argument of perigee and mean anomaly.

    Parameters
    ----------
    el : Elements
        Orbit, read as MEAN elements.

    Returns
    -------
    raan_rate, arg_perigee_rate, mean_anomaly_rate : float
        [rad/s]; the last includes the Keplerian mean motion n = sqrt(mu/a**3).

    Notes
    -----
    The standard first-order results (e.g. Vallado, Fundamentals of Astrodynamics and
    Applications, section 9.6), with k = (3/2) * n * J2 * (R_EARTH_M / p)**2 and
    p = a*(1 - e**2)::

        dRAAN/dt = -k * cos(i)
        dargp/dt =  k * (2 - 2.5 * sin(i)**2)
        dM/dt    =  n + k * sqrt(1 - e**2) * (1 - 1.5 * sin(i)**2)
    """
    a_m, e, i_rad = el.semi_major_axis_m, el.eccentricity, math.radians(el.inclination_deg)
    n = math.sqrt(MU_EARTH_M3_S2 / a_m**3)
    p_m = a_m * (1.0 - e * e)
    k = 1.5 * n * J2 * (R_EARTH_M / p_m) ** 2
    sin2 = math.sin(i_rad) ** 2
    raan_rate = -k * math.cos(i_rad)
    argp_rate = k * (2.0 - 2.5 * sin2)
    mean_anomaly_rate = n + k * math.sqrt(1.0 - e * e) * (1.0 - 1.5 * sin2)
    return raan_rate, argp_rate, mean_anomaly_rate


def propagate(el: Elements, t_s: ArrayLike, j2: bool = False) -> tuple[FloatArray, FloatArray]:
    """ECI states at times ``t_s`` after the epoch of ``el``.

    Parameters
    ----------
    el : Elements
        Orbit at t = 0.
    t_s : (n,) float
        Times since the epoch [s], finite (a scalar is read as one time).
    j2 : bool
        False: two-body motion, the mean anomaly advances at n = sqrt(mu/a**3). True: the elements
        are read as mean elements and RAAN, argument of perigee and mean anomaly advance at the
        first-order secular J2 rates (``j2_secular_rates_rad_s``); a, e and i stay constant and the
        short-period J2 terms (about 10 km in position in LEO, but common to two close satellites)
        are not modelled.

    Returns
    -------
    r_m : (n, 3) float
        Positions [m].
    v_m_s : (n, 3) float
        Velocities [m/s] of the osculating ellipse at each time (for j2=True this omits the slow
        drift of the orbit plane and perigee: relative error ~J2, fine for attitudes).
    """
    t = time_array(t_s, allow_empty=True)
    a_m, e, i_rad, raan0, argp0, m0 = _elements_rad(el)
    if j2:
        raan_rate, argp_rate, m_rate = j2_secular_rates_rad_s(el)
    else:
        raan_rate, argp_rate, m_rate = 0.0, 0.0, math.sqrt(MU_EARTH_M3_S2 / a_m**3)
    ones = np.ones_like(t)
    return _states(
        a_m * ones,
        e * ones,
        i_rad * ones,
        raan0 + raan_rate * t,
        argp0 + argp_rate * t,
        m0 + m_rate * t,
        MU_EARTH_M3_S2,
    )
