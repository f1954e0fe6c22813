"""Point cloud assembly: measured ranges along each pixel's line of sight, plus outliers.

The model: docs/physics.md#point-cloud.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .stage import Stage

if TYPE_CHECKING:
    from .echo import EchoStage
    from .geometry import RayGrid
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
    attrs = {
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
    scene: Scene, rays: RayGrid, echo: EchoStage, response: Response, det: Detection
) -> PointCloud:
    """The cloud stage: detected target pixels at their measured ranges, then the outliers;
    the shared attributes (ATTRIBUTES) and the receiver's own (``Detection.point_attributes``)."""
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
    for name, (lit_values, outlier_values) in det.point_attributes.items():
        cloud.attributes[name] = np.concatenate([np.asarray(lit_values)[k], outlier_values])
    return cloud


CLOUD = Stage(
    name="cloud",
    upstream=("rays", "echo", "receiver", "detection"),
    reads=lambda s: (),
    compute=stage_cloud,
)
