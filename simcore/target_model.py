"""The target model: a target mesh ready for ray casting, with its parts and their materials
(from a material map, then the scene's overrides), the parts' table and the distance at which a
target fills the field of view."""

from __future__ import annotations

import dataclasses
import fnmatch
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .materials import LIBRARY
from .target_mesh import TargetError, TargetMesh

if TYPE_CHECKING:
    import trimesh


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
        return self.part_material_library[self.face_part]

    @property
    def part_material_library(self) -> np.ndarray:
        """(n_parts,) int32 index into materials.MATERIAL_NAMES of each part's material."""
        names = list(LIBRARY)
        return np.array([names.index(m) for m in self.part_materials], np.int32)

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


def is_pattern(key: str) -> bool:
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
    exact = {k: v for k, v in mapping.items() if k != "*" and not is_pattern(k)}
    patterns = [(k.lower(), v) for k, v in mapping.items() if k != "*" and is_pattern(k)]
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
