"""Uploads read Draco-compressed glTF through the core's loader: a compressed mesh is accepted
with its triangles, a broken stream refused with the loader's one message."""

from __future__ import annotations

import pytest
import trimesh
from support.gltf import draco_glb

from app.logic.upload import UploadError, self_contained_glb


def test_a_draco_upload_is_read_with_its_triangles():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    data, n_faces = self_contained_glb(draco_glb(sphere.vertices, sphere.faces), ".glb")
    assert n_faces == len(sphere.faces) and data[:4] == b"glTF"
    assert b"KHR_draco_mesh_compression" not in data


def test_a_broken_draco_upload_is_refused_with_one_message():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    with pytest.raises(UploadError, match="Draco-compressed primitive 0 cannot be decoded"):
        self_contained_glb(draco_glb(sphere.vertices, sphere.faces, stream=b"junk" * 10), ".glb")
