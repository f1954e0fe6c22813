"""Exact point-to-mesh distances: libigl's axis-aligned bounding-box tree of a mesh's triangles.

Building the tree is most of the cost of a query (about 0.1-0.3 s for the MRO's 124,062 facets,
then a few milliseconds for a frame's points), and it does not depend on the pose: a series of
frames of one target (an atlas's attitudes on a worker, a slider drag, a sweep) builds it once
per mesh (:func:`closest_points`) and shares it. The trees are kept per mesh object (the identity
the stage caches key a target by), weakly, so a mesh that is dropped takes its tree with it, and
for the ``_KEPT`` meshes used last at most (about 25 MB each for the MRO), so many meshes in turn
do not pile up.

The distances are the same with or without the shared tree, bit for bit (one tree of the same
triangles); :func:`point_to_mesh_m` builds one for a single query.
"""

from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .target_mesh import TargetMesh

_KEPT = 4  # [-] meshes whose trees are kept (the ones used last)
_TREES: weakref.WeakKeyDictionary[TargetMesh, ClosestPoints] = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


class ClosestPoints:
    """The closest-point structure of some triangles: their tree and the arrays it indexes.

    vertices_m : (n_vertices, 3) float64 positions [m]
    faces : (n_faces, 3) int64 vertex indices of each triangle
    """

    def __init__(self, vertices_m, faces) -> None:
        self.vertices_m = np.ascontiguousarray(vertices_m, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.tree = _new_tree(self.vertices_m, self.faces) if len(self.faces) else None

    def distance_m(self, points) -> np.ndarray:
        """(n,) exact distance of each point (n, 3) [m] to the nearest triangle [m]; inf for
        all where there is no triangle."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(points) or self.tree is None:
            return np.full(len(points), np.inf)
        squared_m2, _, _ = self.tree.squared_distance(self.vertices_m, self.faces, points)
        return np.sqrt(np.asarray(squared_m2, dtype=np.float64)).reshape(len(points))


def _new_tree(vertices_m: np.ndarray, faces: np.ndarray):
    """A libigl AABB tree of the triangles (the one place a tree is built)."""
    import igl  # noqa: PLC0415  (only when distances are asked for)

    tree = igl.AABB()
    tree.init(vertices_m, faces)
    return tree


def closest_points(surface: TargetMesh) -> ClosestPoints:
    """The closest-point structure of ``surface``, built on its first use and then shared (the
    ``_KEPT`` meshes used last keep theirs)."""
    with _LOCK:
        kept = _TREES.pop(surface, None)
        if kept is None:
            kept = ClosestPoints(surface.vertices_m, surface.faces)
        _TREES[surface] = kept  # the newest last: the oldest goes first
        while len(_TREES) > _KEPT:
            _TREES.pop(next(iter(_TREES.keys())))
        return kept


def clear() -> None:
    """Drop every kept tree (the next query of each mesh builds its own again)."""
    with _LOCK:
        _TREES.clear()


def point_to_mesh_m(points, vertices_m, faces) -> np.ndarray:
    """(n,) exact distance of each point (n, 3) to the nearest of the triangles ``faces`` (m, 3)
    of ``vertices_m`` [m], with a tree built for this query alone; inf where there is no
    triangle. For a target's mesh, :func:`closest_points` shares one tree among queries."""
    return ClosestPoints(vertices_m, faces).distance_m(points)
