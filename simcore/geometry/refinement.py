"""Refinement of mixed pixels: the pixels a few sub-rays cannot represent (silhouettes, depth
steps, creases, parts, steep slopes, the beam's edge), found from the sub-rays and the rays through
the pixel corners, cast again densely; the range spread of each sub-ray's cell
(docs/physics.md#geometry)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .casting import HitBlock, Hits, RayCaster, cast_block, cast_rays
from .poses import PoseInSensor
from .rays import RayGrid, subray_directions


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
    hits = cast_rays(caster, rays.corner_directions, pose)
    assert hits.cos_theta is not None
    part = np.where(hits.face >= 0, caster.model.face_part[np.maximum(hits.face, 0)], -1)
    n1 = rays.pixels + 1
    return CornerSamples(
        range_m=hits.range_m.reshape(n1, n1),
        part=part.reshape(n1, n1),
        cos_theta=hits.cos_theta.reshape(n1, n1),
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
