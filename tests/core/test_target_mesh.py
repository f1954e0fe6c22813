"""The target's triangles, normals and extents are computed without trimesh, bit for bit as trimesh
computed them (the golden outputs depend on every bit), and trimesh stays unimported on the cached
path."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import simcore
from simcore.scene import Target
from simcore.target import _resolve, mesh_geometry

ROOT = Path(__file__).resolve().parents[2]


def trimesh_reference(target: Target, scale: float | None = None) -> trimesh.Trimesh:
    """The target as load_target made it with trimesh: the file's geometry, centred on its
    bounding box, scaled (``scale``, else the built-in's longest extent)."""
    path, settings, _ = _resolve(target)
    geometry = mesh_geometry(path)
    mesh = trimesh.Trimesh(
        geometry.vertices.copy(), geometry.faces.copy(), process=False, validate=False
    )
    assert mesh.area > 0
    if scale is None:
        scale = settings["longest_extent_m"] / mesh.extents.max()
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale(scale)
    return mesh


def write_mesh(path: Path, vertices, faces) -> str:
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    return str(path)


def assert_bitwise_equal(ours: np.ndarray, theirs: np.ndarray) -> None:
    theirs = np.asarray(theirs)
    assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
    assert ours.tobytes() == theirs.tobytes()


def lumpy_sphere(offset, stretch) -> tuple[np.ndarray, np.ndarray]:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    rng = np.random.default_rng(11)
    vertices = sphere.vertices * stretch * rng.uniform(0.9, 1.1, (len(sphere.vertices), 1))
    return vertices + offset, sphere.faces


CASES = {
    # (vertices offset, stretch, scale_m_per_unit): off-centre, in millimetres, already centred
    "off-centre mm": ((1200.0, -350.0, 40.0), (900.0, 400.0, 250.0), 1e-3),
    "metres, scale 1": ((0.3, 0.1, -0.2), (2.0, 1.0, 0.5), 1.0),
    "centred, scale 2.5": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 2.5),
}


@pytest.mark.parametrize("case", list(CASES))
def test_vertices_normals_and_extents_are_trimeshs_bit_for_bit(tmp_path, case):
    offset, stretch, scale = CASES[case]
    vertices, faces = lumpy_sphere(np.array(offset), np.array(stretch))
    faces = np.vstack([faces, [[0, 0, 1]]])  # a degenerate triangle: a zero normal
    target = Target(mesh=write_mesh(tmp_path / "blob.ply", vertices, faces), scale_m_per_unit=scale)
    model = simcore.load_target(target)
    reference = trimesh_reference(target, scale)
    assert_bitwise_equal(model.vertices_m, reference.vertices)
    assert_bitwise_equal(model.faces, reference.faces)
    assert_bitwise_equal(model.face_normals, reference.face_normals)
    assert_bitwise_equal(model.extents_m, reference.extents)
    assert not model.face_normals[-1].any()
    assert model.radius_m == float(np.linalg.norm(reference.vertices, axis=1).max())


def test_the_built_in_target_is_trimeshs_bit_for_bit():
    target = simcore.load_scene().target
    model = simcore.load_target(target)
    reference = trimesh_reference(target)
    assert_bitwise_equal(model.vertices_m, reference.vertices)
    assert_bitwise_equal(model.face_normals, reference.face_normals)
    assert_bitwise_equal(model.extents_m, reference.extents)


def test_the_mesh_is_still_a_trimesh_of_the_same_arrays(tmp_path):
    vertices, faces = lumpy_sphere(np.zeros(3), np.ones(3))
    model = simcore.load_target(
        Target(mesh=write_mesh(tmp_path / "blob.obj", vertices, faces), scale_m_per_unit=1.0)
    )
    assert isinstance(model.mesh, trimesh.Trimesh)
    assert model.mesh is model.mesh  # made once
    np.testing.assert_array_equal(model.mesh.vertices, model.vertices_m)
    np.testing.assert_array_equal(model.mesh.faces, model.faces)


def test_the_target_arrays_are_read_only_and_shared_by_material_copies():
    model = simcore.load_target(simcore.load_scene().target)
    for array in (model.vertices_m, model.faces, model.face_normals):
        assert not array.flags.writeable
    recoloured = simcore.target.with_materials(model, [("*", "coating_1")])
    assert recoloured.surface is model.surface


PROBE = """
import json, sys
import simcore
model = simcore.load_target(simcore.load_scene().target)
simcore.geometry.RayCaster(model)
print(json.dumps(sorted(m for m in ("trimesh", "scipy.optimize") if m in sys.modules)))
"""


def test_a_cached_target_is_loaded_and_cast_against_without_importing_trimesh():
    simcore.load_target(simcore.load_scene().target)  # fills this session's cache
    done = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert json.loads(done.stdout) == []
