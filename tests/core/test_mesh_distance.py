"""The exact point-to-mesh distances (simcore.mesh_distance): against closed forms (a square
plate, a cube), the shared tree against one built for the query alone, and the tree built once
for many frames of one mesh, kept for a bounded number of meshes and dropped with its mesh."""

from __future__ import annotations

import gc
import math
import weakref

import numpy as np
import pytest

from simcore import mesh_distance
from simcore.pipeline import Pipeline
from simcore.scene import load_scene, with_overrides
from simcore.target_mesh import TargetMesh

HALF_M = 0.75  # half the side of the plate and of the cube [m]


def _mesh(vertices, faces) -> TargetMesh:
    return TargetMesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))


def _plate() -> TargetMesh:
    """The square |x|, |y| <= HALF_M in the plane z = 0, two triangles."""
    h = HALF_M
    return _mesh([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], [[0, 1, 2], [0, 2, 3]])


def _cube() -> TargetMesh:
    """The surface of the cube |x|, |y|, |z| <= HALF_M, twelve triangles."""
    h = HALF_M
    corners = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))]
    return _mesh(corners, faces)


@pytest.fixture
def counted_builds(monkeypatch):
    """The trees built from now on, counted (every kept tree dropped first)."""
    built: list[int] = []
    build = mesh_distance._new_tree

    def counting(vertices_m, faces):
        built.append(len(faces))
        return build(vertices_m, faces)

    mesh_distance.clear()
    monkeypatch.setattr(mesh_distance, "_new_tree", counting)
    yield built
    mesh_distance.clear()


def test_distances_to_a_plate_are_its_closed_form_with_or_without_the_shared_tree():
    rng = np.random.default_rng(5)
    points = rng.uniform([-2.0, -2.0, -1.0], [2.0, 2.0, 1.0], size=(2000, 3))
    # over the plate |z|; beside it the distance to the nearest edge or corner in the plane
    outside = np.maximum(np.abs(points[:, :2]) - HALF_M, 0.0)
    want_m = np.sqrt(np.sum(outside**2, axis=1) + points[:, 2] ** 2)
    plate = _plate()
    shared = mesh_distance.closest_points(plate).distance_m(points)
    alone = mesh_distance.point_to_mesh_m(points, plate.vertices_m, plate.faces)
    assert np.array_equal(shared, alone)
    np.testing.assert_allclose(shared, want_m, rtol=0, atol=1e-12)
    # a point on the plate, and one straight above its centre
    on = mesh_distance.closest_points(plate).distance_m([[0.1, -0.2, 0.0], [0.0, 0.0, 0.4]])
    np.testing.assert_allclose(on, [0.0, 0.4], rtol=0, atol=1e-15)


def test_distances_to_a_cube_are_its_closed_form_inside_and_out():
    rng = np.random.default_rng(6)
    points = rng.uniform(-2.0, 2.0, size=(3000, 3))
    a = np.abs(points)
    inside = np.all(a <= HALF_M, axis=1)
    # outside: the distance to the box; inside: to the nearest face
    want_m = np.where(
        inside,
        HALF_M - a.max(axis=1),
        np.sqrt(np.sum(np.maximum(a - HALF_M, 0.0) ** 2, axis=1)),
    )
    assert 0 < inside.sum() < len(points)  # both cases are tried
    cube = _cube()
    shared = mesh_distance.closest_points(cube).distance_m(points)
    alone = mesh_distance.point_to_mesh_m(points, cube.vertices_m, cube.faces)
    assert np.array_equal(shared, alone)
    np.testing.assert_allclose(shared, want_m, rtol=0, atol=1e-12)


def test_no_points_or_no_triangles():
    assert mesh_distance.closest_points(_plate()).distance_m(np.zeros((0, 3))).shape == (0,)
    no_faces = mesh_distance.point_to_mesh_m([[0.0, 0.0, 1.0]], np.zeros((0, 3)), np.zeros((0, 3)))
    assert no_faces.tolist() == [math.inf]


def test_the_tree_is_built_once_for_many_frames_of_one_mesh(counted_builds):
    base = with_overrides(load_scene("paper"), pixels=16)
    pipeline = Pipeline()
    attitudes = [(p, a) for p in (-50.0, 0.0, 50.0) for a in (0.0, 120.0, 240.0)]
    figures = []
    for p, a in attitudes:
        result = pipeline.run(with_overrides(base, pitch_deg=p, azimuth_deg=a))
        figures.append(result.quality["distance_to_mesh_median_m"])
    assert len(counted_builds) == 1  # nine frames, one tree of the MRO's mesh
    assert counted_builds[0] == len(result.target.faces)
    assert sum(f is not None for f in figures) >= 6  # the frames measured distances
    # a frame of the same attitude computed with a tree of its own has the same figures
    mesh_distance.clear()
    again = Pipeline().run(with_overrides(base, pitch_deg=p, azimuth_deg=a))
    assert again.quality["distance_to_mesh_median_m"] == figures[-1]
    assert len(counted_builds) == 2


def test_trees_are_kept_for_a_bounded_number_of_meshes_and_go_with_their_mesh(counted_builds):
    meshes = [_plate() for _ in range(mesh_distance._KEPT + 3)]
    for m in meshes:
        mesh_distance.closest_points(m)
    assert len(mesh_distance._TREES) == mesh_distance._KEPT
    assert len(counted_builds) == len(meshes)
    # the last used are kept: asking again builds nothing; the first was dropped, it builds again
    mesh_distance.closest_points(meshes[-1])
    assert len(counted_builds) == len(meshes)
    mesh_distance.closest_points(meshes[0])
    assert len(counted_builds) == len(meshes) + 1
    # the kept tree does not hold its mesh: a mesh no one holds leaves the cache
    gone = weakref.ref(meshes[0])
    del meshes[0], m
    gc.collect()
    assert gone() is None
    assert len(mesh_distance._TREES) == mesh_distance._KEPT - 1
