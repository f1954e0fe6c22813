"""Targets: load a mesh (glTF/OBJ/STL/PLY), scale it to metres, centre it, and label each face with
its part (submesh material or name) and the part's material from a material map.

The target frame is the mesh's own axes, scaled to metres, with the origin at the centre of the
bounding box (the body origin the lidar tracks).

Reading a glTF with its textures costs more than the rest of a frame, so the geometry read from a
mesh file (vertices, triangles, part of each triangle) is cached on disk, keyed by the SHA-256 of
the file's content: ``$LMAPD_CACHE_DIR`` (``off`` disables it), else ``$XDG_CACHE_HOME/lmapd-sim``,
else ``~/.cache/lmapd-sim``. Entries are written atomically; a stale one is never read (another
content, another key), a corrupt one is rebuilt and an unwritable folder skipped, with a warning.
trimesh is imported only to read a mesh file (or for ``TargetModel.mesh``): a cached target is
centred, scaled and given its normals with numpy alone, bit for bit as trimesh would.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import tomllib
import warnings
import zipfile
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .cache import CACHE_ENV, cache_dir, write_atomically
from .materials import LIBRARY, read_material_map
from .scene import ASSETS_DIR, MESH_SUFFIXES, Target

if TYPE_CHECKING:  # trimesh loads when a mesh file is read or ``TargetModel.mesh`` is asked for
    import trimesh

TARGETS_DIR = ASSETS_DIR / "targets"
MAX_FACES = 5_000_000
# longest extent of a target once scaled to metres: outside this the scale is surely wrong (a mesh
# in millimetres read as metres, or the reverse)
MIN_EXTENT_M = 1e-3
MAX_EXTENT_M = 1e4


class TargetError(ValueError):
    """A mesh file is missing, unreadable or degenerate. The message names the file."""


_IDENTITY4 = np.eye(4)
_NORMAL_MIN = float(np.finfo(np.float64).resolution * 100)  # shorter cross products: no normal


def _transformed_points(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(n, 3) ``points`` through the homogeneous (4, 4) ``matrix``, as trimesh's
    ``apply_transform`` computes them (the same products in the same order, so the vertices are
    bit for bit those of a target transformed by trimesh); a matrix within 1e-8 of the identity
    leaves them unchanged, as it does there."""
    offset = matrix - _IDENTITY4
    if float(np.ptp(offset)) < 1e-8 or np.abs(offset).max() < 1e-8:
        return points.copy()
    stack = np.column_stack((points, np.ones(len(points))))
    return np.ascontiguousarray(np.dot(matrix, stack.T).T[:, :3])


def _edge_crosses(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
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


def _area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total area of the triangles [units^2] (trimesh's ``Trimesh.area``, bit for bit)."""
    crosses = _edge_crosses(vertices, faces)
    return float((np.sqrt((crosses**2).sum(axis=1)) / 2.0).sum())


def _bounds(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
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
        crosses = _edge_crosses(self.vertices_m, self.faces)
        norm = np.sqrt(np.dot(crosses * crosses, [1.0] * 3))
        valid = norm > _NORMAL_MIN
        norm[valid] **= -1
        normals = np.where(valid[:, None], crosses * norm.reshape((-1, 1)), 0.0)
        normals.setflags(write=False)
        return normals

    @cached_property
    def extents_m(self) -> np.ndarray:
        """(3,) size of the axis-aligned bounding box of the faces [m]."""
        return np.ptp(_bounds(self.vertices_m, self.faces), axis=0)

    @cached_property
    def as_trimesh(self) -> trimesh.Trimesh:
        """The mesh as a ``trimesh.Trimesh`` (of copies of the arrays), made on first use."""
        import trimesh  # noqa: PLC0415  (a third of a second to import: only when asked for)

        return trimesh.Trimesh(
            self.vertices_m.copy(), self.faces.copy(), process=False, validate=False
        )


@dataclass(frozen=True)
class TargetModel:
    """A target mesh ready for ray casting.

    Attributes
    ----------
    surface : TargetMesh
        Triangles in metres, target frame (origin at the bounding-box centre); shared by the
        copies :func:`with_materials` makes, with what was derived from it.
    face_part : (n_faces,) int32
        Index into ``part_names`` for each face.
    part_names : tuple of str
        Part names (glTF material names for the MRO).
    part_materials : tuple of str
        Library material of each part, after the material map and the scene's overrides.
    name, credit : str
        Display name and the credit line to show wherever the model is shown.
    """

    surface: TargetMesh
    face_part: np.ndarray
    part_names: tuple[str, ...]
    part_materials: tuple[str, ...]
    name: str
    credit: str
    source: str
    body_from_mesh: np.ndarray  # (3, 3) rotation: p_body = body_from_mesh @ p_mesh

    @property
    def vertices_m(self) -> np.ndarray:
        """(n_vertices, 3) float64 vertex positions [m], target frame."""
        return self.surface.vertices_m

    @property
    def faces(self) -> np.ndarray:
        """(n_faces, 3) int64 vertex indices of each triangle."""
        return self.surface.faces

    @property
    def face_normals(self) -> np.ndarray:
        """(n_faces, 3) float64 unit normal of each triangle, target frame."""
        return self.surface.face_normals

    @property
    def extents_m(self) -> np.ndarray:
        """(3,) size of the target's axis-aligned bounding box [m]."""
        return self.surface.extents_m

    @property
    def mesh(self) -> trimesh.Trimesh:
        """The target as a ``trimesh.Trimesh`` (imports trimesh on first use)."""
        return self.surface.as_trimesh

    @property
    def face_material(self) -> np.ndarray:
        """(n_faces,) int32 index into ``material_names`` for each face."""
        lookup = np.array([self.material_names.index(m) for m in self.part_materials], np.int32)
        return lookup[self.face_part]

    @property
    def face_material_library(self) -> np.ndarray:
        """(n_faces,) int32 index into materials.MATERIAL_NAMES (stable across targets)."""
        names = list(LIBRARY)
        lookup = np.array([names.index(m) for m in self.part_materials], np.int32)
        return lookup[self.face_part]

    @property
    def material_names(self) -> tuple[str, ...]:
        """Distinct materials used by this target, in library order."""
        used = set(self.part_materials)
        return tuple(n for n in LIBRARY if n in used)

    @property
    def radius_m(self) -> float:
        """Radius of the bounding sphere about the target origin [m]."""
        return float(np.linalg.norm(self.vertices_m, axis=1).max())


def builtin_targets() -> list[str]:
    return sorted(p.parent.name for p in TARGETS_DIR.glob("*/target.toml"))


def _resolve(target: Target) -> tuple[Path, dict, Path | None]:
    """Mesh path, target settings and the directory of a built-in target's files."""
    spec = target.mesh
    builtin = TARGETS_DIR / spec / "target.toml"
    if builtin.exists():
        settings = tomllib.loads(builtin.read_text(encoding="utf-8"))
        return builtin.parent / settings["mesh"], settings, builtin.parent
    path = Path(spec).expanduser()
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise TargetError(
            f"target.mesh = {spec!r}: not a built-in target ({', '.join(builtin_targets())}) "
            f"nor a mesh file ({', '.join(MESH_SUFFIXES)})"
        )
    if not path.is_file():
        raise TargetError(f"target.mesh: file not found: {path}")
    return path, {"name": path.stem, "credit": ""}, None


@dataclass(frozen=True)
class MeshGeometry:
    """What a mesh file holds for us, in the file's own units and axes.

    Attributes
    ----------
    vertices : (n_vertices, 3) float64 -- positions [file units]
    faces : (n_faces, 3) int64 -- vertex indices of each triangle
    face_part : (n_faces,) int32 -- index into ``part_names`` of each triangle
    part_names : tuple of str -- sorted part names (glTF material names, or ``part<i>``)
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_part: np.ndarray
    part_names: tuple[str, ...]


CACHE_FORMAT = 1  # bump when MeshGeometry or the way it is read from a file changes
CACHE_MAX_ENTRIES = 32  # the least recently written entries beyond this are removed


def _cache_file(folder: Path, content: bytes) -> Path:
    digest = hashlib.sha256(content)
    reader = importlib.metadata.version("trimesh")  # (without importing it)
    digest.update(f"format {CACHE_FORMAT} trimesh {reader}".encode())
    return folder / "targets" / f"{digest.hexdigest()}.npz"


def _read_cached(file: Path) -> MeshGeometry | None:
    """The geometry cached in ``file``; None if there is none, a warning if it is corrupt."""
    try:
        with np.load(file, allow_pickle=False) as npz:
            geometry = MeshGeometry(
                vertices=npz["vertices"],
                faces=npz["faces"],
                face_part=npz["face_part"],
                part_names=tuple(str(n) for n in npz["part_names"]),
            )
        n_vertices, n_faces = len(geometry.vertices), len(geometry.faces)
        if (
            geometry.vertices.shape != (n_vertices, 3)
            or geometry.faces.shape != (n_faces, 3)
            or geometry.face_part.shape != (n_faces,)
            or (n_faces and not 0 <= geometry.faces.min() <= geometry.faces.max() < n_vertices)
            or (n_faces and not 0 <= geometry.face_part.min() <= geometry.face_part.max())
            or (n_faces and geometry.face_part.max() >= len(geometry.part_names))
        ):
            raise ValueError("inconsistent arrays")
        return geometry
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        warnings.warn(f"target cache {file} is corrupt ({exc}); rebuilt", stacklevel=3)
        return None


def _write_cached(file: Path, geometry: MeshGeometry) -> None:
    """Write ``geometry`` to ``file`` atomically; an unwritable cache only warns."""

    def write(fh) -> None:
        np.savez(
            fh,
            vertices=geometry.vertices,
            faces=geometry.faces,
            face_part=geometry.face_part,
            part_names=np.array(geometry.part_names, dtype=str),
        )

    try:
        write_atomically(file, write, CACHE_MAX_ENTRIES)
    except OSError as exc:
        warnings.warn(
            f"target cache {file.parent} is not writable ({exc}); the mesh is read from its "
            f"file each time (set {CACHE_ENV} to another folder, or to off)",
            stacklevel=3,
        )


def mesh_geometry(path: Path) -> MeshGeometry:
    """The geometry of the mesh file ``path``, from the on-disk cache when it holds it."""
    folder = cache_dir()
    if folder is None:
        return _read_geometry(path)
    try:
        content = path.read_bytes()
    except OSError as exc:
        raise TargetError(f"{path}: cannot read the mesh ({exc.strerror or exc})") from None
    file = _cache_file(folder, content)
    geometry = _read_cached(file)
    if geometry is None:
        geometry = _read_geometry(path)
        _write_cached(file, geometry)
    return geometry


def _read_geometry(path: Path) -> MeshGeometry:
    """Read a mesh file: every triangle, and the part it belongs to."""
    parts = _read_parts(path)
    if not parts:
        return MeshGeometry(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int32), ())
    vertices = np.concatenate([g.vertices for _, g in parts]).astype(np.float64)
    offsets = np.cumsum([0] + [len(g.vertices) for _, g in parts[:-1]])
    faces = np.concatenate([g.faces + o for (_, g), o in zip(parts, offsets, strict=True)])
    names = sorted({n for n, _ in parts})
    face_part = np.concatenate([np.full(len(g.faces), names.index(n), np.int32) for n, g in parts])
    return MeshGeometry(vertices, faces.astype(np.int64), face_part, tuple(names))


def source_stamp(target: Target) -> tuple:
    """What identifies the files behind ``target`` now: each file's path, size and modification
    time (None for a file that cannot be found; loading it then says why). A cache keyed by
    this sees a mesh or material map overwritten in place."""
    try:
        path, _, folder = _resolve(target)
    except TargetError:
        path, folder = None, None
    files = [path, Path(target.material_map) if target.material_map else None]
    if folder is not None:
        files.append(folder / "target.toml")
    stamp = []
    for f in files:
        try:
            st = f.stat() if f is not None else None
        except OSError:
            st = None
        stamp.append((str(f), st.st_size, st.st_mtime_ns) if st is not None else None)
    return tuple(stamp)


def load_mesh_file(
    file_obj, file_type: str | None, **load_options
) -> trimesh.Trimesh | trimesh.Scene:
    """``trimesh.load`` of a mesh file that refuses NaN or infinite vertices in every format.

    trimesh's default processing drops the triangles of non-finite vertices from OBJ, PLY and STL
    files without a word (glTF is not processed), so the file is read unprocessed, checked, then
    processed as trimesh would have (the same vertices and faces as a default load).

    Raises
    ------
    TargetError
        A vertex coordinate is NaN or infinite (the message names no file: callers add it).
    """
    import trimesh  # noqa: PLC0415  (only to read a mesh file: the cached path needs none)

    loaded = trimesh.load(file_obj, file_type=file_type, force=None, process=False, **load_options)
    geometries = loaded.geometry.values() if isinstance(loaded, trimesh.Scene) else [loaded]
    meshes = [g for g in geometries if isinstance(g, trimesh.Trimesh)]
    if not all(np.isfinite(g.vertices).all() for g in meshes):
        raise TargetError("the mesh has NaN or infinite vertex coordinates")
    if (file_type or "").lower().lstrip(".") not in ("glb", "gltf"):
        for mesh in meshes:
            mesh.process()
    return loaded


def _read_parts(path: Path) -> list[tuple[str, trimesh.Trimesh]]:
    """Read a mesh file as (part name, mesh) pairs with scene transforms applied."""
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
        parts.append((str(name), g))
    return parts


def load_target(target: Target) -> TargetModel:
    """Load, check, scale and label a target mesh (the scene's per-part material overrides are
    applied later by :func:`with_materials`, so changing them never reloads the mesh).

    Raises
    ------
    TargetError
        Missing file, unreadable or empty mesh, NaN/inf vertices, zero total area, too many faces.
    """
    path, settings, folder = _resolve(target)
    geometry = mesh_geometry(path)
    n_faces = len(geometry.faces)
    if n_faces == 0:
        raise TargetError(f"{path}: the mesh has no triangles")
    if n_faces > MAX_FACES:
        raise TargetError(f"{path}: {n_faces} triangles is more than the {MAX_FACES} allowed")
    if not np.isfinite(geometry.vertices).all():
        raise TargetError(f"{path}: the mesh has NaN or infinite vertex coordinates")
    names, face_part = list(geometry.part_names), geometry.face_part
    vertices, faces = geometry.vertices, geometry.faces
    if not _area(vertices, faces) > 0:
        raise TargetError(f"{path}: the mesh has zero surface area (degenerate triangles)")

    bounds = _bounds(vertices, faces)
    extents = np.ptp(bounds, axis=0)
    if target.scale_m_per_unit > 0:
        scale = target.scale_m_per_unit
    elif "longest_extent_m" in settings:
        scale = settings["longest_extent_m"] / extents.max()
    else:
        scale = float(settings.get("scale_m_per_unit", 1.0))
    longest_m = float(extents.max()) * scale
    if not MIN_EXTENT_M <= longest_m <= MAX_EXTENT_M:
        raise TargetError(
            f"{path}: the target is {longest_m:.3g} m long once scaled ({scale:g} m per unit); "
            f"targets must be {MIN_EXTENT_M:g} m to {MAX_EXTENT_M:g} m long: check the scale"
        )
    centring = np.eye(4)
    centring[:3, 3] = -bounds.mean(axis=0)
    scaling = np.eye(4)
    if scale != 1:
        scaling[:3, :3] *= scale
    surface = TargetMesh(
        vertices_m=_transformed_points(_transformed_points(vertices, centring), scaling),
        faces=np.array(faces, dtype=np.int64),
    )
    surface.vertices_m.setflags(write=False)
    surface.faces.setflags(write=False)

    mapping = _material_map(target, folder)
    materials = tuple(mapping.get(n, mapping["*"]) for n in names)
    body = np.asarray(settings.get("body_from_mesh", np.eye(3)), dtype=np.float64)
    if (
        body.shape != (3, 3)
        or not np.allclose(body @ body.T, np.eye(3), atol=1e-9)
        or not (np.isclose(np.linalg.det(body), 1.0))
    ):
        raise TargetError(f"{path}: body_from_mesh must be a 3 x 3 rotation matrix")
    return TargetModel(
        surface=surface,
        face_part=face_part,
        part_names=tuple(names),
        part_materials=materials,
        name=str(settings.get("name", path.stem)),
        credit=str(settings.get("credit", "")),
        source=str(path),
        body_from_mesh=body,
    )


def _material_map(target: Target, folder: Path | None) -> dict[str, str]:
    if target.material_map:
        mapping = _read_map(Path(target.material_map))
    elif folder is not None:
        settings = tomllib.loads((folder / "target.toml").read_text(encoding="utf-8"))
        mapping = _read_map(folder / settings.get("material_map", "materials.toml"))
    else:
        mapping = {"*": "coating_2"}
    return mapping


def _read_map(path: Path) -> dict[str, str]:
    try:
        return read_material_map(path)
    except (FileNotFoundError, ValueError) as exc:
        raise TargetError(f"target.material_map: {exc}") from None


def with_materials(model: TargetModel, overrides) -> TargetModel:
    """The same geometry with some parts' materials replaced (no reload, no new BVH)."""
    mats = dict(zip(model.part_names, model.part_materials, strict=True))
    for part, name in overrides:
        if name not in LIBRARY:
            raise TargetError(
                f"target.materials.{part} = {name!r}: unknown material; "
                f"the library has {', '.join(LIBRARY)}"
            )
        if part == "*":  # every part
            mats = dict.fromkeys(mats, name)
            continue
        if part not in mats:
            raise TargetError(
                f"target.materials: unknown part {part!r}; parts are "
                f"{', '.join(model.part_names)} (or * for all)"
            )
        mats[part] = name
    return TargetModel(
        surface=model.surface,
        face_part=model.face_part,
        part_names=model.part_names,
        part_materials=tuple(mats[n] for n in model.part_names),
        name=model.name,
        credit=model.credit,
        source=model.source,
        body_from_mesh=model.body_from_mesh,
    )
