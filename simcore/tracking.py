"""A pose track: each frame's cloud registered to the target's model, scored against the truth.

The model is a cloud of points sampled uniformly (by area) on the target's mesh, in its body
frame, with the faces' normals (:func:`model_points`). A frame is registered by generalised ICP
(small_gicp, GICP) from a seed: the model's side that faces the lidar under the seed (back faces
culled) is the target of the registration, the frame's points (outliers included: the tracker does
not know them) its source. The seed of a frame is the previous estimate moved on by the last
step's motion (constant velocity, in the sensor frame); the first frame, and any after a lost one,
come from :func:`global_register`, as does a frame whose seeded registration fails the lost rule
twice, from the prediction and then re-centred on the cloud's centroid (re-acquired, in the same
frame). The global registration does not use the truth: GICP started from
``GLOBAL_HYPOTHESES`` attitudes spread evenly over the rotation group (a seeded draw), each placed
so that the seen side's centroid lies on the cloud's, the best by fitness kept.

A frame is LOST (``lost_rule``) when fewer than ``MIN_POINTS`` points take part, or when under
``MIN_FITNESS`` of the frame's points end within 1 % of the model's radius of a model point:
its estimate is kept in the table but never seeds the next frame. Errors are against the ground
truth (``trajectory.GroundTruth``): the rotation angle of R_est^T R_true [deg] and the distance
between the estimated and the true target centre [m].
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from .trajectory import GroundTruth

__all__ = [
    "GLOBAL_HYPOTHESES",
    "MIN_FITNESS",
    "MIN_POINTS",
    "TRACK_COLUMNS",
    "ModelCloud",
    "Registration",
    "TrackResult",
    "global_register",
    "is_lost",
    "model_points",
    "pose_errors",
    "register",
    "track",
    "track_frame",
]

MODEL_POINTS = 60_000  # [-] points sampled on the mesh (MRO: about 6 cm apart)
MIN_POINTS = 30  # [-] fewer points than this in a frame: lost
MIN_FITNESS = 0.5  # [-] a smaller share of the points near the model after registration: lost
GLOBAL_HYPOTHESES = 96  # [-] start attitudes of the global registration
_FINE_FRACTION = 0.01  # [-] final correspondence distance / model radius (MRO: 8.5 cm)
_COARSE_FRACTION = 0.06  # [-] first correspondence distance / model radius (MRO: 0.5 m)
_GLOBAL_FRACTION = 0.15  # [-] correspondence distance of the global search / radius
_EDGE_ON_DEG = 5.0  # [deg] faces turned less than this away from the lidar are kept
_ITERATIONS = 60  # [-] GICP iterations of a pass at most
_ROTATION_EPSILON_RAD = 1e-5  # [rad] GICP's convergence: an update below this (and below...)
_TRANSLATION_EPSILON_M = 1e-5  # [m] ... this) ends it (small_gicp's default 0.1 deg stops short)
_GLOBAL_VOXEL_FRACTION = 0.03  # [-] voxel of the global search's clouds / radius


@dataclass(frozen=True, eq=False)
class ModelCloud:
    """Points on the target's surface in its body frame.

    Attributes
    ----------
    points_m : (n, 3) float
        Positions [m], target body frame.
    normals : (n, 3) float
        Outward unit normals of their faces, body frame.
    radius_m : float
        The farthest point from the body origin [m].
    """

    points_m: np.ndarray
    normals: np.ndarray
    radius_m: float

    def seen_from(self, pose: np.ndarray) -> np.ndarray:
        """(m, 3) the points whose faces look towards the lidar when the target is at ``pose``
        (4, 4) T_sensor_target, or turn less than ``_EDGE_ON_DEG`` away (back faces culled, those
        seen edge-on kept: a seed a degree off must not drop a panel seen edge-on; no
        occlusion)."""
        lidar_m = -pose[:3, :3].T @ pose[:3, 3]
        to_lidar = lidar_m - self.points_m
        cos = np.einsum("ij,ij->i", self.normals, to_lidar) / np.linalg.norm(to_lidar, axis=1)
        return self.points_m[cos > -np.sin(np.radians(_EDGE_ON_DEG))]


def model_points(model: Any, n: int = MODEL_POINTS, seed: int = 0) -> ModelCloud:
    """``n`` points sampled uniformly by area on ``model`` (a ``TargetModel``), body frame."""
    import trimesh  # noqa: PLC0415

    mesh = trimesh.Trimesh(model.vertices_m, model.faces, process=False)
    points, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    body = np.asarray(model.body_from_mesh, dtype=np.float64)
    points_b = np.ascontiguousarray(points @ body.T)
    normals_b = np.ascontiguousarray(model.face_normals[face] @ body.T)
    return ModelCloud(points_b, normals_b, float(np.linalg.norm(points_b, axis=1).max()))


@dataclass(frozen=True)
class Registration:
    """One registration: the estimated T_sensor_target (4, 4), the share of the source points
    within the final correspondence distance (fitness), the points used and its wall time [s]."""

    pose: np.ndarray
    fitness: float
    n_points: int
    seconds: float
    method: str


def _align(
    source_m, target_m, seed, distances_m, voxel_m, iterations, fitness_m
) -> tuple[np.ndarray, float]:
    """GICP of ``source_m`` (sensor frame) onto ``target_m`` (body frame) from ``seed``
    (T_sensor_target), one pass per correspondence distance of ``distances_m`` on the same
    preprocessed clouds; the estimate and its fitness: the share of the source's points within
    ``fitness_m`` of a target point."""
    import small_gicp  # noqa: PLC0415

    target, tree = small_gicp.preprocess_points(target_m, downsampling_resolution=voxel_m)
    source, _ = small_gicp.preprocess_points(source_m, downsampling_resolution=voxel_m)
    body_from_sensor = np.linalg.inv(seed)
    for distance_m in distances_m:
        result = small_gicp.align(
            target,
            source,
            tree,
            init_T_target_source=body_from_sensor,
            registration_type="GICP",
            max_correspondence_distance=distance_m,
            max_iterations=iterations,
            rotation_epsilon=_ROTATION_EPSILON_RAD,
            translation_epsilon=_TRANSLATION_EPSILON_M,
        )
        body_from_sensor = result.T_target_source
    moved = source_m @ body_from_sensor[:3, :3].T + body_from_sensor[:3, 3]
    _, sq_dist = tree.batch_nearest_neighbor_search(moved)
    fitness = float(np.mean(np.asarray(sq_dist) <= fitness_m**2))
    return np.linalg.inv(body_from_sensor), fitness


def register(points_m: np.ndarray, model: ModelCloud, seed: np.ndarray) -> Registration:
    """Register a frame's points (n, 3) [m, sensor frame] to ``model`` from ``seed`` (4, 4)
    T_sensor_target: on the side seen from the seed, GICP passes at correspondence distances of
    6 %, 1 % and 0.5 % of the model's radius; the fitness at 1 %."""
    start = time.perf_counter()
    points = np.ascontiguousarray(points_m, dtype=np.float64)
    if len(points) < MIN_POINTS:
        return Registration(seed, 0.0, len(points), time.perf_counter() - start, "too few")
    radius = model.radius_m
    passes = (_COARSE_FRACTION * radius, _FINE_FRACTION * radius, 0.5 * _FINE_FRACTION * radius)
    pose, fitness = _align(
        points, model.seen_from(seed), seed, passes, 0.002 * radius, _ITERATIONS, passes[1]
    )
    return Registration(pose, fitness, len(points), time.perf_counter() - start, "tracked")


def global_register(
    points_m: np.ndarray, model: ModelCloud, hypotheses: int = GLOBAL_HYPOTHESES, seed: int = 0
) -> Registration:
    """Register a frame with no prior: GICP from ``hypotheses`` attitudes (a seeded uniform draw
    on the rotation group), each started with the seen side's centroid on the cloud's; the best
    by fitness, refined by :func:`register`. The truth is not used."""
    start = time.perf_counter()
    points = np.ascontiguousarray(points_m, dtype=np.float64)
    if len(points) < MIN_POINTS:
        return Registration(np.eye(4), 0.0, len(points), time.perf_counter() - start, "too few")
    radius = model.radius_m
    centroid = points.mean(axis=0)
    step = max(1, len(model.points_m) // 4000)  # the search on a thinned model
    coarse = ModelCloud(model.points_m[::step], model.normals[::step], radius)
    best = (-1.0, np.eye(4))
    for rot in Rotation.random(hypotheses, random_state=seed).as_matrix():
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rot, centroid
        seen = coarse.seen_from(pose)
        if len(seen) == 0:
            continue
        pose[:3, 3] = centroid - rot @ seen.mean(axis=0)
        estimate, fitness = _align(
            points,
            coarse.seen_from(pose),
            pose,
            (_GLOBAL_FRACTION * radius,),
            _GLOBAL_VOXEL_FRACTION * radius,
            15,
            _GLOBAL_FRACTION * radius,
        )
        if fitness > best[0]:
            best = (fitness, estimate)
    refined = register(points, model, best[1])
    return Registration(
        refined.pose, refined.fitness, refined.n_points, time.perf_counter() - start, "global"
    )


TRACK_COLUMNS = (
    "frame",
    "t_s",
    "range_m",
    "est_x_m",
    "est_y_m",
    "est_z_m",
    "est_qw",
    "est_qx",
    "est_qy",
    "est_qz",
    "rotation_error_deg",
    "translation_error_m",
    "fitness",
    "points_used",
    "lost",
    "method",
    "registration_s",
)


@dataclass(frozen=True, eq=False)
class TrackResult:
    """A pose track over a fly-around's frames (estimates of T_sensor_target, the target's pose
    in the sensor frame; conventions of ``simcore.trajectory``).

    Attributes
    ----------
    t_s, range_m : (n,) float
        Frame times [s] and true ranges [m].
    poses : (n, 4, 4) float
        Estimated T_sensor_target.
    rotation_error_deg, translation_error_m : (n,) float
        Against the truth [deg], [m].
    fitness : (n,) float
        Share of the frame's points within the final correspondence distance of the model.
    points_used : (n,) int
        The frame's points given to the registration.
    lost : (n,) bool
        Frames the rule (``lost_rule``) flags.
    methods : tuple of str
        ``global`` (no prior), ``tracked`` (seeded by the previous estimate), ``recentred``
        (the seed's centre moved onto the cloud's, after the prediction failed the rule),
        ``reacquired`` (both failed, then global) or ``too few``.
    registration_s : (n,) float
        Wall time of each registration [s].
    """

    t_s: np.ndarray
    range_m: np.ndarray
    poses: np.ndarray
    rotation_error_deg: np.ndarray
    translation_error_m: np.ndarray
    fitness: np.ndarray
    points_used: np.ndarray
    lost: np.ndarray
    methods: tuple[str, ...]
    registration_s: np.ndarray
    lost_rule: str = field(
        default=f"fewer than {MIN_POINTS} points, or under {MIN_FITNESS:g} of them within 1 % "
        "of the model's radius of a model point once registered"
    )

    @property
    def quaternion_wxyz(self) -> np.ndarray:
        """(n, 4) estimated target -> sensor rotations, w first."""
        return Rotation.from_matrix(self.poses[:, :3, :3]).as_quat(scalar_first=True)

    def rows(self) -> list[list[Any]]:
        """One row per frame, in :data:`TRACK_COLUMNS` order."""
        q = self.quaternion_wxyz
        return [
            [
                i,
                float(self.t_s[i]),
                float(self.range_m[i]),
                *self.poses[i, :3, 3].tolist(),
                *q[i].tolist(),
                float(self.rotation_error_deg[i]),
                float(self.translation_error_m[i]),
                float(self.fitness[i]),
                int(self.points_used[i]),
                int(self.lost[i]),
                self.methods[i],
                float(self.registration_s[i]),
            ]
            for i in range(len(self.t_s))
        ]

    def summary(self) -> dict[str, Any]:
        """Median and worst errors over the frames not lost, the frames lost, the median
        registration time [s] and the rule."""
        kept = ~self.lost
        rot, tra = self.rotation_error_deg[kept], self.translation_error_m[kept]
        return {
            "n_frames": len(self.t_s),
            "n_lost": int(self.lost.sum()),
            "rotation_error_deg_median": float(np.median(rot)) if kept.any() else None,
            "rotation_error_deg_max": float(rot.max()) if kept.any() else None,
            "translation_error_m_median": float(np.median(tra)) if kept.any() else None,
            "translation_error_m_max": float(tra.max()) if kept.any() else None,
            "registration_s_median": float(np.median(self.registration_s)),
            "lost_rule": self.lost_rule,
        }

    def to_json(self) -> dict[str, Any]:
        """The summary and one dict per frame (the tracking.csv row, named)."""
        return {
            "summary": self.summary(),
            "frames": [dict(zip(TRACK_COLUMNS, row, strict=True)) for row in self.rows()],
        }


def pose_errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Rotation error [deg] and translation error [m] of ``estimate`` against ``truth``, both
    (4, 4) T_sensor_target."""
    delta = Rotation.from_matrix(estimate[:3, :3].T @ truth[:3, :3])
    return float(np.degrees(delta.magnitude())), float(
        np.linalg.norm(estimate[:3, 3] - truth[:3, 3])
    )


def _predict(previous: list[tuple[float, np.ndarray]], t_s: float) -> np.ndarray:
    """The seed at ``t_s``: the last good estimate moved on at the last step's rates (its
    rotation's, in the sensor frame, and its centre's velocity), scaled to the time step; the
    last estimate itself if there is one only."""
    t1, pose1 = previous[-1]
    if len(previous) < 2:
        return pose1
    t0, pose0 = previous[-2]
    scale = (t_s - t1) / (t1 - t0) if t1 > t0 else 1.0
    turn = Rotation.from_matrix(pose1[:3, :3] @ pose0[:3, :3].T).as_rotvec() * scale
    seed = np.eye(4)
    seed[:3, :3] = Rotation.from_rotvec(turn).as_matrix() @ pose1[:3, :3]
    seed[:3, 3] = pose1[:3, 3] + scale * (pose1[:3, 3] - pose0[:3, 3])
    return seed


def _recentred(seed: np.ndarray, points_m: np.ndarray, model: ModelCloud) -> np.ndarray:
    """``seed`` with its translation moved so that the seen side's centroid lands on the frame's
    (the rotation kept): the second try of a seeded frame whose centre moved more than the
    prediction knew (an approach's second frame, seeded by the first alone)."""
    seen = model.seen_from(seed)
    out = seed.copy()
    if len(seen):
        out[:3, 3] += points_m.mean(axis=0) - (seed[:3, :3] @ seen.mean(axis=0) + seed[:3, 3])
    return out


def is_lost(reg: Registration) -> bool:
    """The lost rule: too few points, or too few of them near the model."""
    return reg.n_points < MIN_POINTS or reg.fitness < MIN_FITNESS


def track_frame(
    points_m: np.ndarray,
    model: ModelCloud,
    previous: list[tuple[float, np.ndarray]],
    t_s: float,
    seed: int = 0,
) -> Registration:
    """One frame of :func:`track`: its points (n, 3) [m, sensor frame] registered from the
    prediction of ``previous`` (the last one or two frames not lost, (t [s], T_sensor_target),
    in time order) at ``t_s``, re-centred on the cloud if that fails the lost rule; with no
    ``previous``, or when both fail, by :func:`global_register` (``seed`` its draw)."""
    points = np.ascontiguousarray(points_m, dtype=np.float64)
    reg = None
    if previous:
        predicted = _predict(previous, t_s)
        reg = register(points, model, predicted)
        if is_lost(reg) and reg.n_points >= MIN_POINTS:  # the prediction's centre off
            again = register(points, model, _recentred(predicted, points, model))
            reg = Registration(
                again.pose, again.fitness, again.n_points, again.seconds + reg.seconds, "recentred"
            )
    if reg is None or (is_lost(reg) and reg.n_points >= MIN_POINTS):  # (re-)acquire
        spent = reg.seconds if reg is not None else 0.0
        reg = global_register(points, model, seed=seed)
        if spent:
            reg = Registration(
                reg.pose, reg.fitness, reg.n_points, reg.seconds + spent, "reacquired"
            )
    return reg


def track(
    clouds,
    model: Any,
    truth: GroundTruth,
    n_model_points: int = MODEL_POINTS,
    seed: int = 0,
    cloud_model: ModelCloud | None = None,
) -> TrackResult:
    """Track the target's pose over ``clouds`` (one ``PointCloud`` per frame, sensor frame).

    Parameters
    ----------
    clouds : sequence of PointCloud
        The frames, in time order (all their points: the tracker does not know the outliers).
    model : TargetModel
        The target (its mesh is sampled: :func:`model_points`).
    truth : GroundTruth
        The frames' true poses: only to score the estimates, never to make them.
    n_model_points : int
        Points sampled on the mesh.
    seed : int
        Seed of the model's samples and of the global search's attitudes.
    cloud_model : ModelCloud, optional
        The model's points, if already sampled (then ``n_model_points`` is not used).

    Returns
    -------
    TrackResult
    """
    if cloud_model is None:
        cloud_model = model_points(model, n_model_points, seed)
    true_poses = truth.matrices
    previous: list[tuple[float, np.ndarray]] = []  # (t, estimate) of the frames not lost
    out: dict[str, list] = {k: [] for k in ("pose", "rot", "tra", "fit", "n", "lost", "m", "s")}
    for i, cloud in enumerate(clouds):
        t_s = float(truth.t_s[i])
        reg = track_frame(
            np.asarray(cloud.points, dtype=np.float64), cloud_model, previous, t_s, seed
        )
        lost = is_lost(reg)
        if lost:
            previous.clear()  # the next frame starts again with no prior
        else:
            previous = [*previous[-1:], (t_s, reg.pose)]
        rot_deg, tra_m = pose_errors(reg.pose, true_poses[i])
        for name, value in zip(
            out,
            (reg.pose, rot_deg, tra_m, reg.fitness, reg.n_points, lost, reg.method, reg.seconds),
            strict=True,
        ):
            out[name].append(value)
    return TrackResult(
        t_s=np.asarray(truth.t_s, dtype=np.float64),
        range_m=np.asarray(truth.range_m, dtype=np.float64),
        poses=np.array(out["pose"]).reshape(-1, 4, 4),
        rotation_error_deg=np.array(out["rot"], dtype=np.float64),
        translation_error_m=np.array(out["tra"], dtype=np.float64),
        fitness=np.array(out["fit"], dtype=np.float64),
        points_used=np.array(out["n"], dtype=np.int64),
        lost=np.array(out["lost"], dtype=bool),
        methods=tuple(out["m"]),
        registration_s=np.array(out["s"], dtype=np.float64),
    )
