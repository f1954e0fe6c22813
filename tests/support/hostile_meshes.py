"""Mesh files that declare far more than they hold, written by the tests themselves: small files
that a reader sizing its arrays by their headers would expand to gigabytes."""

from __future__ import annotations

import struct

import numpy as np

from support.gltf import glb

UINT32, FLOAT32 = 5125, 5126


def bufferless_glb(n_meshes: int = 400, n_triangles: int = 300_000) -> bytes:
    """``n_meshes`` meshes whose one primitive uses two accessors declaring ``n_triangles``
    triangles with no buffer behind them (trimesh: zeros of that size, copied into each mesh):
    about 30 kB for 400 meshes, 5.6 GB once expanded."""
    tree = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(n_meshes))}],
        "nodes": [{"mesh": i} for i in range(n_meshes)],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]} for _ in range(n_meshes)
        ],
        "accessors": [
            {"componentType": UINT32, "count": 3 * n_triangles, "type": "SCALAR"},
            {"componentType": FLOAT32, "count": n_triangles, "type": "VEC3"},
        ],
    }
    return glb(tree, b"")


def _strip(n_triangles: int) -> tuple[bytes, int]:
    """The bytes of a strip of ``n_triangles`` triangles (uint32 indices, then float32
    positions) and the offset of the positions."""
    n_vertices = n_triangles + 2
    faces = np.column_stack([np.arange(n_triangles) + k for k in range(3)]).astype("<u4")
    x = np.arange(n_vertices, dtype="<f4") // 2
    y = (np.arange(n_vertices) % 2).astype("<f4")
    vertices = np.column_stack([x, y, np.zeros(n_vertices, "<f4")]).astype("<f4")
    indices = faces.tobytes()
    return indices + vertices.tobytes(), len(indices)


def shared_accessor_glb(
    n_meshes: int, n_triangles: int, n_nodes: int | None = None, buffer_extra: int = 0
) -> bytes:
    """A real strip of ``n_triangles`` triangles whose two accessors every one of ``n_meshes``
    meshes uses, shown by ``n_nodes`` nodes (default: one a mesh); the buffer declares
    ``buffer_extra`` bytes more than the file holds."""
    data, offset = _strip(n_triangles)
    n_vertices = n_triangles + 2
    nodes = [{"mesh": i % n_meshes} for i in range(n_nodes or n_meshes)]
    tree = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]} for _ in range(n_meshes)
        ],
        "buffers": [{"byteLength": len(data) + buffer_extra}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": offset},
            {"buffer": 0, "byteOffset": offset, "byteLength": len(data) - offset},
        ],
        "accessors": [
            {"componentType": UINT32, "count": 3 * n_triangles, "type": "SCALAR", "bufferView": 0},
            {
                "componentType": FLOAT32,
                "count": n_vertices,
                "type": "VEC3",
                "bufferView": 1,
                "min": [0, 0, 0],
                "max": [float(n_vertices // 2), 1, 0],
            },
        ],
    }
    return glb(tree, data)


def ply_claiming(n_vertices: int, n_faces: int, ascii: bool = False) -> bytes:
    """A PLY whose header declares ``n_vertices`` and ``n_faces`` over one triangle of data."""
    kind = "ascii" if ascii else "binary_little_endian"
    header = (
        f"ply\nformat {kind} 1.0\nelement vertex {n_vertices}\nproperty float x\n"
        f"property float y\nproperty float z\nelement face {n_faces}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode()
    if ascii:
        return header + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    body = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    return header + body + b"\x03" + np.array([0, 1, 2], "<i4").tobytes()


def stl_claiming(n_triangles: int, n_held: int = 1) -> bytes:
    """A binary STL whose header declares ``n_triangles`` and that holds ``n_held``."""
    row = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"\0" * 80 + struct.pack("<I", n_triangles) + row * n_held


def obj_of(n_triangles: int) -> bytes:
    """An OBJ of three vertices and ``n_triangles`` faces using them."""
    return b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + b"f 1 2 3\n" * n_triangles
