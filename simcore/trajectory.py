"""Trajectories of a fly-around (the scene's ``[trajectory]`` section) and their ground truth.

Three kinds of relative motion, each with an optional tumble on top:

- ``orbit``: the Table 3 orbits (two-body or J2) or two TLEs (SGP4), as ``simcore.orbit`` gives
  the pose of the target's LVLH frame in the tracking lidar's sensor frame;
- ``approach``: the lidar on the target's zenith side (an R-bar approach), its boresight along the
  target's LVLH z axis (towards the Earth's centre), the range falling linearly in time from
  ``start_range_m`` to ``end_range_m`` over ``duration_s``;
- ``hold``: the same geometry at the fixed range ``start_range_m``.

The target's attitude in its trajectory's frame is A(t) = Q0 * exp(w t a): the initial attitude
``initial_quaternion_wxyz`` (Q0) followed by a spin at ``tumble_rate_deg_s`` (w) about the BODY
axis ``tumble_axis`` (a). The target body -> sensor rotation is then R(t) = R_base(t) A(t), with
R_base the LVLH -> sensor rotation of the kind (the identity for approach and hold).

Conventions (docs/trajectories.md): quaternions are Hamilton, scalar first (w, x, y, z), active
(they rotate vectors: p_sensor = R p_target + t); frames are ``sensor`` (x image right, y image
down, z boresight; origin the lidar's centre of projection) and ``target`` (the model's body
frame, origin the centre of its bounding box). ``T_sensor_target`` maps target coordinates to
sensor coordinates; ``T_target_sensor`` is its inverse (the lidar's pose in the target frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from .orbit import RelativePose
from .orbit.attitude import _continuous_quaternions
from .scene import Scene, SceneError

__all__ = [
    "CONVENTIONS",
    "POSE_COLUMNS",
    "GroundTruth",
    "attitude_offsets",
    "check_trajectory_target",
    "frame_times",
    "ground_truth",
    "line_of_sight_poses",
    "with_attitude",
]


def frame_times(scene: Scene) -> np.ndarray:
    """(n,) frame times [s] of an approach or hold: 0, 1/rate, 2/rate, ... <= duration_s.

    The count is floor(duration_s * frame_rate_hz) + 1 (the end point when the product is whole,
    to 1e-9); the scene's validation caps it at ``MAX_TRAJECTORY_FRAMES``.
    """
    tr = scene.trajectory
    count = math.floor(tr.duration_s * tr.frame_rate_hz * (1.0 + 1e-9)) + 1
    return np.arange(count, dtype=np.float64) / tr.frame_rate_hz


def range_at(scene: Scene, t_s: ArrayLike) -> np.ndarray:
    """(n,) range to the target's centre [m] at ``t_s`` for an approach (linear from
    ``start_range_m`` at 0 to ``end_range_m`` at ``duration_s``) or a hold (``start_range_m``)."""
    tr = scene.trajectory
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if tr.kind == "hold":
        return np.full(t.shape, tr.start_range_m)
    return tr.start_range_m + (tr.end_range_m - tr.start_range_m) * (t / tr.duration_s)


def attitude_offsets(scene: Scene, t_s: ArrayLike) -> Rotation:
    """The target's attitude in its trajectory's frame, A(t) = Q0 * exp(w t a), at ``t_s`` [s]:
    (n,) rotations, target body -> trajectory frame (see the module's docstring)."""
    tr = scene.trajectory
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    axis = np.asarray(tr.tumble_axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    spin = Rotation.from_rotvec(np.outer(np.radians(tr.tumble_rate_deg_s) * t, axis))
    q0 = Rotation.from_quat(tr.initial_quaternion_wxyz, scalar_first=True)
    return q0 * spin


def line_of_sight_poses(scene: Scene, t_s: ArrayLike) -> RelativePose:
    """The pose series of an approach or hold (target LVLH = sensor axes, the target on the
    boresight at ``range_at``), before the target's own attitude (:func:`with_attitude`)."""
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    distance_m = range_at(scene, t)
    n = len(t)
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    lidar_lvlh_m = np.zeros((n, 3))
    lidar_lvlh_m[:, 2] = -distance_m  # above the target, on its zenith side
    return RelativePose(
        t_s=t,
        distance_m=distance_m,
        quaternion_wxyz=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        rotation=eye,
        angles_deg=np.zeros((n, 3)),
        relative_position_lvlh_m=lidar_lvlh_m,
    )


def with_attitude(base: RelativePose, offsets: Rotation) -> RelativePose:
    """``base`` (LVLH -> sensor) with the target turned by ``offsets`` (body -> LVLH), (n,):
    R = R_base A; quaternions continuous in time, the first with w >= 0."""
    rot = Rotation.from_matrix(base.rotation) * offsets
    return RelativePose(
        t_s=base.t_s,
        distance_m=base.distance_m,
        quaternion_wxyz=_continuous_quaternions(rot.as_quat(scalar_first=True)),
        rotation=rot.as_matrix(),
        angles_deg=rot.as_euler("XYZ", degrees=True),
        relative_position_lvlh_m=base.relative_position_lvlh_m,
    )


def check_trajectory_target(scene: Scene, radius_m: float) -> None:
    """Refuse (SceneError) an approach or hold whose ranges reach into the target's bounding
    sphere (``radius_m`` about its centre [m]): the lidar would fly into the target."""
    tr = scene.trajectory
    if tr.kind == "orbit":
        return
    for name in ("start_range_m", "end_range_m") if tr.kind == "approach" else ("start_range_m",):
        value = getattr(tr, name)
        if value <= radius_m:
            raise SceneError(
                f"trajectory.{name} = {value:g} m ends inside the target: its bounding sphere "
                f"reaches {radius_m:.3g} m from its centre; give a range above that"
            )


# ----------------------------------------------------------------------------------------------
# Ground truth
# ----------------------------------------------------------------------------------------------
POSE_COLUMNS = (
    "frame",
    "t_s",
    "range_m",
    # T_sensor_target: the target's pose in the sensor frame
    "target_in_sensor_x_m",
    "target_in_sensor_y_m",
    "target_in_sensor_z_m",
    "target_in_sensor_qw",
    "target_in_sensor_qx",
    "target_in_sensor_qy",
    "target_in_sensor_qz",
    # T_target_sensor: the lidar's pose in the target frame
    "sensor_in_target_x_m",
    "sensor_in_target_y_m",
    "sensor_in_target_z_m",
    "sensor_in_target_qw",
    "sensor_in_target_qx",
    "sensor_in_target_qy",
    "sensor_in_target_qz",
    # unit vector towards the Sun, in each frame
    "sun_sensor_x",
    "sun_sensor_y",
    "sun_sensor_z",
    "sun_target_x",
    "sun_target_y",
    "sun_target_z",
)


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """The true poses of a fly-around's frames (conventions: the module's docstring).

    Attributes
    ----------
    t_s, range_m : (n,) float
        Frame times [s] and ranges to the target's centre [m].
    translation_m : (n, 3) float
        The target's centre in the sensor frame [m] (t of T_sensor_target).
    quaternion_wxyz : (n, 4) float
        Target -> sensor rotation (Hamilton, w first, active, continuous in time).
    sun_target : (n, 3) float
        Unit vector towards the Sun in the target frame.
    """

    t_s: np.ndarray
    range_m: np.ndarray
    translation_m: np.ndarray
    quaternion_wxyz: np.ndarray
    sun_target: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """(n, 3, 3) target -> sensor rotation matrices."""
        return Rotation.from_quat(self.quaternion_wxyz, scalar_first=True).as_matrix()

    @property
    def matrices(self) -> np.ndarray:
        """(n, 4, 4) homogeneous T_sensor_target."""
        out = np.tile(np.eye(4), (len(self.t_s), 1, 1))
        out[:, :3, :3] = self.rotation
        out[:, :3, 3] = self.translation_m
        return out

    def sensor_in_target(self) -> tuple[np.ndarray, np.ndarray]:
        """The inverse, T_target_sensor: the lidar's position in the target frame (n, 3) [m]
        and the sensor -> target quaternion (n, 4), w first, continuous, first w >= 0."""
        rot = self.rotation
        position = -np.einsum("nji,nj->ni", rot, self.translation_m)
        q = self.quaternion_wxyz * np.array([1.0, -1.0, -1.0, -1.0])  # the conjugate
        return position, _continuous_quaternions(q)

    def rows(self) -> list[list[float]]:
        """One row per frame, in :data:`POSE_COLUMNS` order."""
        position, q_inv = self.sensor_in_target()
        sun_sensor = np.einsum("nij,nj->ni", self.rotation, self.sun_target)
        out = []
        for i in range(len(self.t_s)):
            out.append(
                [
                    i,
                    float(self.t_s[i]),
                    float(self.range_m[i]),
                    *self.translation_m[i].tolist(),
                    *self.quaternion_wxyz[i].tolist(),
                    *position[i].tolist(),
                    *q_inv[i].tolist(),
                    *sun_sensor[i].tolist(),
                    *self.sun_target[i].tolist(),
                ]
            )
        return out

    def records(self) -> list[dict]:
        """Each frame's truth as the JSON record holds it: its poses.csv row, by column name."""
        return [dict(zip(POSE_COLUMNS[1:], row[1:], strict=True)) for row in self.rows()]


# what the JSON record and the bag say about the frames and the quaternions
CONVENTIONS = {
    "quaternion": "Hamilton, scalar first (w, x, y, z), active: p_sensor = R(q) p_target + t",
    "sensor": "x image right, y image down, z boresight; origin the lidar",
    "target": "the model's body frame; origin the centre of its bounding box",
    "target_in_sensor": "T_sensor_target, maps target coordinates to sensor coordinates",
    "sensor_in_target": "T_target_sensor, the lidar's pose in the target frame",
}


def ground_truth(scene: Scene, pose: RelativePose, sun_lvlh: np.ndarray) -> GroundTruth:
    """The truth of the frames imaged at ``pose``: the target at (offset_x_m, offset_y_m,
    distance) in the sensor frame (the pipeline's placement), the Sun from ``sun_lvlh`` (n, 3)
    (the ephemeris's, in the target's LVLH frame) turned into the body frame, or the scene's
    manual direction (fixed in the body frame) with ``sun.mode = manual``."""
    n = len(pose.t_s)
    translation = np.zeros((n, 3))
    translation[:, 0] = scene.pose.offset_x_m
    translation[:, 1] = scene.pose.offset_y_m
    translation[:, 2] = pose.distance_m
    if scene.sun.mode == "manual":
        from .sun import direction_from_angles  # noqa: PLC0415

        s = direction_from_angles(scene.sun.azimuth_deg, scene.sun.elevation_deg)
        sun_target = np.tile(s, (n, 1))
    else:
        sun_target = attitude_offsets(scene, pose.t_s).inv().apply(np.asarray(sun_lvlh))
    return GroundTruth(
        t_s=np.asarray(pose.t_s),
        range_m=np.linalg.norm(translation, axis=1),
        translation_m=translation,
        quaternion_wxyz=np.asarray(pose.quaternion_wxyz),
        sun_target=sun_target,
    )
