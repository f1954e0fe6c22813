"""Mesh files bounded before they expand: what a glTF's primitives declare (every mesh counted,
each node showing it counted), every buffer holding what its accessors need, and what an OBJ,
PLY or STL header declares, checked before trimesh makes any array; files within the limits
still load. The hostile files are written here (tests/support/hostile_meshes.py)."""

from __future__ import annotations

import io
import json
import logging
import resource
import struct

import numpy as np
import pytest
import trimesh
from support.gltf import draco_glb, glb
from support.hostile_meshes import (
    bufferless_glb,
    obj_of,
    ply_claiming,
    shared_accessor_glb,
    stl_claiming,
)

from app.logic.upload import MAX_UPLOAD_FACES, UploadError, self_contained_glb
from simcore.mesh_headers import declared_counts
from simcore.target import TargetError
from simcore.target_mesh import load_mesh_file


def load(data: bytes, kind: str, **limits):
    return load_mesh_file(io.BytesIO(data), file_type=kind, resolver=None, **limits)


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def test_the_400_mesh_bufferless_glb_is_refused_before_any_array_is_made():
    data = bufferless_glb()
    assert len(data) < 40_000  # the 0.03 MiB file
    before = peak_rss_mb()
    with pytest.raises(TargetError, match=r"accessor 0 declares 900,000 elements and has no"):
        load(data, "glb")
    assert peak_rss_mb() - before < 100  # trimesh would have made 400 copies of 7 MB arrays


@pytest.mark.parametrize(
    ("n_meshes", "n_nodes"), [(400, None), (1, 400)], ids=["meshes-share", "nodes-show"]
)
def test_triangles_are_summed_over_every_mesh_and_node_before_trimesh_reads_them(n_meshes, n_nodes):
    """3,000 real triangles, used by 400 meshes or shown by 400 nodes: 1.2 M in all."""
    data = shared_accessor_glb(n_meshes, 3000, n_nodes=n_nodes)
    with pytest.raises(
        UploadError, match=r"declare 1,200,000 triangles in all \(at most 1,000,000"
    ):
        self_contained_glb(data, ".glb")
    with pytest.raises(TargetError, match="1,200,000 triangles"):
        load(data, "glb", max_faces=1_199_999)
    scene = load(data, "glb", max_faces=1_200_000)  # at the limit: read
    assert sum(len(g.faces) for g in scene.geometry.values()) == 3000 * n_meshes


def test_a_valid_glb_under_the_limits_loads_with_its_triangles():
    glb_bytes, n_faces = self_contained_glb(shared_accessor_glb(2, 30), ".glb")
    assert n_faces == 60
    again = trimesh.load(io.BytesIO(glb_bytes), file_type="glb")
    assert sum(len(g.faces) for g in again.geometry.values()) == 60


def _tree_and_bin(data: bytes) -> tuple[dict, bytes]:
    (n,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + n]), data[20 + n + 8 :]


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda t: t["buffers"][0].update(byteLength=t["buffers"][0]["byteLength"] + 64),
         r"buffer 0 declares \d+ bytes but holds"),
        (lambda t: t["bufferViews"][1].update(byteOffset=10_000),
         "bufferView 1 runs past the end of buffer 0"),
        (lambda t: t["accessors"][0].update(count=300_000),
         r"accessor 0 needs 1,200,000 bytes of its bufferView, which holds 360"),
        (lambda t: t["accessors"][1].update(byteOffset=8),
         "accessor 1 needs"),
        (lambda t: t["bufferViews"][0].update(byteStride=2), "byteStride 2 is not 4 to 252"),
        (lambda t: t["accessors"][0].update(componentType=5130), "componentType|component 5130"),
        (lambda t: t["meshes"][0]["primitives"][0].update(indices=7), "accessor 7 does not exist"),
        (lambda t: t["buffers"][0].update(uri="../../etc/passwd"), "external file"),
    ],
    ids=["buffer-short", "view-past-buffer", "accessor-past-view", "offset-past-view",
         "bad-stride", "bad-component", "missing-accessor", "external-buffer"],
)  # fmt: skip
def test_buffers_that_do_not_hold_what_their_accessors_need_are_refused(damage, message):
    tree, binary = _tree_and_bin(shared_accessor_glb(1, 30))
    damage(tree)
    with pytest.raises(UploadError, match=message) as error:
        self_contained_glb(glb(tree, binary), ".glb")
    assert "\n" not in str(error.value)


def test_a_draco_stream_that_decodes_to_more_than_the_limit_is_refused_after_decoding():
    """The accessors declare one triangle; the stream decodes to 320 (the decoded counts are
    summed again)."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    tree, binary = _tree_and_bin(draco_glb(sphere.vertices, sphere.faces))
    tree["accessors"][0]["count"] = 3
    tree["accessors"][1]["count"] = 3
    data = glb(tree, binary)
    with pytest.raises(TargetError, match=r"decode to 320 triangles in all \(at most 100\)"):
        load(data, "glb", max_faces=100)
    assert len(load(data, "glb", max_faces=320).geometry) == 1


@pytest.mark.parametrize(
    ("data", "kind", "message"),
    [
        (ply_claiming(10**9, 10**9), "ply", r"declares 1,000,000,000 'vertex' and 1,000,000,000 "
         r"'face' rows, at least 25,000,000,000 bytes of data; the file holds 49"),
        (ply_claiming(3, 2_000_000), "ply", "26,000,036 bytes of data"),
        (ply_claiming(3, 500_000, ascii=True), "ply", "4,000,018 bytes of data; the file holds 26"),
        (b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", "ply", "line 3 is not"),
        (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty fl x\nend_header\n", "ply",
         "line 4 is not a known property"),
        (stl_claiming(2**31), "stl", "length does not match the triangle count"),
        (stl_claiming(3, 2), "stl", "length does not match"),
        (obj_of(MAX_UPLOAD_FACES + 1), "obj", "declares 1,000,001 triangles; the limit is"),
    ],
    ids=["ply-binary-huge", "ply-binary-faces", "ply-ascii", "ply-bad-count",
         "ply-bad-property", "stl-huge", "stl-short", "obj-over"],
)  # fmt: skip
def test_obj_ply_and_stl_headers_over_the_limits_or_their_data_are_refused(data, kind, message):
    with pytest.raises(UploadError, match=message) as error:
        self_contained_glb(data, f".{kind}")
    assert "\n" not in str(error.value)


def test_headers_within_the_limits_load_and_count_what_they_declare():
    assert declared_counts(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3 4\n f 1 2 3\n", "obj") == (
        3,
        4,
    )
    assert declared_counts(stl_claiming(2, 2), "stl") == (2, 6)
    assert declared_counts(ply_claiming(3, 1), "ply") == (1, 3)
    for data, kind in [(stl_claiming(2, 2), ".stl"), (ply_claiming(3, 1), ".ply")]:
        assert self_contained_glb(data, kind)[1] >= 1
    ascii_stl = trimesh.creation.box().export(file_type="stl_ascii").encode()
    assert declared_counts(ascii_stl, "stl") == (12, 36)
    assert self_contained_glb(ascii_stl, ".stl")[1] == 12


def test_a_ply_naming_a_texture_file_loads_without_a_traceback(caplog):
    """An upload brings no texture file: the comment is ignored, nothing logged."""
    box = trimesh.creation.box()
    text = box.export(file_type="ply", encoding="ascii")
    text = text.replace(b"end_header", b"comment TextureFile secret.png\nend_header")
    with caplog.at_level(logging.DEBUG):
        _, n_faces = self_contained_glb(text, ".ply")
    assert n_faces == 12
    assert not [r for r in caplog.records if r.exc_info or r.levelno >= logging.WARNING]


def test_an_ascii_ply_polygon_counts_as_a_triangle_at_least():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False)
    data = mesh.export(file_type="ply", encoding="ascii")
    assert declared_counts(data, "ply") == (2, 4)
