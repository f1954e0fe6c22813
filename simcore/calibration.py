"""Calibration targets: a flat plate, a sphere, a cube and a cylinder, built in numpy.

Shapes with closed forms (docs/physics.md#calibration-targets): a plate at normal incidence
returns what the lidar equation of a resolved Lambertian plane gives, a sphere spreads its echo
over its radius. Each is made with its longest bounding-box side 1 mesh unit long, one part named
after the shape, and is scaled by ``target.size_m`` (default ``DEFAULT_SIZE_M``) like any mesh.
Their default material is the library's Lambertian (albedo 1); ``[target.materials]`` changes it.

- ``plate``: a square in the mesh x-y plane, 2 triangles (its normal is mesh z);
- ``cube``: 12 triangles;
- ``sphere``: a latitude-longitude sphere, ``SPHERE_RINGS`` rings of ``2 SPHERE_RINGS``
  segments (the facets lie within 1 - cos(pi / (2 SPHERE_RINGS)) = 1.3e-4 radii of the sphere);
- ``cylinder``: its axis along mesh z, height = diameter, ``CYLINDER_SEGMENTS`` sides and both
  caps.
"""

from __future__ import annotations

import numpy as np

SHAPES = ("plate", "sphere", "cube", "cylinder")
DEFAULT_SIZE_M = 2.0  # [m] longest side of a calibration target when target.size_m is not given
DEFAULT_MATERIAL = "lambertian"
SPHERE_RINGS = 96  # [1] latitude rings (a multiple of 2: a vertex ring on the equator)
CYLINDER_SEGMENTS = 128  # [1] sides (a multiple of 4: the box is exactly the diameter)

TITLES = {
    "plate": "Flat square plate (calibration)",
    "sphere": "Sphere (calibration)",
    "cube": "Cube (calibration)",
    "cylinder": "Cylinder, height = diameter (calibration)",
}


def _plate() -> tuple[np.ndarray, np.ndarray]:
    vertices = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
    return vertices, np.array([[0, 1, 2], [0, 2, 3]])


def _cube() -> tuple[np.ndarray, np.ndarray]:
    vertices = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    faces = np.array(
        [
            [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6],  # x = -/+
            [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3],  # y = -/+
            [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5],  # z = -/+
        ]
    )  # fmt: skip
    return vertices, faces[:, ::-1]  # outward normals


def _sphere(rings: int = SPHERE_RINGS) -> tuple[np.ndarray, np.ndarray]:
    segments = 2 * rings
    polar = np.linspace(0.0, np.pi, rings + 1)[1:-1]  # the inner rings (poles apart)
    azimuth = 2.0 * np.pi * np.arange(segments) / segments
    s, c = np.sin(polar)[:, None], np.cos(polar)[:, None]
    shape = (len(polar), segments)
    ring = np.stack(
        [s * np.cos(azimuth), s * np.sin(azimuth), np.broadcast_to(c, shape)], axis=-1
    ).reshape(-1, 3)
    vertices = 0.5 * np.vstack([[0.0, 0.0, 1.0], ring, [0.0, 0.0, -1.0]])
    south = len(vertices) - 1
    j = np.arange(segments)
    k = (j + 1) % segments
    faces = [np.column_stack([np.zeros(segments, int), 1 + j, 1 + k])]
    for r in range(rings - 2):
        a, b = 1 + r * segments, 1 + (r + 1) * segments
        faces += [np.column_stack([a + j, b + j, b + k]), np.column_stack([a + j, b + k, a + k])]
    last = 1 + (rings - 2) * segments
    faces.append(np.column_stack([last + j, np.full(segments, south), last + k]))
    return vertices, np.vstack(faces)


def _cylinder(segments: int = CYLINDER_SEGMENTS) -> tuple[np.ndarray, np.ndarray]:
    azimuth = 2.0 * np.pi * np.arange(segments) / segments
    x, y = 0.5 * np.cos(azimuth), 0.5 * np.sin(azimuth)
    top = np.column_stack([x, y, np.full(segments, 0.5)])
    bottom = np.column_stack([x, y, np.full(segments, -0.5)])
    vertices = np.vstack([top, bottom, [[0.0, 0.0, 0.5], [0.0, 0.0, -0.5]]])
    j = np.arange(segments)
    k = (j + 1) % segments
    n = segments
    faces = np.vstack(
        [
            np.column_stack([j, n + j, n + k]),  # the sides
            np.column_stack([j, n + k, k]),
            np.column_stack([np.full(n, 2 * n), j, k]),  # the top cap
            np.column_stack([np.full(n, 2 * n + 1), n + k, n + j]),  # the bottom cap
        ]
    )
    return vertices, faces


_BUILDERS = {"plate": _plate, "sphere": _sphere, "cube": _cube, "cylinder": _cylinder}


def shape_mesh(shape: str) -> tuple[np.ndarray, np.ndarray]:
    """The calibration shape ``shape`` (one of SHAPES) with its longest box side 1 unit long.

    Returns
    -------
    vertices : (n_vertices, 3) float64 [mesh units], centred on the origin
    faces : (n_faces, 3) int64 -- vertex indices of each triangle
    """
    vertices, faces = _BUILDERS[shape]()
    return np.ascontiguousarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
