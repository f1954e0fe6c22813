"""Point cloud assembly: measured ranges along each pixel's line of sight, plus outliers, and
the ground truth of every point (the part it came from, its true range and error, the incidence).

The model: docs/physics.md#point-cloud, docs/physics.md#ground-truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import parallel
from .constants import C
from .pulse import A_FWHM
from .stage import Stage

if TYPE_CHECKING:
    from .echo import EchoStage
    from .geometry import Hits, RayGrid
    from .receivers import Detection, Response
    from .scene import Scene

ATTRIBUTES = (
    ("row", np.int32),
    ("col", np.int32),
    ("range_m", np.float64),
    ("intensity_w", np.float64),
    ("snr", np.float64),
    ("material_id", np.int32),
    ("facet_id", np.int32),
    ("is_outlier", np.bool_),
)
# the ground truth of every point (NaN / -1 for a false alarm, which no surface produced)
GROUND_TRUTH = (
    ("part_id", np.int32),  # the target part of the surface that gave the point
    ("true_range_m", np.float64),  # the noise-free range of that surface in the pixel [m]
    ("range_error_m", np.float64),  # measured minus true range [m]
    ("incidence_deg", np.float64),  # angle between the line of sight and the facet normal
    ("outlier", np.bool_),  # a false alarm, or a target point more than quality.tau_m off
)


@dataclass(frozen=True, kw_only=True)
class PointCloud:
    """points : (n, 3) float64 [m], sensor frame; attributes : name -> (n,) array (ATTRIBUTES)."""

    points: np.ndarray
    attributes: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.points)


def assemble_cloud(
    pixel_directions,
    pixels: int,
    target_pixel,
    target_range_m,
    intensity_w,
    snr,
    material_id,
    facet_id,
    outlier_pixel,
    outlier_range_m,
) -> PointCloud:
    """Points R u_pix for detected target pixels, then the outliers (Section 4, steps 4-5).

    pixel_directions : (pixels**2, 3) unit u_pix of every pixel
    target_* : (n,) per detected target pixel (flat index, measured range, peak power, SNR, ids)
    outlier_* : (n_out,) flat pixel index and range of each false alarm
    """
    pix = np.concatenate([target_pixel, outlier_pixel]).astype(np.int64)
    rng_m = np.concatenate([target_range_m, outlier_range_m])
    n_t, n_o = len(target_pixel), len(outlier_pixel)
    points = pixel_directions[pix] * rng_m[:, None]
    attrs: dict[str, np.ndarray] = {
        "row": (pix // pixels).astype(np.int32),
        "col": (pix % pixels).astype(np.int32),
        "range_m": rng_m.astype(np.float64),
        "intensity_w": np.concatenate([intensity_w, np.zeros(n_o)]),
        "snr": np.concatenate([snr, np.zeros(n_o)]),
        "material_id": np.concatenate([material_id, np.full(n_o, -1)]).astype(np.int32),
        "facet_id": np.concatenate([facet_id, np.full(n_o, -1)]).astype(np.int32),
        "is_outlier": np.concatenate([np.zeros(n_t, bool), np.ones(n_o, bool)]),
    }
    return PointCloud(points=points, attributes=attrs)


def stage_cloud(
    scene: Scene, rays: RayGrid, hits: Hits, echo: EchoStage, response: Response, det: Detection
) -> PointCloud:
    """The cloud stage: detected target pixels at their measured ranges, then the outliers;
    the shared attributes (ATTRIBUTES), the ground truth (GROUND_TRUTH) and the receiver's own
    (``Detection.point_attributes``)."""
    k = det.detected
    cloud = assemble_cloud(
        rays.pixel_directions,
        rays.pixels,
        echo.pixel[k],
        det.range_m[k],
        response.peak_power_w[k],
        response.snr[k],
        echo.material_id[k],
        echo.facet_id[k],
        det.outliers.pixel,
        det.outliers.range_m,
    )
    truth = ground_truth(
        echo,
        hits,
        np.flatnonzero(k),
        det.range_m[k],
        len(det.outliers.pixel),
        tau_m=scene.quality.tau_m,
    )
    cloud.attributes.update(truth)
    for name, (lit_values, outlier_values) in det.point_attributes.items():
        cloud.attributes[name] = np.concatenate([np.asarray(lit_values)[k], outlier_values])
    beyond_reach(cloud, hits, echo.model.radius_m, scene.quality.tau_m)
    return cloud


def beyond_reach(cloud: PointCloud, hits: Hits, radius_m: float, tau_m: float) -> np.ndarray:
    """Mark IN PLACE as false alarms (``is_outlier``, no ground truth) the target points whose
    range lies more than ``tau_m`` outside the target's reach, the shell of its bounding sphere
    (``radius_m`` about its origin) seen from the lidar: no point of the target can lie there (a
    Geiger-mode pixel's densest window in its noise, 119-165 m off at 1 us of jitter). Returns
    (n,) bool, the points marked."""
    attrs = cloud.attributes
    centre_m = float(np.linalg.norm(hits.pose.translation_m))
    r = np.asarray(attrs["range_m"])
    far = ~attrs["is_outlier"] & (
        (r < centre_m - radius_m - tau_m) | (r > centre_m + radius_m + tau_m)
    )
    if far.any():
        attrs["is_outlier"] = attrs["is_outlier"] | far
        attrs["outlier"] = attrs["outlier"] | far
        attrs["part_id"] = np.where(far, -1, attrs["part_id"]).astype(np.int32)
        for name in ("true_range_m", "range_error_m", "incidence_deg"):
            attrs[name] = np.where(far, np.nan, attrs[name])
    return far


def surface_gap_s(echo: EchoStage) -> float:
    """Two surfaces in one pixel give separate echoes when their delays differ by more than the
    emitted pulse's FWHM (tau A_FWHM / a, Eq. 1) [s]; closer, one echo carries both."""
    return echo.shape.tau_s * A_FWHM / echo.shape.a


def pixel_surfaces(arrivals_s, weights, gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The surfaces each pixel sees: its echo elements sorted by delay, a new surface wherever
    the next lit element comes more than ``gap_s`` after the previous one.

    arrivals_s, weights : (n, K) each pixel's element delays [s] and Eq. 30 weights (0: no light)
    Returns the energy-weighted delay of each surface (n, K) [s] (NaN past a pixel's last
    surface), in order of delay, and each surface's weight (n, K) [1] (0 there).
    """
    a = np.asarray(arrivals_s, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    n, k = w.shape
    lit = w > 0
    order = np.argsort(np.where(lit, a, np.inf), axis=1, kind="stable")
    a = np.take_along_axis(a, order, axis=1)
    w = np.take_along_axis(w, order, axis=1)
    lit = np.take_along_axis(lit, order, axis=1)
    new = np.ones((n, k), dtype=bool)
    new[:, 1:] = a[:, 1:] - a[:, :-1] > gap_s
    slot = np.arange(n)[:, None] * k + np.cumsum(new, axis=1) - 1
    weight = np.bincount(slot[lit], w[lit], minlength=n * k).reshape(n, k)
    moment = np.bincount(slot[lit], (w * a)[lit], minlength=n * k).reshape(n, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        delay = np.where(weight > 0, moment / weight, np.nan)
    return delay, weight


# Fewer points than this get their ground truth on one thread: 10-15 ns a point (a 256 x 256
# frame's 13,400 points in 0.1-0.2 ms a kernel), well under the cost of waking a second thread
TRUTH_SERIAL_BELOW = 65536


def ground_truth(
    echo: EchoStage,
    hits: Hits,
    lit_index,
    range_m,
    n_outliers: int,
    tau_m: float,
) -> dict[str, np.ndarray]:
    """The ground truth of the cloud's points: the target points first (lit pixels
    ``lit_index`` (m,) of ``echo.pixel``, measured at ``range_m`` (m,) [m]), then ``n_outliers``
    false alarms. The surface that gave a point is the pixel's surface
    (:func:`pixel_surfaces`) nearest its measured range; its true range is that surface's
    noise-free energy-weighted range c/2 sum(w t) / sum(w) (Eqs. 29-30), its part and incidence
    those of the pixel's sub-ray that hit nearest that range. Returns GROUND_TRUTH's arrays,
    each (m + n_outliers,).
    """
    lit_index = np.asarray(lit_index, dtype=np.int64)
    range_m = np.asarray(range_m, dtype=np.float64)
    m = len(lit_index)
    kernel = _kernel()
    if kernel is not None:  # the same surfaces and sums per point, on the frame's threads
        true_m = kernel.nearest_surface_m(
            echo.arrivals_s, echo.weights, lit_index, range_m, surface_gap_s(echo), 0.5 * C,
            parallel.threads_for(m, TRUTH_SERIAL_BELOW),
        )  # fmt: skip
    else:
        delay_s, _ = pixel_surfaces(
            echo.arrivals_s[lit_index], echo.weights[lit_index], surface_gap_s(echo)
        )
        surface_m = 0.5 * C * delay_s
        if m:
            nearest = np.argmin(
                np.where(np.isnan(surface_m), np.inf, np.abs(surface_m - range_m[:, None])),
                axis=1,
            )
            true_m = surface_m[np.arange(m), nearest]
        else:
            true_m = np.zeros(0)
    face, cos_theta = _nearest_subray(hits, echo.pixel[lit_index], true_m, kernel)
    part = np.where(face >= 0, np.asarray(echo.model.face_part)[np.maximum(face, 0)], -1)
    error_m = range_m - true_m
    with np.errstate(invalid="ignore"):
        incidence_deg = np.degrees(np.arccos(np.clip(cos_theta, 0.0, 1.0)))
    pad_nan = np.full(n_outliers, np.nan)
    return {
        "part_id": np.concatenate([part, np.full(n_outliers, -1)]).astype(np.int32),
        "true_range_m": np.concatenate([true_m, pad_nan]),
        "range_error_m": np.concatenate([error_m, pad_nan]),
        "incidence_deg": np.concatenate([np.where(face >= 0, incidence_deg, np.nan), pad_nan]),
        "outlier": np.concatenate([~(np.abs(error_m) <= tau_m), np.ones(n_outliers, bool)]),
    }


def _kernel():
    """The compiled kernel (simcore.echo.kernel), or None on the numpy path."""
    from .echo.features import compiled_kernel  # noqa: PLC0415  (numba, loaded on first use)

    return compiled_kernel()


def _nearest_subray(hits: Hits, pixel, range_m, kernel=None) -> tuple[np.ndarray, np.ndarray]:
    """For each of the pixels ``pixel`` (m,) (flat), the facet and abs(cos) of incidence of
    its sub-ray whose hit lies nearest ``range_m`` (m,) [m] (-1 and NaN if none hit); with the
    compiled ``kernel`` the nearest sub-ray is found per point on the frame's threads."""
    face = np.full(len(pixel), -1, dtype=np.int64)
    cos_theta = np.full(len(pixel), np.nan)
    for block in hits.blocks():
        if not len(block.pixel):
            continue
        if block.pixel[0] == 0 and block.pixel[-1] == len(block.pixel) - 1:
            row = pixel  # every pixel, in order (sorted and distinct): each pixel is its row
        else:
            row = np.minimum(np.searchsorted(block.pixel, pixel), len(block.pixel) - 1)
        mine = np.flatnonzero(block.pixel[row] == pixel)
        if not len(mine):
            continue
        if kernel is not None:
            threads = parallel.threads_for(len(mine), TRUTH_SERIAL_BELOW)
            k = kernel.nearest_column(block.range_m, row[mine], range_m[mine], threads)
        else:
            r = block.range_m[row[mine]]
            k = np.argmin(np.abs(np.where(np.isfinite(r), r, np.inf) - range_m[mine, None]), axis=1)
        take = (row[mine], k)
        face[mine] = block.face[take]
        cos_theta[mine] = block.cos_theta[take]
    return face, cos_theta


CLOUD = Stage(
    name="cloud",
    upstream=("rays", "hits", "echo", "receiver", "detection"),
    reads=lambda s: (s.quality.tau_m,),
    compute=stage_cloud,
)


def first_photon_cloud(result) -> PointCloud:
    """The single-pulse first-photon cloud of a result whose receiver records each pixel's first
    avalanche of the frame's first pulse (``Detection.first_photon_range_m`` and
    ``first_photon_is_echo``, the Geiger-mode array's): one point per pixel that fired, at that
    avalanche's range (``is_outlier`` where it was not the echo's), with the cloud's attributes
    and ground truth."""
    d, e, rx = result.detection, result.echo, result.receiver
    first_range_m = getattr(d, "first_photon_range_m", None)
    if first_range_m is None:
        raise ValueError(
            "first_photon_cloud needs a receiver that records each pixel's first photon "
            f"(receiver.kind = {result.scene.receiver.kind!r} does not)"
        )
    n = result.pixels**2
    fired = np.flatnonzero(np.isfinite(first_range_m))
    lit_of = np.full(n, -1, dtype=np.int64)
    lit_of[e.pixel] = np.arange(len(e.pixel))
    echo_pix = fired[d.first_photon_is_echo[fired]]
    noise_pix = fired[~d.first_photon_is_echo[fired]]
    li = lit_of[echo_pix]
    cloud = assemble_cloud(
        result.rays.pixel_directions,
        result.pixels,
        echo_pix,
        first_range_m[echo_pix],
        rx.peak_power_w[li],
        rx.snr[li],
        e.material_id[li],
        e.facet_id[li],
        noise_pix,
        first_range_m[noise_pix],
    )
    truth = ground_truth(
        e,
        result.hits,
        li,
        first_range_m[echo_pix],
        len(noise_pix),
        tau_m=result.scene.quality.tau_m,
    )
    cloud.attributes.update(truth)
    return cloud
