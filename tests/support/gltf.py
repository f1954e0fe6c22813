"""Binary glTF files made in the tests: a mesh as one Draco-compressed primitive."""

from __future__ import annotations

import json
import struct

import DracoPy
import numpy as np

DRACO = "KHR_draco_mesh_compression"
QUANTIZATION_BITS = 16  # Draco moves a vertex by at most half a step: extent * 2**-(bits + 1)


def draco_stream(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A Draco-compressed mesh (vertex order kept)."""
    return bytes(
        DracoPy.encode(
            np.asarray(vertices, dtype=np.float32),
            np.asarray(faces, dtype=np.uint32),
            quantization_bits=QUANTIZATION_BITS,
            preserve_order=True,
        )
    )


def glb(tree: dict, binary: bytes) -> bytes:
    """A binary glTF of the JSON ``tree`` and the BIN chunk ``binary`` (both padded to 4)."""
    text = json.dumps(tree).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    length = 12 + 8 + len(text) + 8 + len(binary)
    return (
        b"glTF"
        + struct.pack("<II", 2, length)
        + struct.pack("<II", len(text), 0x4E4F534A)
        + text
        + struct.pack("<II", len(binary), 0x004E4942)
        + binary
    )


def draco_glb(
    vertices: np.ndarray, faces: np.ndarray, stream: bytes | None = None, material: str = "hull"
) -> bytes:
    """A glb holding ``vertices`` and ``faces`` as one Draco-compressed primitive (``stream``:
    another stream in its place, e.g. a broken one), its material named ``material``."""
    stream = draco_stream(vertices, faces) if stream is None else stream
    v = np.asarray(vertices, dtype=np.float32)
    tree = {
        "asset": {"version": "2.0"},
        "extensionsUsed": [DRACO],
        "extensionsRequired": [DRACO],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "body"}],
        "materials": [{"name": material}],
        "meshes": [
            {
                "name": "body",
                "primitives": [
                    {
                        "attributes": {"POSITION": 1},
                        "indices": 0,
                        "material": 0,
                        "mode": 4,
                        "extensions": {DRACO: {"bufferView": 0, "attributes": {"POSITION": 0}}},
                    }
                ],
            }
        ],
        "accessors": [
            {"componentType": 5125, "count": int(np.size(faces)), "type": "SCALAR"},
            {
                "componentType": 5126,
                "count": len(v),
                "type": "VEC3",
                "min": v.min(axis=0).tolist(),
                "max": v.max(axis=0).tolist(),
            },
        ],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(stream)}],
        "buffers": [{"byteLength": len(stream) + (-len(stream) % 4)}],
    }
    return glb(tree, stream)
