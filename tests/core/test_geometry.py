"""Poses, the pixel grid and first-hit ray casting (embreex against trimesh's numpy caster)."""

import numpy as np
import pytest
import trimesh
from trimesh.ray.ray_triangle import RayMeshIntersector

import simcore
from simcore import geometry
from simcore.scene import Pose, Target


@pytest.fixture
def sphere_model(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    mesh.apply_scale((1.0, 1.5, 0.7))
    path = tmp_path / "blob.ply"
    mesh.export(path)
    return simcore.load_target(Target(mesh=str(path), scale_m_per_unit=1.0))


def test_embree_first_hits_match_trimeshs_numpy_caster(sphere_model):
    rng = np.random.default_rng(3)
    origin = np.array([0.3, -0.2, -6.0])
    aim = rng.uniform(-1.2, 1.2, size=(400, 3)) * (1, 1, 0)
    dirs = aim - origin
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    range_m, face = geometry.RayCaster(sphere_model).first_hits(origin, dirs, start_m=3.0)

    ref = RayMeshIntersector(sphere_model.mesh)
    tri, ray, loc = ref.intersects_id(
        np.tile(origin, (len(dirs), 1)), dirs, multiple_hits=False, return_locations=True
    )
    ref_range = np.full(len(dirs), np.inf)
    ref_range[ray] = np.linalg.norm(loc - origin, axis=1)
    ref_face = np.full(len(dirs), -1)
    ref_face[ray] = tri
    hit = np.isfinite(ref_range)
    assert hit.sum() > 100 and (~hit).sum() > 20  # both hits and misses are exercised
    assert np.array_equal(np.isfinite(range_m), hit)
    assert np.allclose(range_m[hit], ref_range[hit], atol=1e-5)
    # faces agree except where a ray grazes an edge between two faces at the same distance
    assert np.mean(face[hit] == ref_face[hit]) > 0.98


def test_front_view_looks_along_the_smallest_extent_with_the_largest_across():
    rot = geometry.front_view_rotation(np.array([32.76, 61.01, 89.74]))  # the MRO's box
    assert np.allclose(rot @ rot.T, np.eye(3)) and np.isclose(np.linalg.det(rot), 1.0)
    assert np.allclose(np.abs(rot @ [1, 0, 0]), [0, 0, 1])  # smallest extent on the boresight
    assert np.allclose(rot @ [0, 0, 1], [1, 0, 0])  # largest along the image x axis
    assert np.allclose(rot @ [0, 1, 0], [0, -1, 0])  # middle one up (image y points down)


def test_pitch_turns_about_the_array_horizontal_and_azimuth_about_its_vertical():
    extents = np.array([1.0, 2.0, 3.0])
    r0 = geometry.front_view_rotation(extents)
    p = geometry.target_pose(Pose(pitch_deg=30.0), extents).rotation
    a = geometry.target_pose(Pose(azimuth_deg=30.0), extents).rotation
    assert np.allclose(p, geometry.rotation_x(np.radians(30)) @ r0)
    assert np.allclose(a, geometry.rotation_y(np.radians(30)) @ r0)
    pose = geometry.target_pose(Pose(distance_m=750.0), extents)
    assert np.allclose(pose.translation_m, [0, 0, 750.0])


def test_quaternion_pose_composes_with_the_body_frame():
    q = (np.cos(0.2), 0.0, np.sin(0.2), 0.0)  # 0.4 rad about y
    body = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]], float)
    rot = geometry.target_pose(Pose(quaternion_wxyz=q), np.ones(3), body).rotation
    assert np.allclose(rot, geometry.rotation_y(0.4) @ body)


def test_pixel_grid_spans_the_field_of_view_and_centres_look_along_pinhole_directions():
    rays = geometry.ray_grid(pixels=8, fov_rad=0.03, subrays=4)
    assert rays.directions.shape == (64, 4, 3)
    assert np.allclose(np.linalg.norm(rays.directions, axis=-1), 1.0)
    tan_x = rays.directions[..., 0] / rays.directions[..., 2]
    assert tan_x.max() < np.tan(0.015) and tan_x.max() > np.tan(0.015) * (1 - 1 / 8)
    # the pixel centre direction is the mean of its sub-ray tangents
    centre_tan = rays.pixel_directions[:, :2] / rays.pixel_directions[:, 2:]
    sub_tan = rays.directions[..., :2] / rays.directions[..., 2:]
    assert np.allclose(centre_tan, sub_tan.mean(axis=1))
    # row index grows downwards (+y), column index to the right (+x)
    assert rays.pixel_directions[0, 1] < 0 and rays.pixel_directions[0, 0] < 0


def test_far_targets_keep_millimetre_ranges_despite_embrees_float32(plate_scene):
    res = simcore.Pipeline().run(plate_scene(size_m=4000.0, distance_m=100_000.0, pixels=8))
    centre = res.hits.range_m.reshape(8, 8, -1)[4, 4, 0]
    d = res.rays.directions.reshape(8, 8, -1, 3)[4, 4, 0]
    assert centre == pytest.approx((100_000.0 - 0.5e-3) / d[2], abs=2e-3)  # 0.5 mm: plate face
