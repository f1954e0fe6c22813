"""Orbits of the target and the imaging satellite, their attitudes and the relative pose series.

Keplerian elements -> ECI states (two-body, optionally with the secular J2 drift), the target's
three-axis stabilised LVLH attitude, the lidar's tracking attitude and, from the two, the pose of
the target body in the lidar sensor frame over a fly-around (docs/physics.md#table-3).

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
from scipy.spatial.transform import Rotation

__all__ = [
    "J2",
    "MU_EARTH_M3_S2",
    "PAPER_IMAGING",
    "PAPER_PERIOD_S",
    "PAPER_TARGET",
    "R_EARTH_M",
    "Elements",
    "OrbitError",
    "RelativePose",
    "distance_stats",
    "elements_to_state",
    "flyaround_times",
    "j2_secular_rates_rad_s",
    "lvlh_attitude",
    "propagate",
    "relative_pose_from_states",
    "relative_pose_series",
    "solve_kepler",
    "state_to_elements",
    "tracking_attitude",
]

# ----------------------------------------------------------------------------------------------
# Constants
# ----------------------------------------------------------------------------------------------
MU_EARTH_M3_S2 = 3.986004418e14  # [m^3/s^2] Earth's GM, WGS84 (G-2/EGM96 value)
R_EARTH_M = 6378137.0  # [m] Earth's equatorial radius, WGS84 semi-major axis
J2 = 1.08262668e-3  # [-] unnormalised second zonal harmonic, WGS84 / EGM96

_KEPLER_TOL_RAD = 1e-14  # [rad] Newton step below which Kepler's equation counts as solved
_KEPLER_MAX_ITER = 60  # [-] iteration cap; monotone Newton needs < 10 for e <= 0.99 in practice
_CIRCULAR_TOL = 1e-12  # [-] |e| below which state_to_elements reports a circular orbit (e = 0)
_EQUATORIAL_TOL = 1e-12  # [-] sin(i) below which state_to_elements reports an equatorial orbit
_PARALLEL_TOL = 1e-6  # [rad] nadir within this angle of the boresight: roll falls back to -h_hat

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
    r_m = _vector3(r, "r")
    v_m_s = _vector3(v, "v")
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
    t = _times(t_s, allow_empty=True)
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


# ----------------------------------------------------------------------------------------------
# Attitudes
# ----------------------------------------------------------------------------------------------
def _unit(x: FloatArray, name: str) -> FloatArray:
    """Rows of (n, 3) ``x`` normalised; OrbitError if any row is zero."""
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise OrbitError(f"{name} has a zero-length vector: its direction is undefined")
    return x / norm


def lvlh_attitude(r: ArrayLike, v: ArrayLike) -> FloatArray:
    """Attitude of a three-axis stabilised, nadir-pointing satellite (its LVLH frame).

    Parameters
    ----------
    r : (n, 3) or (3,) float
        ECI position [m].
    v : (n, 3) or (3,) float
        ECI velocity [m/s].

    Returns
    -------
    (n, 3, 3) float
        Rotation matrices whose COLUMNS are the body axes in ECI: z = -r_hat (towards the Earth's
        centre), y = -h_hat (minus the orbit normal, h = r x v), x = y x z (the horizontal
        direction of motion; along v for a circular orbit). p_eci = M @ p_body for directions.
    """
    r_m = _rows3(r, "r")
    v_m_s = _rows3(v, "v")
    z = -_unit(r_m, "r")
    y = -_unit(np.cross(r_m, v_m_s), "r x v (orbit normal)")
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def tracking_attitude(r_lidar: ArrayLike, r_target: ArrayLike, v_lidar: ArrayLike) -> FloatArray:
    """Attitude of a lidar that keeps its boresight on the target, "down" in the image to the Earth.

    Parameters
    ----------
    r_lidar : (n, 3) or (3,) float
        ECI position of the lidar [m].
    r_target : (n, 3) or (3,) float
        ECI position of the target's body origin [m].
    v_lidar : (n, 3) or (3,) float
        ECI velocity of the lidar [m/s] (only for the fallback roll reference).

    Returns
    -------
    (n, 3, 3) float
        Rotation matrices whose COLUMNS are the sensor axes in ECI: z = unit(r_target - r_lidar)
        (boresight), y = image down = the component of the nadir direction -r_lidar_hat
        perpendicular to z, normalised, x = y x z (image right). Where the nadir is within 1e-6 rad
        of +-z, y is instead the component of -(orbit normal of the lidar) perpendicular to z.
        The roll flips by 180 deg when the line of sight crosses the vertical (nadir or zenith).
    """
    r_l = _rows3(r_lidar, "r_lidar")
    r_t = _rows3(r_target, "r_target")
    v_l = _rows3(v_lidar, "v_lidar")
    r_l, r_t, v_l = np.broadcast_arrays(r_l, r_t, v_l)
    z = _unit(r_t - r_l, "r_target - r_lidar (lidar and target coincide)")
    nadir = -_unit(r_l, "r_lidar")
    y = nadir - np.sum(nadir * z, axis=-1, keepdims=True) * z
    parallel = np.linalg.norm(y, axis=-1) < _PARALLEL_TOL
    if np.any(parallel):
        normal = -_unit(np.cross(r_l[parallel], v_l[parallel]), "r_lidar x v_lidar")
        zp = z[parallel]
        y[parallel] = normal - np.sum(normal * zp, axis=-1, keepdims=True) * zp
    y = _unit(y, "roll reference (orbit normal along the boresight)")
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


# ----------------------------------------------------------------------------------------------
# Relative pose
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RelativePose:
    """Pose of the target body in the lidar sensor frame over time (read-only arrays).

    Attributes
    ----------
    t_s : (n,) float
        Times since the epoch [s].
    distance_m : (n,) float
        Distance from the lidar to the target's body origin [m].
    quaternion_wxyz : (n, 4) float
        Unit quaternion, scalar first, of the active rotation that maps target-BODY coordinates to
        lidar-SENSOR coordinates: p_sensor = R @ p_body + (0, 0, distance_m). Signs are chosen
        continuous in time (the first has w >= 0), so the series can be interpolated.
    rotation : (n, 3, 3) float
        The same rotations R as matrices (rows: sensor axes in body coordinates).
    angles_deg : (n, 3) float
        R as intrinsic x-y'-z'' Euler angles [deg] (scipy ``as_euler("XYZ")``):
        R = Rx(a0) @ Ry(a1) @ Rz(a2). For the tracking geometry the sensor x axis stays
        perpendicular to the target's z axis (both orbits share nadir to ~separation/r), so a1 stays
        near 0, far from the gimbal lock at +-90 deg; a0 and a2 wrap at +-180 deg.
    relative_position_lvlh_m : (n, 3) float
        Imaging satellite minus target position, in the target's LVLH (= body) frame [m].
    """

    t_s: FloatArray
    distance_m: FloatArray
    quaternion_wxyz: FloatArray
    rotation: FloatArray
    angles_deg: FloatArray
    relative_position_lvlh_m: FloatArray

    def __post_init__(self) -> None:
        for f in fields(self):
            array = np.array(getattr(self, f.name), dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, f.name, array)


def relative_pose_series(
    target: Elements, imaging: Elements, t_s: ArrayLike, j2: bool = False
) -> RelativePose:
    """Pose of the nadir-pointing target in the frame of the tracking lidar at each time.

    Parameters
    ----------
    target : Elements
        Orbit of the target (three-axis stabilised, body frame = its LVLH frame).
    imaging : Elements
        Orbit of the imaging satellite carrying the lidar (tracking attitude).
    t_s : (n,) float
        Times since the common epoch [s]; finite, at least one.
    j2 : bool
        Propagate with the secular J2 rates (see ``propagate``).

    Returns
    -------
    RelativePose
        With rotation R = S.T @ B, B = ``lvlh_attitude`` of the target and S = ``tracking_attitude``
        of the lidar (both with columns = axes in ECI).
    """
    t = _times(t_s, allow_empty=False)
    r_tgt, v_tgt = propagate(target, t, j2=j2)
    r_img, v_img = propagate(imaging, t, j2=j2)
    return relative_pose_from_states(t, r_tgt, v_tgt, r_img, v_img)


def relative_pose_from_states(t_s, r_tgt, v_tgt, r_img, v_img) -> RelativePose:
    """The pose series of :func:`relative_pose_series` from the two satellites' states at the
    times ``t_s`` (n,) [s]: positions (n, 3) [m] and velocities (n, 3) [m/s] in one inertial
    frame (the ECI of the elements, or the GCRS of TLEs propagated by SGP4)."""
    t = _times(t_s, allow_empty=False)
    body = lvlh_attitude(r_tgt, v_tgt)
    sensor = tracking_attitude(r_img, r_tgt, v_img)
    rotation = np.einsum("nji,njk->nik", sensor, body)
    relative_eci_m = r_img - r_tgt
    rot = Rotation.from_matrix(rotation)
    return RelativePose(
        t_s=t,
        distance_m=np.linalg.norm(relative_eci_m, axis=-1),
        quaternion_wxyz=_continuous_quaternions(rot.as_quat(scalar_first=True)),
        rotation=rotation,
        angles_deg=rot.as_euler("XYZ", degrees=True),
        relative_position_lvlh_m=np.einsum("nji,nj->ni", body, relative_eci_m),
    )


def _continuous_quaternions(q: FloatArray) -> FloatArray:
    """(n, 4) quaternions with signs flipped so that neighbours have a non-negative dot product."""
    q = q.copy()
    if q[0, 0] < 0.0:
        q[0] = -q[0]
    for k in range(1, len(q)):
        if q[k] @ q[k - 1] < 0.0:
            q[k] = -q[k]
    return q


def flyaround_times(interval_s: float = 300.0, duration_s: float = PAPER_PERIOD_S) -> FloatArray:
    """Imaging times 0, interval_s, 2*interval_s, ... <= duration_s.

    Parameters
    ----------
    interval_s : float
        Time between two images [s], > 0 (the paper: 300 s).
    duration_s : float
        Length of the fly-around [s], > 0 (the paper: one orbit, PAPER_PERIOD_S).

    Returns
    -------
    (n,) float
        Times [s]; the end point is included when duration_s is a multiple of interval_s (to 1e-9).
    """
    for name, value in (("interval_s", interval_s), ("duration_s", duration_s)):
        if not (math.isfinite(value) and value > 0.0):
            raise OrbitError(f"{name} must be a finite number > 0 s, got {value!r}")
    count = math.floor(duration_s / interval_s * (1.0 + 1e-9)) + 1
    return interval_s * np.arange(count, dtype=float)


def distance_stats(
    target: Elements, imaging: Elements, j2: bool = False, n: int = 2000
) -> dict[str, float]:
    """Minimum, mean and maximum lidar-target distance over one (two-body) period of the target.

    Parameters
    ----------
    target, imaging : Elements
        The two orbits, at a common epoch.
    j2 : bool
        Propagate with the secular J2 rates.
    n : int
        Number of equally spaced samples over [0, target.period_s), >= 1.

    Returns
    -------
    dict
        ``{"min_m": float, "mean_m": float, "max_m": float}`` [m]; the mean is the time average.
    """
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise OrbitError(f"n must be an integer >= 1, got {n!r}")
    t = np.linspace(0.0, target.period_s, int(n), endpoint=False)
    r_tgt, _ = propagate(target, t, j2=j2)
    r_img, _ = propagate(imaging, t, j2=j2)
    distance_m = np.linalg.norm(r_img - r_tgt, axis=-1)
    return {
        "min_m": float(distance_m.min()),
        "mean_m": float(distance_m.mean()),
        "max_m": float(distance_m.max()),
    }


# ----------------------------------------------------------------------------------------------
# Input checks
# ----------------------------------------------------------------------------------------------
def _times(t_s: ArrayLike, allow_empty: bool) -> FloatArray:
    """``t_s`` as a finite (n,) float array; OrbitError otherwise."""
    try:
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
    except (TypeError, ValueError):
        raise OrbitError(f"t_s must be an array of times in seconds, got {t_s!r}") from None
    if t.ndim != 1:
        raise OrbitError(f"t_s must be one-dimensional (n,), got shape {t.shape}")
    if not allow_empty and t.size == 0:
        raise OrbitError("t_s is empty: a pose series needs at least one time (duration of zero)")
    if not np.all(np.isfinite(t)):
        raise OrbitError("t_s must be finite (no NaN or inf)")
    return t


def _vector3(x: ArrayLike, name: str) -> FloatArray:
    """``x`` as a finite (3,) float array; OrbitError otherwise."""
    array = np.asarray(x, dtype=float)
    if array.shape != (3,):
        raise OrbitError(f"{name} must have shape (3,), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise OrbitError(f"{name} must be finite (no NaN or inf)")
    return array


def _rows3(x: ArrayLike, name: str) -> FloatArray:
    """``x`` as a finite (n, 3) float array ((3,) becomes (1, 3)); OrbitError otherwise."""
    array = np.atleast_2d(np.asarray(x, dtype=float))
    if array.ndim != 2 or array.shape[1] != 3:
        raise OrbitError(f"{name} must have shape (n, 3) or (3,), got {np.shape(x)}")
    if not np.all(np.isfinite(array)):
        raise OrbitError(f"{name} must be finite (no NaN or inf)")
    return array
