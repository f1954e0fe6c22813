"""Poses: rotations, quaternions and the target's pose in the sensor frame (origin at the lidar,
z = boresight, x = image right, y = image down; docs/physics.md#geometry)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Pose


def rotation_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quaternion_matrix(q_wxyz) -> np.ndarray:
    """(3, 3) active rotation matrix of a (not necessarily unit) quaternion w, x, y, z."""
    w, x, y, z = np.asarray(q_wxyz, dtype=np.float64) / np.linalg.norm(q_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def front_view_rotation(extents) -> np.ndarray:
    """Rotation (sensor <- target) of the zero pose: the line of sight runs along the target's
    smallest extent, its largest extent lies along the image x axis, the middle one points up."""
    order = np.argsort(extents)  # smallest, middle, largest
    rot = np.zeros((3, 3))
    rot[0, order[2]] = 1.0  # sensor x <- largest extent
    rot[1, order[1]] = -1.0  # sensor y (down) <- minus the middle extent (it points up)
    rot[2, order[0]] = 1.0  # sensor z (line of sight) <- smallest extent
    if np.linalg.det(rot) < 0:
        rot[2] *= -1.0
    return rot


@dataclass(frozen=True, kw_only=True)
class PoseInSensor:
    """Where the target is: p_sensor = rotation @ p_target + translation_m."""

    rotation: np.ndarray  # (3, 3)
    translation_m: np.ndarray  # (3,)


def target_pose(pose: Pose, extents, body_from_mesh=None) -> PoseInSensor:
    """The target's pose in the sensor frame: its origin at ``distance_m`` along the boresight,
    moved sideways by ``offset_x_m``, ``offset_y_m`` (0: on the boresight).

    With no quaternion: R = Rz(roll) Rx(pitch) Ry(azimuth) R0, rotations about the sensor's own axes
    applied to the front view R0 (azimuth first, then pitch, then roll). With ``quaternion_wxyz``
    (target body -> sensor, as orbit.relative_pose_series gives it): R = Q @ body_from_mesh.
    """
    if pose.quaternion_wxyz:
        body = np.eye(3) if body_from_mesh is None else body_from_mesh
        rot = quaternion_matrix(pose.quaternion_wxyz) @ body
    else:
        rot = (
            rotation_z(np.radians(pose.roll_deg))
            @ rotation_x(np.radians(pose.pitch_deg))
            @ rotation_y(np.radians(pose.azimuth_deg))
            @ front_view_rotation(extents)
        )
    return PoseInSensor(
        rotation=rot,
        translation_m=np.array([pose.offset_x_m, pose.offset_y_m, pose.distance_m]),
    )
