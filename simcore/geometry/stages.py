"""The geometry's stages: the target (mesh and caster), the rays and the first hits."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..constants import C
from ..illumination import illumination_gain
from ..pulse import scene_pulse_shape
from ..scene import Scene, SceneError
from ..stage import Stage, readonly
from ..target import TargetModel, load_target, source_stamp
from .casting import Hits, RayCaster
from .poses import target_pose
from .rays import RayGrid, corner_directions, ray_grid
from .refinement import cast, straddles


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
        steep_m = 0.5 * scene_pulse_shape(scene).rise_time_10_90_s * C / 2
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
    check_standoff(tgt.model, pose, hits.base)
    return hits


# the nearest surface the echo model holds for [m]: the far-field range equation's 1 / R^2 grows
# without bound at the surface (a joule-class pulse at a few millimetres overflowed the waveform);
# distance_m's own lower end
MIN_STANDOFF_M = 0.3


def check_standoff(model, pose, block) -> None:
    """Refuse (SceneError naming distance_m) a pose that puts the lidar closer than
    MIN_STANDOFF_M to the surface it sees, or inside a closed target: most of its first hits
    on the inner side of their faces (what a closed surface shows from within)."""
    ranges = block.range_m[np.isfinite(block.range_m)]
    if not len(ranges):
        return
    nearest = float(ranges.min())
    if nearest < MIN_STANDOFF_M:
        raise SceneError(
            f"distance_m: the lidar is {nearest:.3g} m from the target's surface, closer than the "
            f"{MIN_STANDOFF_M:g} m the echo model holds for: move it back (distance_m is to the "
            "target's centre)"
        )
    surface = model.surface
    at_t = -pose.rotation.T @ pose.translation_m  # the lidar in the target frame
    # inside a target is inside its bounding sphere: only there is the surface's closure asked
    # for (half a second for the MRO's 124,062 triangles)
    if np.linalg.norm(at_t) < surface.radius_m and surface.closed:
        faces = block.face[block.face >= 0]
        corner = surface.vertices_m[surface.faces[faces, 0]]
        inner = np.einsum("ij,ij->i", surface.face_normals[faces], corner - at_t) > 0.0
        if inner.mean() > 0.5:
            raise SceneError(
                f"distance_m: the lidar at {pose.translation_m[2]:.3g} m from the target's centre "
                f"is inside the target ({model.name}, {surface.radius_m:.3g} m to its farthest "
                "corner): move it back"
            )


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
