"""The target's three-axis stabilised LVLH attitude, the lidar's tracking attitude and, from the
two, the pose of the target body in the lidar sensor frame over a fly-around (frames:
``simcore.orbit.elements``; docs/physics.md#table-3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from .elements import PAPER_PERIOD_S, Elements, FloatArray, OrbitError
from .inputs import rows3, time_array
from .propagation import propagate

_PARALLEL_TOL = 1e-6  # [rad] nadir within this angle of the boresight: roll falls back to -h_hat


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
    r_m = rows3(r, "r")
    v_m_s = rows3(v, "v")
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
    r_l = rows3(r_lidar, "r_lidar")
    r_t = rows3(r_target, "r_target")
    v_l = rows3(v_lidar, "v_lidar")
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
    t = time_array(t_s, allow_empty=False)
    r_tgt, v_tgt = propagate(target, t, j2=j2)
    r_img, v_img = propagate(imaging, t, j2=j2)
    return relative_pose_from_states(t, r_tgt, v_tgt, r_img, v_img)


def relative_pose_from_states(t_s, r_tgt, v_tgt, r_img, v_img) -> RelativePose:
    """The pose series of :func:`relative_pose_series` from the two satellites' states at the
    times ``t_s`` (n,) [s]: positions (n, 3) [m] and velocities (n, 3) [m/s] in one inertial
    frame (the ECI of the elements, or the GCRS of TLEs propagated by SGP4)."""
    t = time_array(t_s, allow_empty=False)
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
