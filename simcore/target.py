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

import dataclasses
import fnmatch
import hashlib
import importlib.metadata
import io
import math
import tomllib
import warnings
import zipfile
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from . import calibration
from .cache import CACHE_ENV, cache_dir, write_atomically
from .gltf import GltfError, check_gltf_file
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
# a spacecraft is 0.3 m (a small CubeSat) to 200 m (the ISS is 109 m across): a mesh scaled outside
# this is probably in another unit, and the warning names the likeliest
PLAUSIBLE_EXTENT_M = (0.3, 200.0)
LENGTH_UNITS_M = {"mm": 1e-3, "cm": 1e-2, "inch": 0.0254, "foot": 0.3048, "m": 1.0, "km": 1e3}
# the rule file of a user mesh with no material map of its own: part and mesh names (patterns) to
# the library's materials
MATERIAL_RULES = ASSETS_DIR / "material_rules.toml"


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
    def radius_m(self) -> float:
        """Radius of the bounding sphere about the target origin [m] (every vertex)."""
        return float(np.linalg.norm(self.vertices_m, axis=1).max())

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
    part_triangles : tuple of int
        Triangles of each part in the file (a transparent part's too).
    part_area_m2 : tuple of float
        Area of each part once scaled [m^2] (a transparent part's too).
    part_transparent : tuple of bool
        Parts the lidar sees through (opacity below ``target.alpha_threshold``): their
        triangles are not in ``surface``.
    part_matched : tuple of bool
        Whether a part's material comes from a material map entry, a rule or a scene override
        (False: the map's default).
    notes : tuple of str
        Warnings given when the target was loaded (an implausible size).
    """

    surface: TargetMesh
    face_part: np.ndarray
    part_names: tuple[str, ...]
    part_materials: tuple[str, ...]
    name: str
    credit: str
    source: str
    body_from_mesh: np.ndarray  # (3, 3) rotation: p_body = body_from_mesh @ p_mesh
    part_triangles: tuple[int, ...] = ()
    part_area_m2: tuple[float, ...] = ()
    part_transparent: tuple[bool, ...] = ()
    part_matched: tuple[bool, ...] = ()
    notes: tuple[str, ...] = ()

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
        """Radius of the bounding sphere about the target origin [m] (computed once per mesh:
        the background stage asks for it every frame)."""
        return self.surface.radius_m


def builtin_targets() -> list[str]:
    """The built-in targets' names: the catalogue's spacecraft (``assets/targets``), then the
    calibration shapes (:mod:`simcore.calibration`)."""
    spacecraft = sorted(p.parent.name for p in TARGETS_DIR.glob("*/target.toml"))
    return spacecraft + list(calibration.SHAPES)


def builtin_settings(name: str) -> dict:
    """The settings of the built-in target ``name`` (its ``target.toml``, or a calibration
    shape's: name, size, material)."""
    if name in calibration.SHAPES:
        return {
            "name": calibration.TITLES[name],
            "credit": "",
            "shape": name,
            "longest_extent_m": calibration.DEFAULT_SIZE_M,
        }
    return tomllib.loads((TARGETS_DIR / name / "target.toml").read_text(encoding="utf-8"))


def _resolve(target: Target) -> tuple[Path | None, dict, Path | None]:
    """Mesh path (None for a calibration shape), target settings and the directory of a
    built-in target's files."""
    spec = target.mesh
    if spec in calibration.SHAPES:
        return None, builtin_settings(spec), None
    builtin = TARGETS_DIR / spec / "target.toml"
    if spec and "/" not in spec and "\\" not in spec and builtin.exists():
        return (
            builtin.parent / builtin_settings(spec)["mesh"],
            builtin_settings(spec),
            builtin.parent,
        )
    path = Path(spec).expanduser()
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise TargetError(
            f"target.mesh = {spec!r}: not a built-in target ({', '.join(builtin_targets())}: "
            f"`lmapd targets` lists them) nor a mesh file ({', '.join(MESH_SUFFIXES)})"
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
    part_alpha : (n_parts,) float64 -- opacity of each part, 0 to 1 (glTF: the base colour's
        alpha, factor times texture, where the material's alphaMode is BLEND or MASK; 1 else)
    part_meshes : tuple of str -- the names of the meshes and nodes each part is made of
        (newline-separated), which material rules match as well as the part's name
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_part: np.ndarray
    part_names: tuple[str, ...]
    part_alpha: np.ndarray | None = None
    part_meshes: tuple[str, ...] = ()

    @property
    def alpha(self) -> np.ndarray:
        """(n_parts,) float64 opacity of each part (1 where the file says nothing)."""
        if self.part_alpha is None:
            return np.ones(len(self.part_names))
        return self.part_alpha

    @property
    def meshes(self) -> tuple[str, ...]:
        """The mesh names of each part (empty strings where the file gives none)."""
        return self.part_meshes or ("",) * len(self.part_names)


CACHE_FORMAT = 3  # bump when MeshGeometry or the way it is read from a file changes
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
                part_alpha=npz["part_alpha"],
                part_meshes=tuple(str(n) for n in npz["part_meshes"]),
            )
        n_vertices, n_faces = len(geometry.vertices), len(geometry.faces)
        n_parts = len(geometry.part_names)
        if (
            geometry.vertices.shape != (n_vertices, 3)
            or geometry.faces.shape != (n_faces, 3)
            or geometry.face_part.shape != (n_faces,)
            or geometry.alpha.shape != (n_parts,)
            or len(geometry.part_meshes) != n_parts
            or (n_faces and not 0 <= geometry.faces.min() <= geometry.faces.max() < n_vertices)
            or (n_faces and not 0 <= geometry.face_part.min() <= geometry.face_part.max())
            or (n_faces and geometry.face_part.max() >= n_parts)
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
            part_alpha=geometry.alpha,
            part_meshes=np.array(geometry.meshes, dtype=str),
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
    """The geometry of the mesh file ``path``, from the on-disk cache when it holds it (a file
    that cannot be read leaves nothing in the cache)."""
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
        if len(geometry.faces):  # a mesh with no triangles is refused: nothing to keep
            _write_cached(file, geometry)
    return geometry


def _read_geometry(path: Path) -> MeshGeometry:
    """Read a mesh file: every triangle, the part it belongs to, each part's opacity and
    mesh names."""
    parts = _read_parts(path)
    if not parts:
        return MeshGeometry(
            np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int32), (), np.ones(0), ()
        )
    vertices = np.concatenate([p.mesh.vertices for p in parts]).astype(np.float64)
    offsets = np.cumsum([0] + [len(p.mesh.vertices) for p in parts[:-1]])
    faces = np.concatenate([p.mesh.faces + o for p, o in zip(parts, offsets, strict=True)])
    names = sorted({p.name for p in parts})
    face_part = np.concatenate(
        [np.full(len(p.mesh.faces), names.index(p.name), np.int32) for p in parts]
    )
    alpha, meshes = [], []
    for name in names:
        mine = [p for p in parts if p.name == name]
        weights = np.array([max(len(p.mesh.faces), 1) for p in mine], dtype=np.float64)
        alpha.append(float(np.dot(weights, [p.alpha for p in mine]) / weights.sum()))
        meshes.append("\n".join(dict.fromkeys(n for p in mine for n in p.mesh_names if n)))
    return MeshGeometry(
        vertices, faces.astype(np.int64), face_part, tuple(names), np.array(alpha), tuple(meshes)
    )


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
    elif path is not None and not target.material_map:
        files.append(MATERIAL_RULES)
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
    """``trimesh.load`` of a mesh file that refuses NaN or infinite vertices in every format and
    reads a glTF only once it has passed :func:`simcore.gltf.check_gltf_file` (the caps, and its
    Draco-compressed geometry decoded in a child process under memory and time limits).

    trimesh's default processing drops the triangles of non-finite vertices from OBJ, PLY and STL
    files without a word (glTF is not processed), so the file is read unprocessed, checked, then
    processed as trimesh would have (the same vertices and faces as a default load).

    Parameters
    ----------
    file_obj : path or binary file
        A path (a ``.gltf``'s buffer files are read beside it) or an open file (a ``.gltf`` must
        then hold its buffers: uploads read no other file).

    Raises
    ------
    TargetError
        A vertex coordinate is NaN or infinite; a glTF over a cap or with compressed geometry
        that cannot be decoded (the message names no file: callers add it).
    """
    import trimesh  # noqa: PLC0415  (only to read a mesh file: the cached path needs none)

    kind = (file_type or "").lower().lstrip(".")
    if kind in ("glb", "gltf"):
        if isinstance(file_obj, str | Path):
            data, folder = Path(file_obj).read_bytes(), Path(file_obj).parent
        else:
            data, folder = file_obj.read(), None
            file_obj = io.BytesIO(data)
        try:
            check_gltf_file(data, kind == "glb", folder)
        except GltfError as exc:
            raise TargetError(f"cannot read the .{kind} file ({exc})") from None
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


@dataclass(frozen=True)
class _Part:
    """One geometry of a mesh file: its part name, triangles, opacity and mesh names."""

    name: str
    mesh: trimesh.Trimesh
    alpha: float
    mesh_names: tuple[str, ...]


def _read_parts(path: Path) -> list[_Part]:
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
        parts.append(_Part(str(name), g, _opacity(g), names))
    return parts


def _opacity(mesh: trimesh.Trimesh) -> float:
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


def _geometry(path: Path | None, settings: dict) -> MeshGeometry:
    """A calibration shape's geometry (built), or a mesh file's (read or cached)."""
    shape = settings.get("shape")
    if shape is None:
        assert path is not None  # a target is a mesh file or a calibration shape
        return mesh_geometry(path)
    vertices, faces = calibration.shape_mesh(shape)
    return MeshGeometry(
        vertices, faces, np.zeros(len(faces), np.int32), (shape,), np.ones(1), (shape,)
    )


def _face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n_faces,) area of each triangle [units^2]."""
    return np.sqrt((_edge_crosses(vertices, faces) ** 2).sum(axis=1)) / 2.0


def likely_unit(longest: float) -> str | None:
    """The length unit (a key of LENGTH_UNITS_M) that makes a mesh ``longest`` units long the
    size of a spacecraft (closest to 10 m in ratio, within PLAUSIBLE_EXTENT_M), or None."""
    lo, hi = PLAUSIBLE_EXTENT_M
    fits = {u: longest * m for u, m in LENGTH_UNITS_M.items() if lo <= longest * m <= hi}
    if not fits:
        return None
    return min(fits, key=lambda u: abs(math.log(fits[u] / 10.0)))


def _size_warning(path: Path | str | None, longest_units: float, scale: float) -> str | None:
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


def _scale(target: Target, settings: dict, longest_units: float) -> tuple[float, bool]:
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


def load_target(target: Target) -> TargetModel:
    """Load, check, scale and label a target mesh (the scene's per-part material overrides are
    applied later by :func:`with_materials`, so changing them never reloads the mesh).

    Parts whose opacity is below ``target.alpha_threshold`` are transparent to the lidar: their
    triangles are left out of the surface (and of its box, centre and size); the part list keeps
    them. A size that rests on a unit and comes out outside PLAUSIBLE_EXTENT_M warns (a
    UserWarning, also kept in ``notes``).

    Raises
    ------
    TargetError
        Missing file, unreadable or empty mesh, NaN/inf vertices, zero total area, too many faces,
        every part transparent.
    """
    path, settings, folder = _resolve(target)
    where = path if path is not None else f"target.mesh = {target.mesh!r}"
    geometry = _geometry(path, settings)
    n_faces = len(geometry.faces)
    if n_faces == 0:
        raise TargetError(f"{where}: the mesh has no triangles")
    if n_faces > MAX_FACES:
        raise TargetError(f"{where}: {n_faces} triangles is more than the {MAX_FACES} allowed")
    if not np.isfinite(geometry.vertices).all():
        raise TargetError(f"{where}: the mesh has NaN or infinite vertex coordinates")
    names = list(geometry.part_names)
    transparent = geometry.alpha < target.alpha_threshold
    vertices, faces, face_part = geometry.vertices, geometry.faces, geometry.face_part
    if transparent.any():
        keep = ~transparent[face_part]
        if not keep.any():
            raise TargetError(
                f"{where}: every part is transparent (glTF alpha below target.alpha_threshold = "
                f"{target.alpha_threshold:g}); set target.alpha_threshold = 0 to see them"
            )
        faces, face_part = faces[keep], face_part[keep]
    if not _area(vertices, faces) > 0:
        raise TargetError(f"{where}: the mesh has zero surface area (degenerate triangles)")

    bounds = _bounds(vertices, faces)
    extents = np.ptp(bounds, axis=0)
    scale, by_unit = _scale(target, settings, float(extents.max()))
    longest_m = float(extents.max()) * scale
    if not MIN_EXTENT_M <= longest_m <= MAX_EXTENT_M:
        unit = likely_unit(float(extents.max())) if by_unit else None
        hint = f" (in {unit}? target.scale_m_per_unit = {LENGTH_UNITS_M[unit]:g})" if unit else ""
        raise TargetError(
            f"{where}: the target is {longest_m:.3g} m long once scaled ({scale:g} m per unit); "
            f"targets must be {MIN_EXTENT_M:g} m to {MAX_EXTENT_M:g} m long: check the scale"
            f"{hint} or give target.size_m"
        )
    notes = []
    warning = _size_warning(where, float(extents.max()), scale) if by_unit else None
    if warning:
        warnings.warn(warning, UserWarning, stacklevel=2)
        notes.append(warning)
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
    face_part = np.ascontiguousarray(face_part)

    areas = _face_areas(geometry.vertices, geometry.faces) * scale**2
    part_area = np.bincount(geometry.face_part, weights=areas, minlength=len(names))
    part_triangles = np.bincount(geometry.face_part, minlength=len(names))
    mapping = _material_map(target, folder, settings)
    materials, matched = part_materials(names, geometry.meshes, mapping)
    body = np.asarray(settings.get("body_from_mesh", np.eye(3)), dtype=np.float64)
    if (
        body.shape != (3, 3)
        or not np.allclose(body @ body.T, np.eye(3), atol=1e-9)
        or not (np.isclose(np.linalg.det(body), 1.0))
    ):
        raise TargetError(f"{where}: body_from_mesh must be a 3 x 3 rotation matrix")
    return TargetModel(
        surface=surface,
        face_part=face_part,
        part_names=tuple(names),
        part_materials=materials,
        name=str(settings.get("name", path.stem if path else target.mesh)),
        credit=str(settings.get("credit", "")),
        source=str(path if path is not None else target.mesh),
        body_from_mesh=body,
        part_triangles=tuple(int(n) for n in part_triangles),
        part_area_m2=tuple(float(a) for a in part_area),
        part_transparent=tuple(bool(t) for t in transparent),
        part_matched=matched,
        notes=tuple(notes),
    )


def _material_map(target: Target, folder: Path | None, settings: dict) -> dict[str, str]:
    """The material map of the target: the scene's, else a built-in's own, else the
    calibration shapes' material, else the rule file."""
    if target.material_map:
        return _read_map(Path(target.material_map))
    if folder is not None:
        return _read_map(folder / settings.get("material_map", "materials.toml"))
    if "shape" in settings:
        return {settings["shape"]: calibration.DEFAULT_MATERIAL, "*": calibration.DEFAULT_MATERIAL}
    return _read_map(MATERIAL_RULES)


def _read_map(path: Path) -> dict[str, str]:
    try:
        return read_material_map(path)
    except (FileNotFoundError, ValueError) as exc:
        raise TargetError(f"target.material_map: {exc}") from None


def _is_pattern(key: str) -> bool:
    return any(c in key for c in "*?[")


def part_materials(
    names, meshes, mapping: dict[str, str]
) -> tuple[tuple[str, ...], tuple[bool, ...]]:
    """Each part's library material from a material map, and whether an entry matched it.

    An entry names a part exactly (its glTF material name), or one of the meshes it is made of,
    or is a pattern (``fnmatch``: ``*``, ``?``, ``[...]``; case-insensitive) tried in the map's
    order on the part's name, then on its mesh names. Exact names win over patterns; a part
    nothing matches gets the map's default (``*``).

    Parameters
    ----------
    names : sequence of str -- the part names
    meshes : sequence of str -- each part's mesh names, newline-separated
    mapping : dict -- entry -> material, ``*`` the default (``read_material_map``'s)

    Returns
    -------
    materials : tuple of str
    matched : tuple of bool -- False where the default was used
    """
    exact = {k: v for k, v in mapping.items() if k != "*" and not _is_pattern(k)}
    patterns = [(k.lower(), v) for k, v in mapping.items() if k != "*" and _is_pattern(k)]
    materials, matched = [], []
    for name, mesh_text in zip(names, meshes, strict=True):
        candidates = [name, *(m for m in mesh_text.split("\n") if m)]
        found = next((exact[c] for c in candidates if c in exact), None)
        if found is None:
            found = next(
                (v for c in candidates for k, v in patterns if fnmatch.fnmatchcase(c.lower(), k)),
                None,
            )
        materials.append(found if found is not None else mapping["*"])
        matched.append(found is not None)
    return tuple(materials), tuple(matched)


def with_materials(model: TargetModel, overrides) -> TargetModel:
    """The same geometry with some parts' materials replaced (no reload, no new BVH)."""
    mats = dict(zip(model.part_names, model.part_materials, strict=True))
    matched = dict(zip(model.part_names, model.part_matched or (True,) * len(mats), strict=True))
    for part, name in overrides:
        if name not in LIBRARY:
            raise TargetError(
                f"target.materials.{part} = {name!r}: unknown material; "
                f"the library has {', '.join(LIBRARY)}"
            )
        if part == "*":  # every part
            mats = dict.fromkeys(mats, name)
            matched = dict.fromkeys(matched, True)
            continue
        if part not in mats:
            raise TargetError(
                f"target.materials: unknown part {part!r}; parts are "
                f"{', '.join(model.part_names)} (or * for all)"
            )
        mats[part] = name
        matched[part] = True
    return dataclasses.replace(
        model,
        part_materials=tuple(mats[n] for n in model.part_names),
        part_matched=tuple(matched[n] for n in model.part_names),
    )


def parts_table(model: TargetModel) -> list[dict]:
    """One row per part: ``name``, ``triangles``, ``area_share`` (of the whole mesh's area,
    transparent parts included), ``material``, ``transparent``, ``matched`` (False: the map's
    default material). What ``lmapd target-info`` prints and the summary's ``target.parts``
    holds."""
    total = float(sum(model.part_area_m2)) or 1.0
    n = len(model.part_names)
    return [
        {
            "name": name,
            "triangles": (model.part_triangles or (0,) * n)[i],
            "area_share": (model.part_area_m2 or (0.0,) * n)[i] / total,
            "material": model.part_materials[i],
            "transparent": (model.part_transparent or (False,) * n)[i],
            "matched": (model.part_matched or (True,) * n)[i],
        }
        for i, name in enumerate(model.part_names)
    ]


def fov_fill_distance_m(radius_m: float, fov_rad: float) -> float:
    """The distance [m] from the lidar to the target's centre at which a target of bounding
    radius ``radius_m`` just fills a full field of view ``fov_rad``: the sphere of that radius
    about the centre subtends the field of view, r / sin(fov / 2) (so it fits at any attitude).

    Parameters
    ----------
    radius_m : float -- bounding-sphere radius about the target's centre [m] (``radius_m``)
    fov_rad : float -- full field of view (``receive.fov_rad``) [rad], in (0, pi)
    """
    if not (radius_m > 0 and 0 < fov_rad < math.pi):
        raise ValueError(f"radius {radius_m!r} m and field of view {fov_rad!r} rad: out of range")
    return radius_m / math.sin(fov_rad / 2.0)
