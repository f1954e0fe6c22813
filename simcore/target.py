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

The target's modules: this one (the catalogue of built-in targets, the on-disk cache and
``load_target``, which joins them), ``target_mesh`` (reading a mesh file, its size in metres) and
``target_model`` (the model, its parts and their materials). Their public names are importable
from here as before.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import tomllib
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import calibration
from ._assets import ASSETS_DIR
from .cache import CACHE_ENV, cache_dir, write_atomically
from .materials import read_material_map
from .scene import MESH_SUFFIXES, Target
from .target_mesh import (
    LENGTH_UNITS_M,
    MAX_EXTENT_M,
    MIN_EXTENT_M,
    PLAUSIBLE_EXTENT_M,
    TargetError,
    TargetMesh,
    face_areas,
    likely_unit,
    load_mesh_file,
    mesh_bounds,
    metres_per_unit,
    size_warning,
    surface_area,
    transformed_points,
)
from .target_mesh import read_parts as _read_parts  # the cache's reader (tests replace it)
from .target_model import (
    TargetModel,
    fov_fill_distance_m,
    part_materials,
    parts_table,
    with_materials,
)

__all__ = [  # this module's names and those of target_mesh and target_model callers take from here
    "CACHE_FORMAT",
    "CACHE_MAX_ENTRIES",
    "LENGTH_UNITS_M",
    "MATERIAL_RULES",
    "MAX_EXTENT_M",
    "MAX_FACES",
    "MIN_EXTENT_M",
    "PLAUSIBLE_EXTENT_M",
    "TARGETS_DIR",
    "MeshGeometry",
    "TargetError",
    "TargetMesh",
    "TargetModel",
    "builtin_settings",
    "builtin_targets",
    "fov_fill_distance_m",
    "likely_unit",
    "load_mesh_file",
    "load_target",
    "mesh_geometry",
    "part_materials",
    "parts_table",
    "source_stamp",
    "with_materials",
]

TARGETS_DIR = ASSETS_DIR / "targets"
MAX_FACES = 5_000_000
# the rule file of a user mesh with no material map of its own: part and mesh names (patterns) to
# the library's materials
MATERIAL_RULES = ASSETS_DIR / "material_rules.toml"


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
    _check_geometry(where, geometry)
    faces, face_part, transparent = _opaque_faces(where, geometry, target.alpha_threshold)
    vertices = geometry.vertices
    bounds = mesh_bounds(vertices, faces)
    longest_units = float(np.ptp(bounds, axis=0).max())
    scale, by_unit = _checked_scale(where, target, settings, longest_units)
    notes = []
    warning = size_warning(where, longest_units, scale) if by_unit else None
    if warning:
        warnings.warn(warning, UserWarning, stacklevel=2)
        notes.append(warning)
    surface = _surface_in_metres(vertices, faces, bounds, scale)
    face_part = np.ascontiguousarray(face_part)

    names = list(geometry.part_names)
    areas = face_areas(geometry.vertices, geometry.faces) * scale**2
    part_area = np.bincount(geometry.face_part, weights=areas, minlength=len(names))
    part_triangles = np.bincount(geometry.face_part, minlength=len(names))
    mapping = _material_map(target, folder, settings)
    materials, matched = part_materials(names, geometry.meshes, mapping)
    return TargetModel(
        surface=surface,
        face_part=face_part,
        part_names=tuple(names),
        part_materials=materials,
        name=str(settings.get("name", path.stem if path else target.mesh)),
        credit=str(settings.get("credit", "")),
        source=str(path if path is not None else target.mesh),
        body_from_mesh=_body_from_mesh(where, settings),
        part_triangles=tuple(int(n) for n in part_triangles),
        part_area_m2=tuple(float(a) for a in part_area),
        part_transparent=tuple(bool(t) for t in transparent),
        part_matched=matched,
        notes=tuple(notes),
    )


def _check_geometry(where, geometry: MeshGeometry) -> None:
    """Some triangles, not too many, and finite vertices; TargetError naming ``where``."""
    n_faces = len(geometry.faces)
    if n_faces == 0:
        raise TargetError(f"{where}: the mesh has no triangles")
    if n_faces > MAX_FACES:
        raise TargetError(f"{where}: {n_faces} triangles is more than the {MAX_FACES} allowed")
    if not np.isfinite(geometry.vertices).all():
        raise TargetError(f"{where}: the mesh has NaN or infinite vertex coordinates")


def _opaque_faces(
    where, geometry: MeshGeometry, alpha_threshold: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces the lidar sees and their parts (those of parts with an opacity below
    ``alpha_threshold`` left out), and which parts are transparent; TargetError when none is
    left or the rest has no area."""
    transparent = geometry.alpha < alpha_threshold
    faces, face_part = geometry.faces, geometry.face_part
    if transparent.any():
        keep = ~transparent[face_part]
        if not keep.any():
            raise TargetError(
                f"{where}: every part is transparent (glTF alpha below target.alpha_threshold = "
                f"{alpha_threshold:g}); set target.alpha_threshold = 0 to see them"
            )
        faces, face_part = faces[keep], face_part[keep]
    if not surface_area(geometry.vertices, faces) > 0:
        raise TargetError(f"{where}: the mesh has zero surface area (degenerate triangles)")
    return faces, face_part, transparent


def _checked_scale(
    where, target: Target, settings: dict, longest_units: float
) -> tuple[float, bool]:
    """Metres per mesh unit (``metres_per_unit``), the target then MIN_EXTENT_M to MAX_EXTENT_M
    long, and whether the scale rests on a unit; TargetError naming the likely unit otherwise."""
    scale, by_unit = metres_per_unit(target, settings, longest_units)
    longest_m = longest_units * scale
    if not MIN_EXTENT_M <= longest_m <= MAX_EXTENT_M:
        unit = likely_unit(longest_units) if by_unit else None
        hint = f" (in {unit}? target.scale_m_per_unit = {LENGTH_UNITS_M[unit]:g})" if unit else ""
        raise TargetError(
            f"{where}: the target is {longest_m:.3g} m long once scaled ({scale:g} m per unit); "
            f"targets must be {MIN_EXTENT_M:g} m to {MAX_EXTENT_M:g} m long: check the scale"
            f"{hint} or give target.size_m"
        )
    return scale, by_unit


def _surface_in_metres(
    vertices: np.ndarray, faces: np.ndarray, bounds: np.ndarray, scale: float
) -> TargetMesh:
    """The triangles centred on their bounding box and scaled to metres (read-only arrays)."""
    centring = np.eye(4)
    centring[:3, 3] = -bounds.mean(axis=0)
    scaling = np.eye(4)
    if scale != 1:
        scaling[:3, :3] *= scale
    surface = TargetMesh(
        vertices_m=transformed_points(transformed_points(vertices, centring), scaling),
        faces=np.array(faces, dtype=np.int64),
    )
    surface.vertices_m.setflags(write=False)
    surface.faces.setflags(write=False)
    return surface


def _body_from_mesh(where, settings: dict) -> np.ndarray:
    """The (3, 3) rotation from the mesh's axes to the target body's (a built-in's
    ``body_from_mesh``, else the identity); TargetError if it is no rotation."""
    body = np.asarray(settings.get("body_from_mesh", np.eye(3)), dtype=np.float64)
    if (
        body.shape != (3, 3)
        or not np.allclose(body @ body.T, np.eye(3), atol=1e-9)
        or not (np.isclose(np.linalg.det(body), 1.0))
    ):
        raise TargetError(f"{where}: body_from_mesh must be a 3 x 3 rotation matrix")
    return body


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
