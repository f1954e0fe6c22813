"""Frames, poses, the pixel ray grid and first-hit ray casting (embreex, the hard requirement).

Sensor frame: origin at the lidar, z = boresight, x = image right (columns), y = image down (rows);
right-handed. Pixel (row i, col j) of an n x n array looks along the pinhole direction
``normalize((x/f_r, y/f_r, 1))`` of its centre.

The package, by concern: ``poses`` (rotations and the target's pose in the sensor frame),
``rays`` (the pixel grid of sub-rays and corners), ``casting`` (Embree first hits),
``refinement`` (mixed pixels found and cast again densely, the cells' range spread) and
``stages`` (the target, rays and hits stages). Every public name is importable from
``simcore.geometry`` as before.

The model: docs/physics.md#geometry (pose, pixel grid, first hits, refinement of mixed pixels).
"""

from __future__ import annotations

from .casting import (
    HitBlock,
    Hits,
    RayCaster,
    RayHits,
    cast_block,
    cast_ranges,
    cast_rays,
    incidence_cos,
)
from .poses import (
    PoseInSensor,
    front_view_rotation,
    quaternion_matrix,
    rotation_x,
    rotation_y,
    rotation_z,
    target_pose,
)
from .rays import (
    RayGrid,
    corner_directions,
    ray_grid,
    subray_directions,
    subray_tangents,
    unit_directions,
)
from .refinement import (
    COS_STEP,
    CornerSamples,
    cast,
    cell_spread_m,
    mixed_pixels,
    probe,
    straddles,
)
from .stages import (
    HITS,
    RAYS,
    TARGET,
    TargetStage,
    beam_edge,
    stage_hits,
    stage_rays,
    stage_target,
)

__all__ = [
    "COS_STEP",
    "HITS",
    "RAYS",
    "TARGET",
    "CornerSamples",
    "HitBlock",
    "Hits",
    "PoseInSensor",
    "RayCaster",
    "RayHits",
    "RayGrid",
    "TargetStage",
    "beam_edge",
    "cast",
    "cast_block",
    "cast_ranges",
    "cast_rays",
    "cell_spread_m",
    "corner_directions",
    "front_view_rotation",
    "incidence_cos",
    "mixed_pixels",
    "probe",
    "quaternion_matrix",
    "ray_grid",
    "rotation_x",
    "rotation_y",
    "rotation_z",
    "stage_hits",
    "stage_rays",
    "stage_target",
    "straddles",
    "subray_directions",
    "subray_tangents",
    "target_pose",
    "unit_directions",
]
