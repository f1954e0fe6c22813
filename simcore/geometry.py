"""Frames, poses, the pixel ray grid and first-hit ray casting (embreex, the hard requirement).

Sensor frame: origin at the lidar, z = boresight, x = image right (columns), y = image down (rows);
right-handed. Pixel (row i, col j) of an n x n array looks along the pinhole direction
``normalize((x/f_r, y/f_r, 1))`` of its centre.

The model: docs/physics.md#geometry (pose, pixel grid, first hits, refinement of mixed pixels).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

try:  # embreex is a hard requirement: trimesh's numpy fallback manages ~100 rays/s
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(
        "lmapd-sim needs embreex for ray casting (pip install embreex); trimesh's pure-numpy "
        "ray caster is far too slow for flash-lidar frames"
    ) from exc

from . import parallel
from .constants import C
from .illumination import illumination_gain
from .pulse import scene_pulse_shape
from .receivers.lm_apd import timing
from .scene import Pose, Scene
from .stage import Stage, readonly
from .target import TargetModel, load_target, source_stamp


# ----------------------------------------------------------------------------------------------
# poses
# ----------------------------------------------------------------------------------------------
def rotation_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quaternion_matrix(q_wxyz) -> np.ndarray:
    """(3, 3) active rotation matrix of a (not necessarily unit) quaternion w, x, y, z."""
    w, x, y, z = np.asarray(q_wxyz, dtype=np.float64) / np.linalg.norm(q_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def front_view_rotation(extents) -> np.ndarray:
    """Rotation (sensor <- target) of the zero pose: the line of sight runs along the target's
    smallest extent, its largest extent lies along the image x axis, the middle one points up."""
    order = np.argsort(extents)  # smallest, middle, largest
    rot = np.zeros((3, 3))
    rot[0, order[2]] = 1.0  # sensor x <- largest extent
    rot[1, order[1]] = -1.0  # sensor y (down) <- minus the middle extent (it points up)
    rot[2, order[0]] = 1.0  # sensor z (line of sight) <- smallest extent
    if np.linalg.det(rot) < 0:
        rot[2] *= -1.0
    return rot


@dataclass(frozen=True, kw_only=True)
class PoseInSensor:
    """Where the target is: p_sensor = rotation @ p_target + translation_m."""

    rotation: np.ndarray  # (3, 3)
    translation_m: np.ndarray  # (3,)


def target_pose(pose: Pose, extents, body_from_mesh=None) -> PoseInSensor:
    """The target's pose in the sensor frame: its origin at ``distance_m`` along the boresight,
    moved sideways by ``offset_x_m``, ``offset_y_m`` (0: on the boresight).

    With no quaternion: R = Rz(roll) Rx(pitch) Ry(azimuth) R0, rotations about the sensor's own axes
    applied to the front view R0 (azimuth first, then pitch, then roll). With ``quaternion_wxyz``
    (target body -> sensor, as orbit.relative_pose_series gives it): R = Q @ body_from_mesh.
    """
    if pose.quaternion_wxyz:
        body = np.eye(3) if body_from_mesh is None else body_from_mesh
        rot = quaternion_matrix(pose.quaternion_wxyz) @ body
    else:
        rot = (
            rotation_z(np.radians(pose.roll_deg))
            @ rotation_x(np.radians(pose.pitch_deg))
            @ rotation_y(np.radians(pose.azimuth_deg))
            @ front_view_rotation(extents)
        )
    return PoseInSensor(
        rotation=rot,
        translation_m=np.array([pose.offset_x_m, pose.offset_y_m, pose.distance_m]),
    )


# ----------------------------------------------------------------------------------------------
# the pixel grid
# ----------------------------------------------------------------------------------------------
def subray_tangents(pixels: int, fov_rad: float, subrays_per_side: int, pixel_index=None):
    """Focal-plane tangents (x/f, y/f) of the k x k sub-pixel centres of some pixels.

    Parameters
    ----------
    pixel_index : (n,) int, optional -- flat pixel indices (row * pixels + col); all if None

    Returns
    -------
    tx, ty : (n, k, k) float64 -- tangents along x (columns) and y (rows); the k x k sub-rays
        sample each pixel's field on a regular grid of sub-pixel centres
    """
    if pixel_index is None:
        pixel_index = np.arange(pixels * pixels)
    pitch = 2.0 * np.tan(fov_rad / 2.0) / pixels  # tangent-plane size of one pixel
    k = subrays_per_side
    row, col = np.divmod(np.asarray(pixel_index), pixels)
    sub = (np.arange(k) - (k - 1) / 2.0) * pitch / k
    tx = ((col - (pixels - 1) / 2.0) * pitch)[:, None, None] + sub[None, None, :]
    ty = ((row - (pixels - 1) / 2.0) * pitch)[:, None, None] + sub[None, :, None]
    return np.broadcast_arrays(tx, ty)


def subray_directions(pixels: int, fov_rad: float, subrays: int, pixel_index=None):
    """(n, subrays, 3) unit sensor-frame directions of the sub-rays of some (default all) pixels."""
    k = int(round(np.sqrt(subrays)))
    tx, ty = subray_tangents(pixels, fov_rad, k, pixel_index)
    return unit_directions(tx, ty).reshape(len(tx), k * k, 3)


def unit_directions(tx, ty) -> np.ndarray:
    """(..., 3) unit vectors normalize((tx, ty, 1))."""
    tx, ty = np.broadcast_arrays(np.asarray(tx, dtype=np.float64), ty)
    d = np.empty((*tx.shape, 3))
    inv = 1.0 / np.sqrt(1.0 + tx * tx + ty * ty)
    np.multiply(tx, inv, out=d[..., 0])
    np.multiply(ty, inv, out=d[..., 1])
    d[..., 2] = inv
    return d


@dataclass(frozen=True, kw_only=True)
class RayGrid:
    """The array's rays in the sensor frame.

    Attributes
    ----------
    directions : (pixels**2, K, 3) float64
        Unit direction of each sub-ray, pixel-major (flat pixel index = row * pixels + col).
    pixel_directions : (pixels**2, 3) float64
        Unit direction u_pix of each pixel centre (points are placed along it).
    """

    pixels: int
    subrays: int
    ifov_rad: float
    directions: np.ndarray
    pixel_directions: np.ndarray
    fov_rad: float

    @cached_property
    def corner_directions(self) -> np.ndarray:
        """((pixels + 1)**2, 3) unit directions through the pixel corners, row-major (made on
        first use, by ``Fidelity.probe_corners``)."""
        corners = corner_directions(self.pixels, self.fov_rad)
        corners.setflags(write=False)
        return corners


def ray_grid(pixels: int, fov_rad: float, subrays: int) -> RayGrid:
    dirs = subray_directions(pixels, fov_rad, subrays)
    centre = subray_directions(pixels, fov_rad, 1)[:, 0]
    for a in (dirs, centre):
        a.setflags(write=False)
    return RayGrid(
        pixels=pixels,
        subrays=dirs.shape[1],
        ifov_rad=fov_rad / pixels,
        directions=dirs,
        pixel_directions=centre,
        fov_rad=fov_rad,
    )


# ----------------------------------------------------------------------------------------------
# ray casting
# ----------------------------------------------------------------------------------------------
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
        n = len(directions_t)
        directions_t = np.asarray(directions_t, dtype=np.float64)
        origins_t = np.asarray(origins_t, dtype=np.float64)
        # a few chunks per thread: rays near fine detail cost several times more than others,
        # and equal halves of an image are rarely equal work
        parts = parallel.threads() * (4 if n > 16384 else 1) if n > 4096 else 1
        bounds = np.linspace(0, n, parts + 1).astype(int)
        chunks = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        range_m = np.empty(n)
        face = np.empty(n, dtype=np.int32)

        def run(part):
            """One chunk, its float32 rays made and its hits written by the thread that casts
            it: the conversions scale with the threads as the traversal does."""
            if part.stop == part.start:
                return
            d = directions_t[part]
            starts = (origins_t[None, :] + start_m * d).astype(np.float32)
            hits = self._scene.run(starts, d.astype(np.float32), output=1)
            primitive = np.asarray(hits["primID"])
            face[part] = primitive
            range_m[part] = np.where(
                primitive >= 0, start_m + hits["tfar"].astype(np.float64), np.inf
            )

        parallel.map_threads(run, chunks)
        return range_m, face

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


def cast_ranges(caster: RayCaster, directions_s, pose: PoseInSensor):
    """First hits of rays from the lidar along ``directions_s`` ((n, 3), sensor frame).

    Returns range_m (n,) [m, inf for a miss], face (n,) [-1 for a miss] and the directions in
    the target frame (n, 3)."""
    origin_t = -pose.rotation.T @ pose.translation_m  # the lidar, in the target frame
    dirs_t = directions_s @ pose.rotation  # R^T d for each row
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * caster._radius)
    range_m, face = caster.first_hits(origin_t, dirs_t, start)
    return range_m, face, dirs_t


def incidence_cos(caster: RayCaster, face, directions_t) -> np.ndarray:
    """(n,) abs(cos) of the incidence angle of rays on the faces they hit, 0 for a miss."""
    normals = caster.facet_normals(np.maximum(face, 0))
    return np.where(face >= 0, np.abs(np.einsum("ij,ij->i", normals, directions_t)), 0.0)


def cast_block(caster: RayCaster, pixel, directions, pose: PoseInSensor) -> HitBlock:
    """First hits of the sub-rays ``directions`` (n, K, 3, sensor frame) of pixels ``pixel``."""
    dirs_s = directions.reshape(-1, 3)
    range_m, face, dirs_t = cast_ranges(caster, dirs_s, pose)
    hit = face >= 0
    cos_t = incidence_cos(caster, face, dirs_t)
    depth = np.where(hit, range_m * dirs_s[:, 2], np.inf)
    shape = directions.shape[:2]
    return HitBlock(
        pixel=np.asarray(pixel, dtype=np.int64),
        directions=directions,
        range_m=range_m.reshape(shape),
        cos_theta=cos_t.reshape(shape),
        face=face.reshape(shape),
        depth_m=depth.reshape(shape),
    )


def corner_directions(pixels: int, fov_rad: float) -> np.ndarray:
    """((pixels + 1)**2, 3) unit sensor-frame directions through the pixel corners, row-major."""
    pitch = 2.0 * np.tan(fov_rad / 2.0) / pixels
    g = (np.arange(pixels + 1) - pixels / 2.0) * pitch
    return unit_directions(g[None, :], g[:, None]).reshape(-1, 3)


@dataclass(frozen=True, kw_only=True)
class CornerSamples:
    """First hits of the rays through the pixel corners, each (pixels + 1, pixels + 1)."""

    range_m: np.ndarray  # inf for a miss
    part: np.ndarray  # the hit face's target part, -1 for a miss
    cos_theta: np.ndarray  # abs(cos) of the incidence angle, 0 for a miss


COS_STEP = 0.1  # a change of incidence cosine within a pixel that marks it mixed (a crease)


def mixed_pixels(
    block: HitBlock,
    pixels: int,
    step_m: float,
    corners: CornerSamples | None = None,
    face_part: np.ndarray | None = None,
    steep_m: float = np.inf,
) -> np.ndarray:
    """Flat indices of the pixels a few sub-rays cannot represent.

    A pixel is mixed when its sub-rays disagree (some hit, some miss, or their ranges leave a
    plane fitted to them by more than ``step_m``: tilted planes pass, steps do not), or when the
    mean-range image has a second difference above ``step_m`` at it (near zero on planes and
    gently curved surfaces; a depth step marks the pixels on both sides of it).

    Without ``corners`` a pixel whose hit status differs from a 4-neighbour's is mixed too (both
    sides of the silhouette). With ``corners`` (rays through the pixel corners) the corners and
    the sub-rays are the pixel's samples: it is mixed when they disagree on hit or miss (a straight
    silhouette edge crosses a square if and only if it separates two of its corners, so this finds
    the silhouette without its outer ring), on the target part they hit (``face_part`` maps faces
    to parts; a part boundary may be a material boundary), or on the incidence cosine by more
    than COS_STEP (a crease), when its corners do not lie on a plane (twist above ``step_m``) or
    when its mean range leaves the mean of its corners by more than ``step_m`` (a step between
    samples). Corners halve the gap a thin part can hide in (struts, panel edges seen edge-on).

    A pixel across which the range changes by more than ``steep_m`` (from its corners or its
    sub-ray plane) is mixed too: near grazing one pixel spans a metre of range and its echo is a
    broad plateau that a few samples, even spread over their cells, do not stand for (50 mm off
    at 45 deg pitch, 30 deg azimuth on the MRO).
    """
    hit = block.face >= 0
    k = block.subrays
    count = np.count_nonzero(hit, axis=1)
    any_hit, full = count > 0, count == k
    mixed = any_hit & ~full
    r = np.where(hit, block.range_m, 0.0)  # sums over the short sub-ray axis as matrix products
    grad = None
    if k > 1:  # least-squares plane r = a + b x + c y over the sub-pixel grid (x, y in sub-steps)
        side = int(round(np.sqrt(k)))
        g = np.arange(side) - (side - 1) / 2.0
        x = np.tile(g, side)
        y = np.repeat(g, side)
        a = r @ np.full(k, 1.0 / k)
        b = r @ (x / (x @ x))
        c = r @ (y / (y @ y))
        plane = a[:, None] + b[:, None] * x + c[:, None] * y
        residual = np.abs(r - plane).max(axis=1)
        mixed |= full & (residual > step_m)
        # the plane's range change per pixel along rows (axis 0, y) and columns (axis 1, x)
        grad = [np.where(full, v * side, np.nan).reshape(pixels, pixels) for v in (c, b)]
    r_mean = np.where(any_hit, (r @ np.ones(k)) / np.maximum(count, 1), np.nan).reshape(
        pixels, pixels
    )
    seen = any_hit.reshape(pixels, pixels)
    flag = mixed.reshape(pixels, pixels).copy()
    if corners is not None:
        flag |= _corner_flags(block, pixels, step_m, steep_m, corners, face_part, r_mean, full)
    for axis in (0, 1):
        a_, b_ = [slice(None)] * 2, [slice(None)] * 2
        a_[axis], b_[axis] = slice(None, -1), slice(1, None)
        if corners is None:
            differ = seen[tuple(a_)] != seen[tuple(b_)]
            flag[tuple(a_)] |= differ
            flag[tuple(b_)] |= differ
        lo, mid, hi = [slice(None)] * 2, [slice(None)] * 2, [slice(None)] * 2
        lo[axis], mid[axis], hi[axis] = slice(None, -2), slice(1, -1), slice(2, None)
        with np.errstate(invalid="ignore"):
            second = np.abs(r_mean[tuple(lo)] - 2 * r_mean[tuple(mid)] + r_mean[tuple(hi)])
            flag[tuple(mid)] |= second > step_m  # NaN (a missing neighbour) compares False
            if grad is not None:  # a step inside a pixel: its own gradient is not its neighbours'
                across = 0.5 * (r_mean[tuple(hi)] - r_mean[tuple(lo)])
                flag[tuple(mid)] |= np.abs(grad[axis][tuple(mid)] - across) > step_m
    if grad is not None:  # steep
        with np.errstate(invalid="ignore"):
            flag |= np.hypot(grad[0], grad[1]) > steep_m
    return np.flatnonzero(flag)


def _quad(a: np.ndarray) -> np.ndarray:
    """(4, n, n) the four corner values of each pixel from an (n + 1, n + 1) corner image."""
    return np.stack((a[:-1, :-1], a[:-1, 1:], a[1:, :-1], a[1:, 1:]))


def _corner_flags(block, pixels, step_m, steep_m, corners, face_part, r_mean, full):
    """(pixels, pixels) bool: the pixel's corners and sub-rays disagree (see mixed_pixels)."""
    shape = (block.subrays, pixels, pixels)  # the sub-ray samples, laid out like _quad's
    c_range = _quad(corners.range_m)
    c_hit = np.isfinite(c_range)
    flag = (c_hit.any(axis=0) | ~np.isnan(r_mean)) & ~(c_hit.all(axis=0) & full.reshape(pixels, -1))
    with np.errstate(invalid="ignore"):  # inf - inf is NaN: compares False
        twist = np.abs(c_range[0] + c_range[3] - c_range[1] - c_range[2])
        off = np.abs(r_mean - c_range.mean(axis=0))
        change = np.hypot(*_corner_slopes(c_range))
    flag |= (twist > step_m) | (off > step_m) | (change > steep_m)
    cos = np.concatenate([_quad(corners.cos_theta), block.cos_theta.T.reshape(shape)])
    flag |= cos.max(axis=0) - cos.min(axis=0) > COS_STEP
    if face_part is not None:
        part = np.where(block.face >= 0, face_part[np.maximum(block.face, 0)], -1)
        parts = np.concatenate([_quad(corners.part), part.T.reshape(shape)])
        flag |= parts.max(axis=0) != parts.min(axis=0)
    return flag


def _corner_slopes(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range change across a pixel along x and y from its corner ranges c = (top-left,
    top-right, bottom-left, bottom-right), as _quad lays them out."""
    return 0.5 * (c[1] - c[0] + c[3] - c[2]), 0.5 * (c[2] - c[0] + c[3] - c[1])


def cell_spread_m(block: HitBlock, corners: CornerSamples | None = None) -> np.ndarray:
    """(n,) standard deviation of the range over each sub-ray's cell of the pixel [m].

    A k x k grid of sub-rays samples a tilted surface at points; each stands for a cell 1/k of
    the pixel on a side over which the range changes by g/k (g, the range change across the
    pixel, along x and y): a uniform spread of variance (g_x^2 + g_y^2) / (12 k^2) that the point
    samples leave out (for one ray per pixel, all of the pixel's pulse broadening). The slope
    comes from the pixel's four corners where they all hit, else from the plane fitted to the
    sub-rays where they all hit (k > 1), else it is taken as 0.
    """
    k = math.isqrt(block.subrays)
    gx = gy = np.zeros(len(block.pixel))
    if k > 1:  # the least-squares plane over the sub-pixel grid, slopes per pixel
        g = (np.arange(k) - (k - 1) / 2.0) / k
        x, y = np.tile(g, k), np.repeat(g, k)
        r = np.where(block.face >= 0, block.range_m, 0.0)
        full = (block.face >= 0).all(axis=1)
        gx = np.where(full, r @ (x / (x @ x)), 0.0)
        gy = np.where(full, r @ (y / (y @ y)), 0.0)
    if corners is not None:
        c = _quad(corners.range_m).reshape(4, -1)[:, block.pixel]
        ok = np.isfinite(c).all(axis=0)
        cx, cy = _corner_slopes(np.where(ok, c, 0.0))
        gx, gy = np.where(ok, cx, gx), np.where(ok, cy, gy)
    return np.sqrt((gx**2 + gy**2) / 12.0) / k


def straddles(corner_values: np.ndarray) -> np.ndarray:
    """(n, n) bool: the pixel's four corners disagree, from an (n + 1, n + 1) bool corner image."""
    q = _quad(corner_values)
    return np.asarray(q.any(axis=0) & ~q.all(axis=0))


def probe(caster: RayCaster, rays: RayGrid, pose: PoseInSensor) -> CornerSamples:
    """Cast the rays through the pixel corners."""
    range_m, face, dirs_t = cast_ranges(caster, rays.corner_directions, pose)
    hit = face >= 0
    cos_t = incidence_cos(caster, face, dirs_t)
    part = np.where(hit, caster.model.face_part[np.maximum(face, 0)], -1)
    n1 = rays.pixels + 1
    return CornerSamples(
        range_m=range_m.reshape(n1, n1), part=part.reshape(n1, n1), cos_theta=cos_t.reshape(n1, n1)
    )


def cast(
    caster: RayCaster,
    rays: RayGrid,
    pose: PoseInSensor,
    refine_subrays: int = 0,
    refine_step_m: float = 0.02,
    probe_corners: bool = False,
    cell_spread: bool = False,
    lit_edge: np.ndarray | None = None,
    steep_m: float = np.inf,
) -> Hits:
    """First hit of every sub-ray of the array for the target in ``pose``; with
    ``refine_subrays`` > the base count, the mixed pixels are cast again that densely (found with
    rays through the pixel corners too if ``probe_corners``), and so are the pixels of
    ``lit_edge`` ((pixels, pixels) bool: the edge of the illuminated field crosses them) that see
    the target, and those across which the range changes by more than ``steep_m``. With
    ``cell_spread`` the base block carries each sub-ray cell's range spread (``cell_spread_m``)."""
    base = cast_block(caster, np.arange(rays.pixels**2), rays.directions, pose)
    refined = corners = None
    if refine_subrays > rays.subrays:
        corners = probe(caster, rays, pose) if probe_corners else None
        which = mixed_pixels(
            base, rays.pixels, refine_step_m, corners, caster.model.face_part, steep_m
        )
        if lit_edge is not None:
            seen = (base.face >= 0).any(axis=1)
            if corners is not None:
                seen |= np.isfinite(_quad(corners.range_m)).any(axis=0).ravel()
            which = np.union1d(which, np.flatnonzero(lit_edge.ravel() & seen))
        dirs = subray_directions(rays.pixels, rays.fov_rad, refine_subrays, which)
        refined = cast_block(caster, which, dirs, pose)
    if cell_spread:
        base = dataclasses.replace(base, spread_m=cell_spread_m(base, corners))
    return Hits(base=base, refined=refined, pose=pose)


# ----------------------------------------------------------------------------------------------
# the stages: target, rays, hits
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TargetStage:
    """The target mesh (with its parts and default materials) and its ray caster (BVH built)."""

    model: TargetModel
    caster: RayCaster


def stage_target(scene: Scene) -> TargetStage:
    model = load_target(scene.target)
    return TargetStage(model=model, caster=RayCaster(model))


def stage_rays(scene: Scene) -> RayGrid:
    return ray_grid(scene.detector.pixels, scene.receive.fov_rad, scene.fidelity.subrays)


@lru_cache(maxsize=8)
def beam_edge(pixels: int, fov_rad: float, theta_ill_rad: float, model: str) -> np.ndarray:
    """(pixels, pixels) bool: the edge of a flat-top or square beam crosses the pixel (its
    corners are not all lit or all dark; never for a Gaussian beam). The same for every pose."""
    gain = illumination_gain(corner_directions(pixels, fov_rad), theta_ill_rad, model)
    edge = straddles((gain > 0).reshape(pixels + 1, -1))
    edge.setflags(write=False)
    return edge


def stage_hits(scene: Scene, tgt: TargetStage, rays: RayGrid) -> Hits:
    """First hits of every sub-ray, the mixed pixels re-cast densely when the scene refines."""
    pose = target_pose(scene.pose, tgt.model.extents_m, tgt.model.body_from_mesh)
    fid = scene.fidelity
    lit_edge, steep_m = None, np.inf  # what refinement needs besides the mixed pixels
    if fid.refine_subrays > rays.subrays:
        lit_edge = beam_edge(
            rays.pixels, rays.fov_rad, scene.illumination_angle_rad, scene.transmit.illumination
        )
        # a pixel whose range changes by more than half the pulse's rise time (in range) across
        # it echoes a plateau: refined (about 21 cm for 5 ns at 120 MHz)
        steep_m = 0.5 * timing.rise_time_10_90_s(scene_pulse_shape(scene)) * C / 2
    hits = cast(
        tgt.caster,
        rays,
        pose,
        fid.refine_subrays,
        fid.refine_step_m,
        fid.probe_corners,
        fid.cell_spread,
        lit_edge,
        steep_m,
    )
    for block in (hits.base, hits.refined):
        if block is not None:
            readonly(block.range_m, block.cos_theta, block.face, block.depth_m)
    return hits


def _hits_reads(s: Scene) -> tuple:
    """The pose, the refinement knobs and, when refining, the beam edge and the pulse's rise."""
    return (
        s.pose,
        s.receive.fov_rad,
        s.fidelity.refine_subrays,
        s.fidelity.refine_step_m,
        s.fidelity.probe_corners,
        s.fidelity.cell_spread,
        s.illumination_angle_rad,
        s.transmit.illumination,
        s.laser.pulse_width_s,
        s.detector.bandwidth_hz,
        s.uses("pulse_constant"),
    )


TARGET = Stage(
    name="target",
    upstream=(),
    reads=lambda s: (
        s.target.mesh,
        s.target.scale_m_per_unit,
        s.target.size_m,
        s.target.alpha_threshold,
        s.target.material_map,
        source_stamp(s.target),  # a file overwritten in place is read again
    ),
    compute=stage_target,
)
RAYS = Stage(
    name="rays",
    upstream=(),
    reads=lambda s: (s.detector.pixels, s.receive.fov_rad, s.fidelity.subrays),
    compute=stage_rays,
)
HITS = Stage(name="hits", upstream=("target", "rays"), reads=_hits_reads, compute=stage_hits)
