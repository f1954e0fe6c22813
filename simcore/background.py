"""The background stage: sunlight from the target and from the Earth behind it, per pixel.

The paper keeps the Sun out of view and drops background light (PHYSICS.md section 7). Here a
sunlit target, and the sunlit Earth behind it, send light into every pixel through the
receiver's band-pass filter:

- the in-band solar irradiance at the target, ``E = E_lambda dlambda eta_filter (1 AU / r)^2``
  (ASTM E-490 AM0 integrated over the filter, ``simcore.sun``); 0 in the Earth's shadow;
- each sub-ray that hits the target: a shadow ray toward the Sun through the same Embree scene
  (the target shadows itself: panels, dish, bus); if it is free and the facet faces the Sun,
  the facet sends the radiance ``L = E cos(theta_i) f`` toward the lidar, ``f`` the bistatic
  extension of Eq. 6 (``materials.brdf_bistatic``);
- each sub-ray that misses the target and meets the Earth: the Earth is a Lambertian of albedo
  a, ``L = a E max(cos(solar zenith), 0) / pi`` (night side dark); deep space 0;
- a pixel collects ``P_bg = eta_r A_r sum_k L_k Omega_k``, ``Omega_k = theta_ifov^2 / K`` the
  solid angle of each of its K sub-rays (the sub-ray sampling of Eq. 30; refined pixels' 64
  sub-rays thinned to 16, :func:`thinned`).

Only the Sun's keys, the filter and the optics re-run this stage: the ray cast from the lidar
(the hits stage) is its input, never re-cast. The model: docs/physics.md#background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import geometry, materials, parallel
from .scene import Scene
from .stage import Stage, readonly
from .target import with_materials

SHADOW_OFFSET = 1e-4  # [-] shadow rays start this fraction of the target's radius off the facet
THIN_FROM = 64  # [-] blocks of this many sub-rays per pixel or more are thinned to a quarter
CHUNK_PIXELS = 4096  # [-] pixels a thread takes at a time (fixed: results never depend on threads)


def _pieces(block: geometry.HitBlock, size: int | None = None) -> list[geometry.HitBlock]:
    """The block's pixels in pieces of ``size`` (CHUNK_PIXELS) consecutive rows."""
    size = CHUNK_PIXELS if size is None else size
    if len(block.pixel) <= size:
        return [block]
    return [
        geometry.HitBlock(
            pixel=block.pixel[i : i + size],
            directions=block.directions[i : i + size],
            range_m=block.range_m[i : i + size],
            cos_theta=block.cos_theta[i : i + size],
            face=block.face[i : i + size],
            depth_m=block.depth_m[i : i + size],
        )
        for i in range(0, len(block.pixel), size)
    ]


def thinned(block: geometry.HitBlock) -> geometry.HitBlock:
    """The block's sub-rays thinned to a quarter where it has THIN_FROM or more per pixel (the
    refined 8 x 8 of the presets): on the k x k grid those with (row - col) divisible by 4, a
    diagonal lattice that keeps two per grid row and column and is symmetric about the pixel's
    centre (so it samples the pixel without a shift). The background is smooth in a pixel;
    the echo's timing is what needs all 64."""
    k = math.isqrt(block.subrays)
    if block.subrays < THIN_FROM or k * k != block.subrays or k % 4:
        return block
    i, j = np.divmod(np.arange(block.subrays), k)
    keep = np.flatnonzero((i - j) % 4 == 0)
    return geometry.HitBlock(
        pixel=block.pixel,
        directions=block.directions[:, keep],
        range_m=block.range_m[:, keep],
        cos_theta=block.cos_theta[:, keep],
        face=block.face[:, keep],
        depth_m=block.depth_m[:, keep],
    )


@dataclass(frozen=True, kw_only=True)
class Background:
    """The optical background of one flash, per pixel (the background stage's output).

    power_w : (rows, cols) float64 -- background power each pixel collects, at the detector
        after the optics and the filter's transmittance [W]; all zeros for ``sun.mode = none``
    sunlit : (rows, cols) bool -- the pixel sees a sunlit part of the target
    earth : (rows, cols) bool -- the pixel's line of sight meets the Earth's sunlit disc
    sun_direction_target : (3,) unit vector toward the Sun in the target body frame, or None
    eclipsed : the target is in the Earth's shadow
    target_power_w, earth_power_w : (rows, cols) float64 -- the parts of ``power_w`` from the
        target and from the Earth [W]
    sun_direction_sensor : (3,) the Sun's direction in the sensor frame, or None
    sun_angle_deg : angle at the target between the Sun and the lidar [deg] (0: the Sun behind
        the lidar), NaN without a Sun
    irradiance_w_m2 : in-band solar irradiance at the target through the filter
        (E_lambda dlambda eta_filter (1 AU / r)^2) [W/m^2], 0 without a Sun
    """

    power_w: np.ndarray
    sunlit: np.ndarray
    earth: np.ndarray
    sun_direction_target: np.ndarray | None
    eclipsed: bool
    target_power_w: np.ndarray
    earth_power_w: np.ndarray
    sun_direction_sensor: np.ndarray | None = None
    sun_angle_deg: float = float("nan")
    irradiance_w_m2: float = 0.0
    figures: dict[str, float] = field(default_factory=dict)

    @property
    def any_light(self) -> bool:
        """Some pixel collects background light."""
        return bool(np.any(self.power_w > 0))


def dark(pixels: int) -> Background:
    """No Sun (the paper's case): every pixel dark."""
    zeros = np.zeros((pixels, pixels))
    none = np.zeros((pixels, pixels), dtype=bool)
    readonly(zeros, none)
    return Background(
        power_w=zeros,
        sunlit=none,
        earth=none,
        sun_direction_target=None,
        eclipsed=False,
        target_power_w=zeros,
        earth_power_w=zeros,
    )


def earth_radiance_w_m2_sr(directions_s, center_s_m, radius_m, sun_s, albedo, irradiance_w_m2):
    """Radiance toward the lidar of the Earth where rays from the lidar meet it [W m^-2 sr^-1]:
    a Lambertian ``albedo E max(cos(solar zenith), 0) / pi``, 0 where the ray misses the
    Earth (deep space) or meets its night side. The ray from the origin along d meets the sphere
    at t = d.C - sqrt((d.C)^2 - |C|^2 + R^2) (the near side; grazing rays at the limb have a
    root of 0 and the solar zenith of the limb).

    directions_s : (n, 3) unit ray directions; center_s_m : (3,) the Earth's centre [m];
    radius_m : its radius [m]; sun_s : (3,) unit vector toward the Sun (same frame).
    Returns radiance (n,) and the mask (n,) of rays that meet the Earth.
    """
    d = np.asarray(directions_s, dtype=np.float64)
    c = np.asarray(center_s_m, dtype=np.float64)
    b = d @ c
    disc = b * b - (c @ c - radius_m * radius_m)
    meets = (disc >= 0.0) & (b > 0.0)
    t = np.where(meets, b - np.sqrt(np.maximum(disc, 0.0)), 0.0)
    normal = (t[:, None] * d - c) / radius_m
    cos_sun = normal @ np.asarray(sun_s, dtype=np.float64)
    radiance = np.where(meets, albedo * irradiance_w_m2 * np.maximum(cos_sun, 0.0) / np.pi, 0.0)
    return radiance, meets


def target_radiance_w_m2_sr(caster, model, block: geometry.HitBlock, pose, sun_t, irradiance):
    """Radiance toward the lidar of each sub-ray's first hit (n, K) [W m^-2 sr^-1] and the mask
    of sunlit hits (n, K): ``E cos(theta_i) f(theta_i, theta_r, theta_h)`` where the facet faces
    the Sun and its shadow ray toward the Sun (from the hit, ``SHADOW_OFFSET`` target radii off
    the facet) meets nothing; 0 elsewhere. ``sun_t`` is the unit Sun direction in the target
    (mesh) frame."""
    hit = block.face >= 0
    radiance = np.zeros(block.face.shape)
    lit = np.zeros(block.face.shape, dtype=bool)
    if not hit.any():
        return radiance, lit
    rot = pose.rotation
    dirs_s = block.directions[hit]
    # R^T d for each row, written out: a (n, 3) @ (3, 3) product through matmul is slow
    dirs_t = dirs_s[:, :1] * rot[0] + dirs_s[:, 1:2] * rot[1] + dirs_s[:, 2:] * rot[2]
    normals = caster.facet_normals(block.face[hit])
    toward_lidar = -np.einsum("ij,ij->i", normals, dirs_t)
    side = np.where(toward_lidar < 0, -1.0, 1.0)  # the side the lidar sees
    cos_i = side * (normals @ sun_t)
    facing = np.flatnonzero((cos_i > 0.0) & (toward_lidar != 0.0))
    if not len(facing):
        return radiance, lit
    # only the facets that face the Sun: shadow rays, the BRDF
    normals = normals[facing] * side[facing, None]
    dirs_t, cos_i = dirs_t[facing], cos_i[facing]
    cos_r = np.abs(toward_lidar[facing])
    origin_t = -rot.T @ pose.translation_m  # the lidar, in the target frame
    points_t = origin_t + block.range_m[hit][facing, None] * dirs_t
    offset = SHADOW_OFFSET * model.radius_m
    free = ~caster.occluded(points_t + offset * normals, sun_t)
    half = sun_t[None, :] - dirs_t
    half /= np.maximum(np.linalg.norm(half, axis=1), 1e-300)[:, None]
    cos_h = np.einsum("ij,ij->i", normals, half)
    params = materials.parameter_table(materials.MATERIAL_NAMES)
    a, b, m, s = params[model.face_material_library[block.face[hit][facing]]].T
    f = materials.brdf_bistatic(cos_i, cos_r, cos_h, a, b, m, s)
    values = np.zeros(len(side))
    values[facing] = np.where(free, irradiance * cos_i * f, 0.0)
    radiance[hit] = values
    lit[hit] = values > 0.0
    return radiance, lit


def stage_background(scene: Scene, tgt: geometry.TargetStage, hits: geometry.Hits) -> Background:
    """Background power per pixel for this frame's Sun (zeros for ``sun.mode = none``)."""
    n = scene.detector.pixels
    if scene.sun.mode == "none":
        return dark(n)
    from . import sun  # noqa: PLC0415  (the ephemeris and orbits: only with a Sun)

    geo = sun.sun_geometry(scene)
    assert geo is not None  # None only for sun.mode = none, returned above
    rx = scene.receive
    irradiance = (
        sun.in_band_irradiance_w_m2(scene.laser.wavelength_m, rx.filter_width_m)
        * rx.filter_transmittance
        * (sun.AU_M / geo.distance_m) ** 2
    )
    model = with_materials(tgt.model, scene.target.materials)
    pose = hits.pose
    body_from_mesh = model.body_from_mesh
    sun_t = body_from_mesh.T @ geo.direction_body  # the mesh frame the caster works in
    sun_s = pose.rotation @ sun_t
    earth_s = pose.translation_m + pose.rotation @ (body_from_mesh.T @ geo.earth_center_body_m)
    lidar_body = body_from_mesh @ (-pose.rotation.T @ pose.translation_m)
    cos_angle = float(geo.direction_body @ lidar_body / np.linalg.norm(lidar_body))
    etendue = rx.transmittance * np.pi * rx.aperture_diameter_m**2 / 4.0 * scene.ifov_rad**2

    target_w = np.zeros(n * n)
    earth_w = np.zeros(n * n)
    sunlit = np.zeros(n * n, dtype=bool)
    earth = np.zeros(n * n, dtype=bool)

    def light(block: geometry.HitBlock) -> None:
        """The block's pixels' target and Earth light, into the frame's arrays (each block's
        pixels its own)."""
        per_ray = etendue / block.subrays  # eta_r A_r Omega_k
        if not geo.eclipsed:
            radiance, lit = target_radiance_w_m2_sr(
                tgt.caster, model, block, pose, sun_t, irradiance
            )
            target_w[block.pixel] = radiance.sum(axis=1) * per_ray
            sunlit[block.pixel] = lit.any(axis=1)
        if scene.background.earth and scene.background.earth_albedo > 0:
            miss = block.face < 0
            radiance = np.zeros(block.face.shape)
            seen = np.zeros(block.face.shape, dtype=bool)
            radiance[miss], meets = earth_radiance_w_m2_sr(
                block.directions[miss],
                earth_s,
                sun.R_EARTH_M,
                sun_s,
                scene.background.earth_albedo,
                irradiance,
            )
            seen[miss] = meets & (radiance[miss] > 0)
            earth_w[block.pixel] = radiance.sum(axis=1) * per_ray
            earth[block.pixel] = seen.any(axis=1)

    # pieces of CHUNK_PIXELS pixels whatever the threads (the same sums), on the frame's threads
    pieces = [piece for block in map(thinned, hits.blocks()) for piece in _pieces(block)]
    parallel.map_threads(light, pieces)
    shape = (n, n)
    out = Background(
        power_w=(target_w + earth_w).reshape(shape),
        sunlit=sunlit.reshape(shape),
        earth=earth.reshape(shape),
        sun_direction_target=np.asarray(geo.direction_body, dtype=np.float64),
        eclipsed=geo.eclipsed,
        target_power_w=target_w.reshape(shape),
        earth_power_w=earth_w.reshape(shape),
        sun_direction_sensor=sun_s,
        sun_angle_deg=float(np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0)))),
        irradiance_w_m2=0.0 if geo.eclipsed else float(irradiance),
        figures={"sun_distance_m": geo.distance_m},
    )
    readonly(
        out.power_w,
        out.sunlit,
        out.earth,
        out.sun_direction_target,
        out.target_power_w,
        out.earth_power_w,
        out.sun_direction_sensor,
    )
    return out


def _reads(s: Scene) -> tuple:
    """The Sun, the orbit (orbit mode), the Earth, the filter and optics, the wavelength and
    materials; the pose and the pixels come through the hits."""
    if s.sun.mode == "none":
        return ("none", s.detector.pixels)
    return (
        s.sun,
        s.orbit if s.sun.mode == "orbit" else None,
        s.background,
        s.laser.wavelength_m,
        s.receive,
        s.target.materials,
        s.detector.pixels,
    )


BACKGROUND = Stage(
    name="background", upstream=("target", "hits"), reads=_reads, compute=stage_background
)
