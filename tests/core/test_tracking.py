"""The pose tracker (simcore.tracking) on clouds of known pose: noise-free points sampled on the
MRO's mesh (another draw than the model's), seen from the lidar (back faces culled)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import simcore
from simcore import tracking
from simcore.pointcloud import PointCloud
from simcore.target import load_target
from simcore.trajectory import GroundTruth

ROT_TOL_DEG = 0.05  # the marks for a noise-free cloud
TRA_TOL_M = 0.005


def pose_matrix(rotvec, translation_m) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = translation_m
    return out


TRUE_POSE = pose_matrix([0.4, -1.1, 0.3], [0.3, -0.2, 60.0])  # T_sensor_target


@pytest.fixture(scope="module")
def mro():
    return load_target(simcore.Scene().target)


@pytest.fixture(scope="module")
def model(mro):
    return tracking.model_points(mro)


@pytest.fixture(scope="module")
def cloud(mro):
    """The MRO's side seen from the lidar at TRUE_POSE, 4000 samples of another seed."""
    view = tracking.model_points(mro, 4000, seed=7)
    body = view.seen_from(TRUE_POSE)
    return body @ TRUE_POSE[:3, :3].T + TRUE_POSE[:3, 3]


def truth_of(poses) -> GroundTruth:
    poses = np.asarray(poses)
    q = Rotation.from_matrix(poses[:, :3, :3]).as_quat(scalar_first=True)
    n = len(poses)
    return GroundTruth(
        t_s=np.arange(n, dtype=float),
        range_m=np.linalg.norm(poses[:, :3, 3], axis=1),
        translation_m=poses[:, :3, 3],
        quaternion_wxyz=q,
        sun_target=np.tile([1.0, 0.0, 0.0], (n, 1)),
    )


def as_cloud(points) -> PointCloud:
    return PointCloud(points=np.asarray(points, dtype=np.float64), attributes={})


def test_the_model_is_on_the_mesh_in_the_body_frame_with_unit_normals(mro, model):
    assert len(model.points_m) == tracking.MODEL_POINTS
    np.testing.assert_allclose(np.linalg.norm(model.normals, axis=1), 1.0, atol=1e-9)
    # the body frame is the mesh's turned by body_from_mesh: the same radius, the same box turned
    assert model.radius_m <= mro.surface.radius_m + 1e-9
    box_body = np.ptp(model.points_m @ np.asarray(mro.body_from_mesh), axis=0)
    assert np.all(box_body <= mro.extents_m + 1e-9)


def test_the_tracker_recovers_a_known_pose_from_a_noise_free_cloud_with_no_prior(model, cloud, mro):
    result = tracking.track([as_cloud(cloud)], mro, truth_of([TRUE_POSE]), cloud_model=model)
    assert result.methods == ("global",)  # the first frame: no seed, the truth unused
    assert not result.lost[0]
    assert result.rotation_error_deg[0] < ROT_TOL_DEG
    assert result.translation_error_m[0] < TRA_TOL_M


def test_a_cloud_moved_by_a_known_small_transform_gives_that_transform(model, cloud):
    delta = pose_matrix(np.radians([1.2, -0.8, 1.5]), [0.06, -0.04, 0.09])  # sensor frame
    moved = cloud @ delta[:3, :3].T + delta[:3, 3]
    estimate = tracking.register(moved, model, TRUE_POSE).pose
    recovered = estimate @ np.linalg.inv(TRUE_POSE)
    rot_deg, tra_m = tracking.pose_errors(recovered @ TRUE_POSE, delta @ TRUE_POSE)
    assert rot_deg < ROT_TOL_DEG and tra_m < TRA_TOL_M


def test_a_frame_with_too_few_points_is_flagged_lost_not_silently_wrong(model, cloud, mro):
    few = cloud[: tracking.MIN_POINTS - 1]
    result = tracking.track([as_cloud(few)], mro, truth_of([TRUE_POSE]), cloud_model=model)
    assert result.lost.tolist() == [True] and result.methods == ("too few",)
    assert result.points_used[0] == tracking.MIN_POINTS - 1
    summary = result.summary()
    assert summary["n_lost"] == 1 and summary["rotation_error_deg_median"] is None


def test_a_cloud_of_no_target_is_lost_by_its_fitness(model):
    rng = np.random.default_rng(5)
    scattered = rng.uniform(-6.0, 6.0, size=(400, 3)) + [0.0, 0.0, 60.0]  # a 12 m cube of dust
    reg = tracking.register(scattered, model, TRUE_POSE)
    assert reg.n_points == 400 and reg.fitness < tracking.MIN_FITNESS
    assert tracking.is_lost(reg)


@pytest.mark.slow
def test_a_seeded_frame_follows_the_motion_of_the_last_two(model, mro):
    # three frames of a target spinning 4 deg a frame about its body y axis, at a fixed range:
    # the third is seeded by constant velocity and tracked, not re-acquired
    spin = [pose_matrix([0.0, np.radians(4.0 * k), 0.0], [0.0, 0.0, 0.0]) for k in range(3)]
    poses = [TRUE_POSE @ s for s in spin]
    view = tracking.model_points(mro, 4000, seed=11)
    clouds = [as_cloud(view.seen_from(p) @ p[:3, :3].T + p[:3, 3]) for p in poses]
    result = tracking.track(clouds, mro, truth_of(poses), cloud_model=model)
    assert result.methods[0] == "global" and result.methods[2] == "tracked"
    assert not result.lost.any()
    assert np.all(result.rotation_error_deg < ROT_TOL_DEG)
    assert np.all(result.translation_error_m < TRA_TOL_M)
    assert len(result.rows()) == 3 and len(result.rows()[0]) == len(tracking.TRACK_COLUMNS)


@pytest.mark.slow
def test_a_frame_whose_centre_jumped_is_recentred_on_its_cloud_not_lost(model, mro, cloud):
    # the second frame of an approach is seeded by the first alone: 15 m closer, the seed's
    # centre is off by far more than the correspondence distance
    closer = TRUE_POSE.copy()
    closer[2, 3] -= 15.0
    view = tracking.model_points(mro, 4000, seed=13)
    second = view.seen_from(closer) @ closer[:3, :3].T + closer[:3, 3]
    result = tracking.track(
        [as_cloud(cloud), as_cloud(second)], mro, truth_of([TRUE_POSE, closer]), cloud_model=model
    )
    assert result.methods == ("global", "recentred")
    assert not result.lost.any()
    assert result.rotation_error_deg[1] < ROT_TOL_DEG
    assert result.translation_error_m[1] < TRA_TOL_M
