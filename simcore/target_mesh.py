"""Mesh loading: a mesh file (glTF/OBJ/STL/PLY) read as parts (each with its opacity and mesh
names) through trimesh, NaN and infinite vertices refused; a target's size in metres from a given
size, scale or unit (and a warning naming the unit of a mesh scaled to no spacecraft's size); the
``TargetMesh``, its triangles in numpy, with the sums trimesh would make, bit for bit.

trimesh is imported only to read a mesh file (or for ``TargetMesh.as_trimesh``).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from .gltf import MAX_ACCESSOR_VALUES, MAX_TRIANGLES, MAX_VERTICES, GltfError, check_gltf_file
from .mesh_headers import MeshHeaderError, declared_counts

if TYPE_CHECKING:  # trimesh loads when a mesh file is read or ``TargetMesh.as_trimesh`` is asked
    import trimesh

    from .scene import Target

# longest extent of a target once scaled to metres: outside this the scale is surely wrong (a mesh
# in millimetres read as metres, or the reverse)
MIN_EXTENT_M = 1e-3
MAX_EXTENT_M = 1e4
# a spacecraft is 0.3 m (a small CubeSat) to 200 m (the ISS is 109 m across): a mesh scaled outside
# this is probably in another unit, and the warning names the likeliest
PLAUSIBLE_EXTENT_M = (0.3, 200.0)
LENGTH_UNITS_M = {"mm": 1e-3, "cm": 1e-2, "inch": 0.0254, "foot": 0.3048, "m": 1.0, "km": 1e3}


class TargetError(ValueError):
    """A mesh file is missing, unreadable or degenerate. The message names the file."""


_IDENTITY4 = np.eye(4)
_NORMAL_MIN = float(np.finfo(np.float64).resolution * 100)  # shorter cross products: no normal


def transformed_points(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(n, 3) ``points`` through the homogeneous (4, 4) ``matrix``, as trimesh's
    ``apply_transform`` computes them (the same products in the same order, so the vertices are
    bit for bit those of a target transformed by trimesh); a matrix within 1e-8 of the identity
    leaves them unchanged, as it does there."""
    offset = matrix - _IDENTITY4
    if float(np.ptp(offset)) < 1e-8 or np.abs(offset).max() < 1e-8:
        return points.copy()
    stack = np.column_stack((points, np.ones(len(points))))
    return np.ascontiguousarray(np.dot(matrix, stack.T).T[:, :3])


def edge_crosses(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n_faces, 3) cross product (v1 - v0) x (v2 - v1) of each triangle's edges: trimesh's
    (and numpy.cross's) products and differences, on one coordinate at a time (4x faster)."""
    corners = np.ascontiguousarray(faces.T)
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = (c[corners] for c in vertices.T)
    ax, ay, az = x1 - x0, y1 - y0, z1 - z0
    bx, by, bz = x2 - x1, y2 - y1, z2 - z1
    crosses = np.empty((len(faces), 3))
    np.subtract(ay * bz, az * by, out=crosses[:, 0])
    np.subtract(az * bx, ax * bz, out=crosses[:, 1])
    np.subtract(ax * by, ay * bx, out=crosses[:, 2])
    return crosses


def surface_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total area of the triangles [units^2] (trimesh's ``Trimesh.area``, bit for bit)."""
    crosses = edge_crosses(vertices, faces)
    return float((np.sqrt((crosses**2).sum(axis=1)) / 2.0).sum())


def mesh_bounds(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(2, 3) lowest and highest coordinates of the vertices the faces use."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces] = True
    coordinates = np.ascontiguousarray(vertices[used].T)
    return np.array([coordinates.min(axis=1), coordinates.max(axis=1)])


@dataclass(frozen=True, eq=False)
class TargetMesh:
    """A target's triangles in metres, in the target frame (origin at the bounding-box centre).

    What the ray caster and the app read is derived from the arrays on first use and kept, with
    trimesh's arithmetic (bit for bit what a ``trimesh.Trimesh`` of them gives); trimesh itself
    is imported only for :attr:`as_trimesh`.

    Attributes
    ----------
    vertices_m : (n_vertices, 3) float64 -- positions [m], read-only
    faces : (n_faces, 3) int64 -- vertex indices of each triangle, read-only
    """

    vertices_m: np.ndarray
    faces: np.ndarray

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(n_faces, 3) float64 unit normal of each triangle (right-handed in its vertex order;
        zero for a triangle without area), read-only."""
        crosses = edge_crosses(self.vertices_m, self.faces)
        norm = np.sqrt(np.dot(crosses * crosses, [1.0] * 3))
        valid = norm > _NORMAL_MIN
        norm[valid] **= -1
        normals = np.where(valid[:, None], crosses * norm.reshape((-1, 1)), 0.0)
        normals.setflags(write=False)
        return normals

    @cached_property
    def radius_m(self) -> float:
        """Radius of the bounding sphere about the target origin [m] (every vertex)."""
        return float(np.linalg.norm(self.vertices_m, axis=1).max())

    @cached_property
    def extents_m(self) -> np.ndarray:
        """(3,) size of the axis-aligned bounding box of the faces [m]."""
        return np.ptp(mesh_bounds(self.vertices_m, self.faces), axis=0)

    @cached_property
    def closed(self) -> bool:
        """Whether the triangles close a surface wound one way (trimesh's watertight and
        winding-consistent: every edge in two faces, reversed between them; a file's split
        vertices, or an open sheet, make it False). Made on first use, with :attr:`as_trimesh`."""
        mesh = self.as_trimesh
        return bool(mesh.is_watertight and mesh.is_winding_consistent)

    @cached_property
    def as_trimesh(self) -> trimesh.Trimesh:
        """The mesh as a ``trimesh.Trimesh`` (of copies of the arrays), made on first use."""
        import trimesh  # noqa: PLC0415  (a third of a second to import: only when asked for)

        return trimesh.Trimesh(
            self.vertices_m.copy(), self.faces.copy(), process=False, validate=False
        )


def load_mesh_file(
    file_obj,
    file_type: str | None,
    *,
    max_faces: int = MAX_TRIANGLES,
    max_vertices: int = MAX_VERTICES,
    max_values: int = MAX_ACCESSOR_VALUES,
    **load_options,
) -> trimesh.Trimesh | trimesh.Scene:
    """``trimesh.load`` of a mesh file that refuses NaN or infinite vertices in every format, and
    files that declare more than ``max_faces`` triangles or ``max_vertices`` vertices before any
    array is made: a glTF only once it has passed :func:`simcore.gltf.check_gltf_file` (the
    caps and totals, every buffer holding what its accessors need, and its Draco-compressed
    geometry decoded in a child process under memory and time limits); an OBJ, PLY or STL once
    its declared counts (:func:`simcore.mesh_headers.declared_counts`) are within the limits.

    trimesh's default processing drops the triangles of non-finite vertices from OBJ, PLY and STL
    files without a word (glTF is not processed), so the file is read unprocessed, checked, then
    processed as trimesh would have (the same vertices and faces as a default load).

    Parameters
    ----------
    file_obj : path or binary file
        A path (a ``.gltf``'s buffer files are read beside it) or an open file (a ``.gltf`` must
        then hold its buffers, a PLY's texture is not looked for: uploads read no other file).
    max_faces, max_vertices : int
        The most triangles and vertices the file may declare (all its meshes together).
    max_values : int
        The most scalar values a glTF's accessors may declare together.

    Raises
    ------
    TargetError
        A vertex coordinate is NaN or infinite; a file over the limits or that does not hold
        what it declares; a glTF over a cap or with compressed geometry that cannot be decoded
        (the message names no file: callers add it).
    """
    import trimesh  # noqa: PLC0415  (only to read a mesh file: the cached path needs none)

    kind = (file_type or "").lower().lstrip(".")
    if isinstance(file_obj, str | Path):
        data, folder = Path(file_obj).read_bytes(), Path(file_obj).parent
    else:
        data, folder = file_obj.read(), None
        file_obj = io.BytesIO(data)
        if kind == "ply":  # a texture comment names a file no upload brings
            load_options = {"skip_materials": True, **load_options}
    _check_declared(data, kind, folder, (max_faces, max_vertices, max_values))
    if kind == "obj":  # each named object (o) and group (g) of an OBJ becomes a part
        load_options = {"split_objects": True, "split_groups": True, **load_options}
    loaded = trimesh.load(file_obj, file_type=file_type, force=None, process=False, **load_options)
    geometries = loaded.geometry.values() if isinstance(loaded, trimesh.Scene) else [loaded]
    meshes = [g for g in geometries if isinstance(g, trimesh.Trimesh)]
    if not all(np.isfinite(g.vertices).all() for g in meshes):
        raise TargetError("the mesh has NaN or infinite vertex coordinates")
    if kind not in ("glb", "gltf"):
        for mesh in meshes:
            mesh.process()
    return cast("trimesh.Trimesh | trimesh.Scene", loaded)  # trimesh.load: one of the two here


def _check_declared(
    data: bytes, kind: str, folder: Path | None, limits: tuple[int, int, int]
) -> None:
    """TargetError if the file declares more than the limits (triangles, vertices, a glTF's
    accessor values) or less than it needs."""
    max_faces, max_vertices, max_values = limits
    if kind in ("glb", "gltf"):
        try:
            check_gltf_file(
                data,
                kind == "glb",
                folder,
                max_triangles=max_faces,
                max_vertices=max_vertices,
                max_values=max_values,
            )
        except GltfError as exc:
            raise TargetError(f"cannot read the .{kind} file ({exc})") from None
        return
    try:
        n_faces, n_vertices = declared_counts(data, kind)
    except MeshHeaderError as exc:
        raise TargetError(f"cannot read the .{kind} file ({exc})") from None
    if n_faces > max_faces:
        raise TargetError(
            f"the .{kind} file declares {n_faces:,} triangles; the limit is {max_faces:,}"
        )
    if n_vertices > max_vertices:
        raise TargetError(
            f"the .{kind} file declares {n_vertices:,} vertices; the limit is {max_vertices:,}"
        )


@dataclass(frozen=True)
class MeshPart:
    """One geometry of a mesh file: its part name, triangles, opacity and mesh names."""

    name: str
    mesh: trimesh.Trimesh
    alpha: float
    mesh_names: tuple[str, ...]


def read_parts(path: Path) -> list[MeshPart]:
    """Read a mesh file as parts (one per geometry) with scene transforms applied."""
    import trimesh  # noqa: PLC0415

    try:
        loaded = load_mesh_file(path, file_type=path.suffix.lstrip(".") or None)
    except TargetError as exc:
        raise TargetError(f"{path}: {exc}") from None
    except Exception as exc:  # trimesh raises many types for malformed files
        raise TargetError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc})") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = loaded.dump(concatenate=False)
    else:
        geoms = [loaded]
    parts = []
    for i, g in enumerate(geoms):
        if not isinstance(g, trimesh.Trimesh):
            continue  # point clouds, paths: nothing to hit
        material = getattr(getattr(g, "visual", None), "material", None)
        name = getattr(material, "name", None) or g.metadata.get("name") or f"part{i}"
        names = tuple(str(g.metadata.get(k) or "") for k in ("name", "node"))
        parts.append(MeshPart(str(name), g, opacity(g), names))
    return parts


def opacity(mesh: trimesh.Trimesh) -> float:
    """The opacity (0 to 1) of a glTF geometry's material: its base colour's alpha (factor times
    the texture's median alpha at the vertices) with alphaMode BLEND; 0 or 1 against the cutoff
    with MASK; 1 with OPAQUE or no glTF material (glTF 2.0, section 3.9.4)."""
    visual = getattr(mesh, "visual", None)
    material = getattr(visual, "material", None)
    mode = getattr(material, "alphaMode", None)
    if mode not in ("BLEND", "MASK"):
        return 1.0
    factor = getattr(material, "baseColorFactor", None)
    alpha = 1.0 if factor is None else float(np.asarray(factor)[3]) / 255.0
    textured = getattr(material, "baseColorTexture", None) is not None
    if visual is not None and textured and len(mesh.vertices):
        try:
            colours = visual.to_color().vertex_colors
            alpha *= float(np.median(np.asarray(colours)[:, 3])) / 255.0
        except Exception:  # an unreadable texture: the factor alone
            pass
    if mode == "MASK":
        cutoff = getattr(material, "alphaCutoff", None)
        return 1.0 if alpha >= (0.5 if cutoff is None else float(cutoff)) else 0.0
    return alpha


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n_faces,) area of each triangle [units^2]."""
    return np.sqrt((edge_crosses(vertices, faces) ** 2).sum(axis=1)) / 2.0


def likely_unit(longest: float) -> str | None:
    """The length unit (a key of LENGTH_UNITS_M) that makes a mesh ``longest`` units long the
    size of a spacecraft (closest to 10 m in ratio, within PLAUSIBLE_EXTENT_M), or None."""
    lo, hi = PLAUSIBLE_EXTENT_M
    fits = {u: longest * m for u, m in LENGTH_UNITS_M.items() if lo <= longest * m <= hi}
    if not fits:
        return None
    return min(fits, key=lambda u: abs(math.log(fits[u] / 10.0)))


def size_warning(path: Path | str | None, longest_units: float, scale: float) -> str | None:
    """A warning for a mesh scaled (by a given or default metres per unit) to a size no
    spacecraft has, naming the unit the mesh is likely in; None for a plausible size."""
    longest_m = longest_units * scale
    lo, hi = PLAUSIBLE_EXTENT_M
    if lo <= longest_m <= hi:
        return None
    unit = likely_unit(longest_units)
    hint = (
        f"if the mesh is in {unit}, set target.scale_m_per_unit = {LENGTH_UNITS_M[unit]:g}; "
        if unit
        else ""
    )
    return (
        f"{path}: the target is {longest_m:.3g} m long at {scale:g} m per mesh unit, not the "
        f"{lo:g} to {hi:g} m of a spacecraft: {hint}or give its real size with target.size_m"
    )


def metres_per_unit(target: Target, settings: dict, longest_units: float) -> tuple[float, bool]:
    """Metres per mesh unit, and whether it rests on a unit (given or default) rather than on a
    size: target.size_m, else target.scale_m_per_unit, else the built-in's size or scale, else
    1 (a mesh in metres)."""
    if target.size_m > 0:
        return target.size_m / longest_units, False
    if target.scale_m_per_unit > 0:
        return target.scale_m_per_unit, True
    if "longest_extent_m" in settings:
        return settings["longest_extent_m"] / longest_units, False
    return float(settings.get("scale_m_per_unit", 1.0)), "scale_m_per_unit" not in settings
