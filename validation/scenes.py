"""The scenes of the check, rendered by lmapd-sim's own chain (the hits and echo stages).

Each scene is a dict of scene keys; :func:`simcore_side` runs it and gives, per pixel of the
array, what the echo stage hands a receiver: the energy per joule of pulse energy, the
energy-weighted mean delay, the half-maximum time of the band-limited echo, and every element
(delay, weight) for the whole-target echo.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import trimesh

from simcore.geometry.poses import target_pose
from simcore.pipeline import Pipeline
from simcore.scene import Scene, with_overrides

DISTANCE_M = 500.0  # [m] lidar to target centre, every scene
PIXELS = 64  # [px] per side
PLATE_INCIDENCE_DEG = (0.0, 30.0, 60.0)
FOV_RAD = 0.03  # [rad] the array's default field of view
PLATE_HALF_WIDTH_PX = 17.5  # the plate's image spans +-17.5 pixels across (about 8.2 m at 500 m)
_PLATES = Path(tempfile.mkdtemp(prefix="lmapd-validation-"))


def pixel_tangent() -> float:
    """The tangent-plane size of one pixel, 2 tan(fov / 2) / n (simcore.geometry.rays)."""
    return 2.0 * np.tan(FOV_RAD / 2.0) / PIXELS


def plate_corners_m(incidence_deg: float) -> np.ndarray:
    """(4, 3) sensor-frame corners of the plate of one incidence: the plane through the target
    centre (0, 0, DISTANCE_M), tilted by ``incidence_deg`` about the image x axis, cut by the
    pyramid of an image rectangle whose edges lie on half-pixel lines (+-17.5 px across; down
    the image +-(17.5 cos(incidence)) rounded to the nearest half pixel). Each edge pixel is
    then half covered: a 2 x 2 or 8 x 8 sub-ray grid samples that half exactly, and each
    covered part lies a quarter of a pixel beyond the nearest sub-ray row, so the pixels both
    renderers light are the same by the geometry, not by chance. The plate is a trapezoid."""
    b = np.radians(incidence_deg)
    p = pixel_tangent()
    half_y = np.floor(PLATE_HALF_WIDTH_PX * np.cos(b)) + 0.5
    normal = np.array([0.0, -np.sin(b), np.cos(b)])  # Rx(b) applied to the boresight
    corners = []
    for tx, ty in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        ray = np.array([tx * PLATE_HALF_WIDTH_PX * p, ty * half_y * p, 1.0])
        corners.append(ray * (DISTANCE_M * normal[2]) / (ray @ normal))  # ray . n = d n_z
    return np.array(corners)


def plate_keys(incidence_deg: float) -> dict:
    """The plate as a mesh file in the sensor frame, posed where it was made (the identity
    rotation, its box centre as the offsets and distance)."""
    corners = plate_corners_m(incidence_deg)
    centre = (corners.min(axis=0) + corners.max(axis=0)) / 2.0
    path = _PLATES / f"plate_{incidence_deg:g}deg.ply"
    if not path.exists():  # centred: the file's float32 keeps 1e-6 m of it
        trimesh.Trimesh(corners - centre, [[0, 1, 2], [0, 2, 3]], process=False).export(path)
    return {
        "target.mesh": str(path),
        "target.materials": {"*": "lambertian"},
        "pose.quaternion_wxyz": (1.0, 0.0, 0.0, 0.0),
        "pose.offset_x_m": float(centre[0]),
        "pose.offset_y_m": float(centre[1]),
        "pose.distance_m": float(centre[2]),
        "detector.pixels": PIXELS,
    }


def mro_keys() -> dict:
    return {
        "target.mesh": "mro",
        "target.materials": {"*": "lambertian"},
        "pose.distance_m": DISTANCE_M,
        "detector.pixels": PIXELS,
    }


def scenes() -> dict[str, dict]:
    """Name -> scene keys of every scene of the check."""
    named = {f"plate_{a:g}deg": plate_keys(a) for a in PLATE_INCIDENCE_DEG}
    named["mro"] = mro_keys()
    return named


def simcore_side(keys: dict) -> dict:
    """The scene through lmapd-sim's chain: per-pixel figures (n x n arrays, NaN where dark),
    the elements of every lit pixel, and the posed mesh and optics Mitsuba needs."""
    scene = with_overrides(Scene(), keys)
    result = Pipeline().run(scene)
    echo = result.echo
    n = scene.detector.pixels
    energy = np.zeros(n * n)
    mean_delay = np.full(n * n, np.nan)
    t_half = np.full(n * n, np.nan)
    w = np.asarray(echo.weights)
    a = np.asarray(echo.arrivals_s)
    total = w.sum(axis=1)
    energy[echo.pixel] = total
    lit = total > 0
    mean_delay[echo.pixel[lit]] = (w * a).sum(axis=1)[lit] / total[lit]
    t_half[echo.pixel] = echo.features.t_half_s
    model = echo.model
    pose = target_pose(scene.pose, model.extents_m, model.body_from_mesh)
    vertices = model.vertices_m @ pose.rotation.T + pose.translation_m  # sensor frame
    return {
        "scene": scene,
        "energy_per_j": energy.reshape(n, n),
        "mean_delay_s": mean_delay.reshape(n, n),
        "t_half_s": t_half.reshape(n, n),
        "element_delay_s": a[w > 0],
        "element_weight": w[w > 0],
        "vertices_m": vertices,
        # the target's centre at Mitsuba's origin, the lidar where the sensor frame puts it
        "vertices_mitsuba_m": vertices - pose.translation_m,
        "lidar_mitsuba_m": -pose.translation_m,
        "beam_intensity": beam_intensity(scene),
        "radiance_scale": radiance_scale(scene),
        "faces": np.asarray(model.faces),
        "shape": echo.shape,
        "dt_s": echo.dt_s,
        "cfd_delay_s": echo.cfd_delay_s,
    }


def radiance_scale(scene: Scene) -> float:
    """Energy per joule of a pixel per unit of its mean radiance per transmitted watt and per
    steradian of beam [J/J / (W/(m^2 sr) / (W/sr))]: eta_r A_r theta_ifov^2, the receive side of
    Eq. 30 (the pixel's solid angle as the model takes it, theta_ifov^2)."""
    aperture = np.pi * scene.receive.aperture_diameter_m**2 / 4.0
    return scene.receive.transmittance * aperture * scene.ifov_rad**2


def beam_intensity(scene: Scene) -> float:
    """The flat-top beam's radiant intensity per transmitted joule, eta_t 4 / (pi theta_ill^2)
    [1/sr] (Eq. 5: E_in r^2 / P0)."""
    return scene.transmit.transmittance * 4.0 / (np.pi * scene.illumination_angle_rad**2)
