"""The pixel ray grid: pinhole directions of each pixel's k x k sub-rays and of the pixel corners.

Pixel (row i, col j) of an n x n array looks along the pinhole direction
``normalize((x/f_r, y/f_r, 1))`` of its centre (docs/physics.md#geometry).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


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


def corner_directions(pixels: int, fov_rad: float) -> np.ndarray:
    """((pixels + 1)**2, 3) unit sensor-frame directions through the pixel corners, row-major."""
    pitch = 2.0 * np.tan(fov_rad / 2.0) / pixels
    g = (np.arange(pixels + 1) - pixels / 2.0) * pitch
    return unit_directions(g[None, :], g[:, None]).reshape(-1, 3)
