"""First-hit ray casting with Embree (embreex, the hard requirement): the caster of one target,
the hits of a block of pixels' sub-rays and of the whole array (docs/physics.md#geometry)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

try:  # embreex is a hard requirement: trimesh's numpy fallback manages ~100 rays/s
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(
        "lmapd-sim needs embreex for ray casting (pip install embreex); trimesh's pure-numpy "
        "ray caster is far too slow for flash-lidar frames"
    ) from exc

from .. import parallel
from ..target import TargetModel
from .poses import PoseInSensor


@dataclass(frozen=True, kw_only=True)
class RayHits:
    """First hits of n rays (:meth:`RayCaster.cast`).

    range_m : (n,) float64 -- lidar-to-hit distance, inf for a miss [m]
    face : (n,) int32 -- hit face index, -1 for a miss
    directions_t : (n, 3) float64 -- the unit directions in the target frame
    cos_theta : (n,) float64 or None -- abs(cos) of the incidence angle, 0 for a miss
    depth_m : (n,) float64 or None -- range times the direction's sensor-frame z (the boresight
        depth of the hit with sensor-frame directions), inf for a miss [m]
    """

    range_m: np.ndarray
    face: np.ndarray
    directions_t: np.ndarray
    cos_theta: np.ndarray | None = None
    depth_m: np.ndarray | None = None


class RayCaster:
    """First-hit ray casting against one target with Embree (BVH built once per target)."""

    def __init__(self, model: TargetModel):
        self.model = model
        self._scene = rtcore_scene.EmbreeScene()
        # shared vertices and an index buffer, as float64: embreex copies its input element by
        # element in Python, and this takes 0.2 s for the MRO where three float32 vertices per
        # triangle took 0.34 s (the same float32 triangles: the same BVH and hits)
        TriangleMesh(self._scene, model.vertices_m, model.faces)
        self._normals = model.face_normals
        self._radius = model.radius_m
        # the BVH is built lazily by the first query: build it now so its cost is paid here
        self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)

    def first_hits(self, origins_t, directions_t, start_m):
        """Cast rays given in the target frame.

        Parameters
        ----------
        origins_t : (3,) float64 -- ray origin (the lidar) in the target frame [m]
        directions_t : (n, 3) float64 -- unit directions in the target frame
        start_m : float -- distance along each ray at which tracing starts (keeps Embree's float32
            distances small and precise at long range) [m]

        Returns
        -------
        range_m : (n,) float64 -- distance from the lidar to the first hit, inf for a miss
        face : (n,) int32 -- hit face index, -1 for a miss
        """
        hits = self.cast(origins_t, directions_t, start_m)
        return hits.range_m, hits.face

    def cast(self, origins_t, directions, start_m, rotation=None, incidence=False) -> RayHits:
        """Cast rays, each chunk of them on one of the frame's threads from its directions to its
        hits: turned into the target frame, cast, and (``incidence``) the incidence cosine and
        boresight depth of each hit, so that this per-ray work scales with the threads as the
        traversal does (done serially it took a third of a 2-thread ray cast).

        Parameters
        ----------
        origins_t : (3,) float64 -- ray origin (the lidar) in the target frame [m]
        directions : (n, 3) float64 -- unit directions: in the target frame, or in the sensor
            frame with ``rotation``, the (3, 3) sensor-from-target rotation R (d_t = R^T d)
        start_m : float -- distance along each ray at which tracing starts [m]
        incidence : also the incidence cosines and depths (RayHits.cos_theta, depth_m)

        Returns
        -------
        RayHits -- its directions_t the target-frame directions (``directions`` itself without
        ``rotation``)
        """
        n = len(directions)
        directions = np.asarray(directions, dtype=np.float64)
        origins_t = np.asarray(origins_t, dtype=np.float64)
        # a few chunks per thread: rays near fine detail cost several times more than others,
        # and equal halves of an image are rarely equal work
        parts = parallel.threads() * (4 if n > 16384 else 1) if n > 4096 else 1
        bounds = np.linspace(0, n, parts + 1).astype(int)
        chunks = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        range_m = np.empty(n)
        face = np.empty(n, dtype=np.int32)
        dirs_t = directions if rotation is None else np.empty((n, 3))
        cos_t = np.empty(n) if incidence else None
        depth = np.empty(n) if incidence else None

        def run(part):
            """One chunk, its rays turned, made float32, cast and its hits written by the thread
            that casts it (each row's figures do not depend on where the chunks fall)."""
            if part.stop == part.start:
                return
            d = directions[part]
            if rotation is not None:
                d = np.matmul(d, rotation, out=dirs_t[part])  # R^T d for each row
            starts = (origins_t[None, :] + start_m * d).astype(np.float32)
            hits = self._scene.run(starts, d.astype(np.float32), output=1)
            primitive = np.asarray(hits["primID"])
            hit = primitive >= 0
            face[part] = primitive
            r = np.where(hit, start_m + hits["tfar"].astype(np.float64), np.inf)
            range_m[part] = r
            if cos_t is not None and depth is not None:
                normals = self.facet_normals(np.maximum(primitive, 0))
                cos_t[part] = np.where(hit, np.abs(np.einsum("ij,ij->i", normals, d)), 0.0)
                depth[part] = np.where(hit, r * directions[part, 2], np.inf)

        parallel.map_threads(run, chunks)
        return RayHits(
            range_m=range_m, face=face, directions_t=dirs_t, cos_theta=cos_t, depth_m=depth
        )

    def embree_hits(self, starts, directions) -> dict:
        """Embree's own first-hit query on float32 rays ((n, 3) each, target frame), nothing
        around it: the floor the benchmark sets :meth:`first_hits` against."""
        return self._scene.run(starts, directions, output=1)

    def occluded(self, origins_t, direction_t) -> np.ndarray:
        """(n,) bool: a ray from each of ``origins_t`` ((n, 3) float64, target frame [m]) along
        the one unit ``direction_t`` ((3,) target frame) meets the mesh (shadow rays toward the
        Sun; Embree's occlusion query, split over the worker threads like first hits)."""
        n = len(origins_t)
        if n == 0:
            return np.zeros(0, dtype=bool)
        starts = np.asarray(origins_t, dtype=np.float32)
        dirs32 = np.broadcast_to(np.asarray(direction_t, dtype=np.float32), (n, 3)).copy()
        parts = parallel.threads() * (4 if n > 16384 else 1) if n > 4096 else 1
        bounds = np.linspace(0, n, parts + 1).astype(int)
        chunks = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

        def run(part):
            if part.stop == part.start:
                return np.zeros(0, np.int32)
            return np.asarray(self._scene.run(starts[part], dirs32[part], query="OCCLUDED"))

        return np.concatenate(parallel.map_threads(run, chunks)) >= 0

    def facet_normals(self, face):
        """(n, 3) unit normals (target frame) of the given faces."""
        return np.take(self._normals, face, axis=0)  # (faster than fancy indexing rows)


@dataclass(frozen=True, kw_only=True)
class HitBlock:
    """First hits of K sub-rays in each of n pixels.

    Attributes
    ----------
    pixel : (n,) int64 -- flat pixel indices
    directions : (n, K, 3) float64 -- sub-ray unit directions, sensor frame
    range_m : (n, K) float64 -- lidar-to-hit distance, inf where the sub-ray misses
    cos_theta : (n, K) float64 -- abs(cos) of the incidence angle towards the lidar, 0 on a miss
    face : (n, K) int32 -- facet id, -1 on a miss
    depth_m : (n, K) float64 -- boresight depth z of the hit, sensor frame (for the paper's
        one-way-delay form of Eq. 29)
    spread_m : (n,) float64 or None -- standard deviation of the range over each sub-ray's cell
        of the pixel (``cell_spread``), None: each sub-ray a point sample
    """

    pixel: np.ndarray
    directions: np.ndarray
    range_m: np.ndarray
    cos_theta: np.ndarray
    face: np.ndarray
    depth_m: np.ndarray
    spread_m: np.ndarray | None = None

    @property
    def subrays(self) -> int:
        return self.directions.shape[1]

    def take(self, rows) -> HitBlock:
        """The block of some of its pixels (an index or a boolean mask)."""
        per_subray = ("pixel", "directions", "range_m", "cos_theta", "face", "depth_m")
        spread = self.spread_m[rows] if self.spread_m is not None else None
        return HitBlock(**{name: getattr(self, name)[rows] for name in per_subray}, spread_m=spread)


@dataclass(frozen=True, kw_only=True)
class Hits:
    """First hits of the whole array: the base sampling of every pixel and, if adaptive
    refinement is on, a denser sampling of the mixed pixels that replaces theirs.

    ``range_m``, ``cos_theta``, ``face``, ``depth_m`` are the base block's (n_pix, K) arrays.
    """

    base: HitBlock
    refined: HitBlock | None
    pose: PoseInSensor

    @property
    def range_m(self) -> np.ndarray:
        return self.base.range_m

    @property
    def cos_theta(self) -> np.ndarray:
        return self.base.cos_theta

    @property
    def face(self) -> np.ndarray:
        return self.base.face

    @property
    def depth_m(self) -> np.ndarray:
        return self.base.depth_m

    @property
    def refined_pixels(self) -> np.ndarray:
        return self.refined.pixel if self.refined is not None else np.zeros(0, np.int64)

    def blocks(self) -> list[HitBlock]:
        """Disjoint blocks covering every pixel: the base minus the refined pixels, the refined."""
        if self.refined is None:
            return [self.base]
        keep = np.ones(len(self.base.pixel), bool)
        keep[self.refined.pixel] = False
        return [self.base.take(keep), self.refined]

    @property
    def hit_pixel_mask(self) -> np.ndarray:
        """(n_pix,) bool: the pixel sees the target with at least one sub-ray."""
        mask = np.asarray((self.base.face >= 0).any(axis=1))
        if self.refined is not None:
            mask[self.refined.pixel] = (self.refined.face >= 0).any(axis=1)
        return mask

    @property
    def visible_faces(self) -> np.ndarray:
        """Sorted unique ids of the facets the lidar sees this frame."""
        faces = [b.face[b.face >= 0] for b in self.blocks()]
        return np.unique(np.concatenate(faces))


def cast_rays(caster: RayCaster, directions_s, pose: PoseInSensor, incidence: bool = True):
    """First hits of rays from the lidar along ``directions_s`` ((n, 3), sensor frame), with
    their incidence cosines and boresight depths (``incidence``), each chunk of rays turned into
    the target frame and its hits' figures computed on the thread that casts it."""
    origin_t = -pose.rotation.T @ pose.translation_m  # the lidar, in the target frame
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * caster._radius)
    return caster.cast(origin_t, directions_s, start, rotation=pose.rotation, incidence=incidence)


def cast_ranges(caster: RayCaster, directions_s, pose: PoseInSensor):
    """First hits of rays from the lidar along ``directions_s`` ((n, 3), sensor frame).

    Returns range_m (n,) [m, inf for a miss], face (n,) [-1 for a miss] and the directions in
    the target frame (n, 3)."""
    hits = cast_rays(caster, directions_s, pose, incidence=False)
    return hits.range_m, hits.face, hits.directions_t


def incidence_cos(caster: RayCaster, face, directions_t) -> np.ndarray:
    """(n,) abs(cos) of the incidence angle of rays on the faces they hit, 0 for a miss."""
    normals = caster.facet_normals(np.maximum(face, 0))
    return np.where(face >= 0, np.abs(np.einsum("ij,ij->i", normals, directions_t)), 0.0)


def cast_block(caster: RayCaster, pixel, directions, pose: PoseInSensor) -> HitBlock:
    """First hits of the sub-rays ``directions`` (n, K, 3, sensor frame) of pixels ``pixel``."""
    hits = cast_rays(caster, directions.reshape(-1, 3), pose)
    assert hits.cos_theta is not None and hits.depth_m is not None
    shape = directions.shape[:2]
    return HitBlock(
        pixel=np.asarray(pixel, dtype=np.int64),
        directions=directions,
        range_m=hits.range_m.reshape(shape),
        cos_theta=hits.cos_theta.reshape(shape),
        face=hits.face.reshape(shape),
        depth_m=hits.depth_m.reshape(shape),
    )
