"""Imaging-quality metrics: how good a point cloud is against the target it came from.

The figures follow the multi-view-stereo benchmarks (Tanks and Temples, ETH3D): at a distance
tolerance tau (``quality.tau_m``)

- precision: the share of the cloud's target points within tau of the true mesh (exact
  point-to-mesh distance, libigl's AABB tree of the mesh, built once per mesh:
  :mod:`simcore.mesh_distance`);
- recall (completeness): the share of the *visible* true surface within tau of a point; the
  whole mesh is sampled uniformly by area, and a sample counts only if it lies inside the
  array's field of view and nothing hides it from the lidar (a ray cast to it, Embree): the
  samples that count are spread by area over the surface the lidar sees, grazing parts included
  (the facets hit by the pixels' rays would miss most of a sphere's rim);
- F-score: their harmonic mean;
- the recall's sampling error ``recall_sd`` (a binomial proportion of the seen samples);
- ``recall_projected``: the recall with each seen sample weighted by |cos| of its incidence, the
  share of the seen surface's *projected* area (what the pixels can sample) within tau of a point:
  a face seen edge-on weighs nothing, so the figure does not jump when one turns into view at a
  grazing angle (the plain recall counts its whole area at once), and ``seen_projected_area_m2``;
- ``recall_cap`` and ``recall_projected_cap``: the same figures for an ideal lidar with the same
  pixels, one exact point per pixel that sees the target (its centre ray's first hit): the most
  any lidar with this pixel footprint can reach, so that a requirement above it is known to be
  unreachable whatever the energy;

and along the lines of sight: the RMS range error against the first hit of each point's own line
of sight; from each point's ground truth (``simcore.pointcloud.ground_truth``, its surface group's
energy-weighted range) the median signed range error (bias), its RMS, the 95th percentile of its
magnitude; each point's distance to the mesh (median, 95th percentile); the share of target
points more than tau from their truth among the target points and of false alarms among all
points; and the target points per square metre of seen surface.
Per part: points, precision, recall and bias.

This is a stage of its own (:data:`QUALITY`), computed only when a summary, a sweep column or the
app asks for it. The model: docs/physics.md#imaging-quality.
"""

from __future__ import annotations

import math
import threading
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from .geometry import RayCaster
from .mesh_distance import closest_points
from .stage import Stage

if TYPE_CHECKING:
    from .geometry import Hits, PoseInSensor, RayGrid, TargetStage
    from .pointcloud import PointCloud
    from .scene import Scene
    from .target import TargetModel
    from .target_mesh import TargetMesh

SURFACE_SAMPLES = 50_000  # area samples of the mesh for recall (those seen count)
SEEN_SLACK_M = 1e-3  # a sample whose ray hits within this of it is seen (float32 ray distances)


@dataclass(frozen=True, kw_only=True)
class SurfaceSamples:
    """Points spread uniformly by area over some facets, and which of them the lidar sees.

    points_t : (n, 3) float64 positions, target frame [m]
    face : (n,) int64 facet of each sample
    seen : (n,) bool inside the field of view and not hidden from the lidar
    area_m2 : total area of the sampled facets [m^2]
    cos_incidence : (n,) float64 or None |cos| of the angle between each sample's facet normal
        and its line of sight (1 face-on, 0 edge-on); None where not computed
    """

    points_t: np.ndarray
    face: np.ndarray
    seen: np.ndarray
    area_m2: float
    cos_incidence: np.ndarray | None = None

    @property
    def seen_area_m2(self) -> float:
        """The seen share of the sampled area [m^2]."""
        return self.area_m2 * float(np.mean(self.seen)) if len(self.seen) else 0.0

    @property
    def seen_projected_area_m2(self) -> float:
        """The seen area projected across the lines of sight, each sample weighted by its
        |cos incidence| [m^2]: a convex target's silhouette area (a sphere's pi R^2)."""
        if self.cos_incidence is None or not len(self.seen):
            return 0.0
        return self.area_m2 * float(np.sum(self.cos_incidence[self.seen])) / len(self.seen)


def facet_areas_m2(vertices_m, faces) -> np.ndarray:
    """(n_faces,) area of each triangle [m^2] (0 for a degenerate one)."""
    v = np.asarray(vertices_m, dtype=np.float64)[np.asarray(faces)]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def sample_facets(vertices_m, faces, face_ids, n: int, rng: np.random.Generator):
    """``n`` points uniform by area over the facets ``face_ids``: (n, 3) positions [m], (n,)
    facet of each, and the facets' total area [m^2]. None of them if the facets have no area."""
    face_ids = np.asarray(face_ids, dtype=np.int64)
    tri = np.asarray(vertices_m, dtype=np.float64)[np.asarray(faces)[face_ids]]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = float(area.sum())
    if not len(face_ids) or not total > 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), 0.0
    pick = rng.choice(len(face_ids), size=n, p=area / total)
    u, v = rng.random(n), rng.random(n)
    s = np.sqrt(u)  # uniform over a triangle: (1 - sqrt u, sqrt u (1 - v), sqrt u v)
    t = tri[pick]
    points = (1.0 - s)[:, None] * t[:, 0] + (s * (1.0 - v))[:, None] * t[:, 1]
    points += (s * v)[:, None] * t[:, 2]
    return points, face_ids[pick], total


# the whole mesh's area samples of recent seeds, per mesh: they do not depend on the pose, so a
# series of frames of one target (an atlas, a slider drag) draws them once (read-only arrays)
_SAMPLES: weakref.WeakKeyDictionary[TargetMesh, dict[tuple[int, int], tuple]] = (
    weakref.WeakKeyDictionary()
)
_SAMPLES_KEPT = 4  # [-] seeds kept per mesh (about 1.6 MB each at 50,000 samples)
_SAMPLES_LOCK = threading.Lock()


def mesh_samples(model: TargetModel, seed: int, n: int = SURFACE_SAMPLES):
    """The recall's ``n`` samples of the whole mesh for ``seed``: (n, 3) positions [m], (n,) facet
    of each and the mesh's area [m^2], as :func:`sample_facets` draws them from the generator
    ``default_rng([seed, 7411])``; drawn once per mesh and seed, then shared (read-only)."""
    surface = model.surface
    key = (int(seed), int(n))
    with _SAMPLES_LOCK:
        kept = _SAMPLES.setdefault(surface, {})
        hit = kept.get(key)
    if hit is not None:
        return hit
    rng = np.random.default_rng([seed, 7411])
    every_face = np.arange(len(model.faces))
    points_t, face, area = sample_facets(model.vertices_m, model.faces, every_face, n, rng)
    points_t.setflags(write=False)
    face.setflags(write=False)
    drawn = (points_t, face, area)
    with _SAMPLES_LOCK:
        while len(kept) >= _SAMPLES_KEPT:
            kept.pop(next(iter(kept)))
        kept[key] = drawn
    return drawn


def seen_surface(
    caster: RayCaster,
    pose: PoseInSensor,
    fov_rad: float,
    face_ids,
    n: int,
    rng: np.random.Generator,
) -> SurfaceSamples:
    """Samples of the facets ``face_ids`` and which the lidar sees: inside the square field of
    view ``fov_rad`` and first along the ray from the lidar (within SEEN_SLACK_M)."""
    model = caster.model
    points_t, face, area = sample_facets(model.vertices_m, model.faces, face_ids, n, rng)
    return seen_samples(caster, pose, fov_rad, points_t, face, area)


def seen_samples(
    caster: RayCaster, pose: PoseInSensor, fov_rad: float, points_t, face, area_m2: float
) -> SurfaceSamples:
    """Which of the surface samples ``points_t`` (n, 3) [m] (on facets ``face``, of total area
    ``area_m2``) the lidar sees: inside the square field of view ``fov_rad`` and first along the
    ray from the lidar (within SEEN_SLACK_M)."""
    model = caster.model
    area = area_m2
    if not len(points_t):
        return SurfaceSamples(points_t=points_t, face=face, seen=np.zeros(0, bool), area_m2=0.0)
    origin_t = -pose.rotation.T @ pose.translation_m
    offset = points_t - origin_t
    dist_m = np.linalg.norm(offset, axis=1)
    dirs_t = offset / dist_m[:, None]
    dirs_s = dirs_t @ pose.rotation.T  # R d for each row: the sensor frame
    half = np.tan(fov_rad / 2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        in_view = (dirs_s[:, 2] > 0) & (np.abs(dirs_s[:, 0]) <= half * dirs_s[:, 2])
        in_view &= np.abs(dirs_s[:, 1]) <= half * dirs_s[:, 2]
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * model.radius_m)
    seen = np.zeros(len(points_t), dtype=bool)
    look = np.flatnonzero(in_view)
    if len(look):
        hit_m, _ = caster.first_hits(origin_t, dirs_t[look], start)
        seen[look] = hit_m >= dist_m[look] - SEEN_SLACK_M
    normals = np.asarray(model.face_normals)[face]
    cos_incidence = np.abs(np.einsum("ij,ij->i", normals, dirs_t))
    return SurfaceSamples(
        points_t=points_t, face=face, seen=seen, area_m2=area, cos_incidence=cos_incidence
    )


def ideal_points_t(caster: RayCaster, pose: PoseInSensor, pixel_directions) -> np.ndarray:
    """(m, 3) the cloud of an ideal lidar with the array's pixels, target frame [m]: one exact
    point per pixel that sees the target, where its centre ray (``pixel_directions`` (n, 3),
    sensor frame) first hits it; no noise, no missed pixel, every pixel lit."""
    origin_t = -pose.rotation.T @ pose.translation_m
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * caster.model.radius_m)
    hits = caster.cast(origin_t, np.asarray(pixel_directions), start, rotation=pose.rotation)
    hit = np.isfinite(hits.range_m)
    return origin_t + hits.range_m[hit, None] * hits.directions_t[hit]


def recall_figures(
    points_t, surface: SurfaceSamples, tau_m: float
) -> tuple[np.ndarray, float, float]:
    """Which seen samples lie within ``tau_m`` of a point of ``points_t`` (m, 3) [m], and the
    recall by area and by projected area: (n,) bool recalled, recall, projected recall."""
    recalled = np.zeros(len(surface.face), dtype=bool)
    if len(points_t) and surface.seen.any():
        d_m, _ = cKDTree(points_t).query(surface.points_t[surface.seen], k=1)
        recalled[surface.seen] = d_m <= tau_m
    recall = _ratio(recalled.sum(), surface.seen.sum())
    w = surface.cos_incidence if surface.cos_incidence is not None else surface.seen * 1.0
    projected = _ratio(float(np.sum(w[recalled])), float(np.sum(w[surface.seen])))
    return recalled, recall, projected


def to_target_frame(points_s, pose: PoseInSensor) -> np.ndarray:
    """Sensor-frame points (n, 3) in the target frame: R^T (p - t)."""
    return (np.asarray(points_s, dtype=np.float64) - pose.translation_m) @ pose.rotation


def _ratio(num: float, den: float) -> float:
    return float(num / den) if den > 0 else 0.0


def _errors(error_m: np.ndarray) -> dict[str, float | None]:
    """Bias (median), RMS and 95th percentile of |error| of some range errors [m]; None if none."""
    e = error_m[np.isfinite(error_m)]
    if not len(e):
        return {"range_bias_m": None, "range_rmse_m": None, "range_error_p95_m": None}
    return {
        "range_bias_m": float(np.median(e)),
        "range_rmse_m": float(np.sqrt(np.mean(e * e))),
        "range_error_p95_m": float(np.percentile(np.abs(e), 95.0)),
    }


def line_of_sight_errors_m(
    caster: RayCaster, pose: PoseInSensor, points_t, mesh_m=None
) -> np.ndarray:
    """(n,) each point's range error along its own line of sight [m]: its distance from the
    lidar less that of the first hit of the ray from the lidar through it (Embree), signed (a
    point in front of the surface is negative). Where that ray misses the mesh (a point beside
    a silhouette) the point's exact distance to the mesh, unsigned.

    Unlike ``range_error_m`` (measured against the energy-weighted truth of the point's own
    surface group), a mixed pixel's point floating between two depths counts with its distance
    from the surface its line of sight meets. ``mesh_m``: the points' distances to the mesh, if
    known (:func:`simcore.mesh_distance.point_to_mesh_m`)."""
    points_t = np.asarray(points_t, dtype=np.float64)
    if not len(points_t):
        return np.zeros(0)
    model = caster.model
    origin_t = -pose.rotation.T @ pose.translation_m
    offset = points_t - origin_t
    range_m = np.linalg.norm(offset, axis=1)
    dirs_t = offset / np.where(range_m > 0, range_m, 1.0)[:, None]
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * model.radius_m)
    hit_m, _ = caster.first_hits(origin_t, dirs_t, start)
    hit_m = np.asarray(hit_m, dtype=np.float64)
    error_m = range_m - hit_m
    miss = ~np.isfinite(hit_m)
    if miss.any():
        error_m[miss] = (
            closest_points(model.surface).distance_m(points_t[miss])
            if mesh_m is None
            else np.asarray(mesh_m)[miss]
        )
    return error_m


def _distances(d_m: np.ndarray) -> dict[str, float | None]:
    """Median and 95th percentile of the points' exact distances to the whole mesh ``d_m``
    [m]."""
    if not len(d_m):
        return {"distance_to_mesh_median_m": None, "distance_to_mesh_p95_m": None}
    return {
        "distance_to_mesh_median_m": float(np.median(d_m)),
        "distance_to_mesh_p95_m": float(np.percentile(d_m, 95.0)),
    }


def _outliers(attrs, target) -> dict[str, float]:
    """The two outlier shares, each over the points it counts: the target points more than
    tau from their truth over the target points, the false alarms over all points [1]."""
    far = np.asarray(attrs["outlier"], dtype=bool) & target
    return {
        "target_outlier_fraction": _ratio(
            float(np.count_nonzero(far)), float(np.count_nonzero(target))
        ),
        "false_alarm_fraction": _ratio(float(np.count_nonzero(~target)), len(target)),
    }


def quality_metrics(
    cloud: PointCloud,
    caster: RayCaster,
    hits: Hits,
    fov_rad: float,
    tau_m: float,
    seed: int,
    n_samples: int = SURFACE_SAMPLES,
    pixel_directions=None,
) -> dict[str, Any]:
    """The ``quality.*`` figures of one frame (see the module's docstring), plain JSON values.

    cloud : the frame's points (sensor frame) with their ground truth
    caster : the target's ray caster (its model is the true mesh)
    hits : the frame's first hits (the seen facets and the pose)
    pixel_directions : (n_pixels, 3) the pixels' centre directions, sensor frame (the rays
        stage's): with them, the recall caps of an ideal lidar with these pixels
    """
    model = caster.model
    attrs = cloud.attributes
    target = ~np.asarray(attrs["is_outlier"], dtype=bool)
    points_t = to_target_frame(cloud.points[target], hits.pose)
    # each target point's exact distance to the whole mesh, once a frame (the mesh's tree is
    # built once per mesh): the precision's test, the distance figures and the line-of-sight
    # error where a ray misses
    mesh_m = closest_points(model.surface).distance_m(points_t)
    near = mesh_m <= tau_m
    points_s, face_s, area_m2 = mesh_samples(model, seed, n_samples)
    surface = seen_samples(caster, hits.pose, fov_rad, points_s, face_s, area_m2)
    recalled, recall, recall_projected = recall_figures(points_t, surface, tau_m)
    precision = _ratio(near.sum(), len(near))
    f_score = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    error_m = np.asarray(attrs["range_error_m"])[target]
    seen_m2 = surface.seen_area_m2
    n_seen = int(surface.seen.sum())
    figures: dict[str, Any] = {
        "tau_m": float(tau_m),
        "precision": precision,
        "recall": recall,
        "f_score": float(f_score),
        **_errors(error_m),
        "range_rmse_surface_m": _errors(error_m)["range_rmse_m"],
        "range_rmse_m": _errors(line_of_sight_errors_m(caster, hits.pose, points_t, mesh_m))[
            "range_rmse_m"
        ],
        **_distances(mesh_m),
        **_outliers(attrs, target),
        "point_density_per_m2": _ratio(len(points_t), seen_m2),
        "seen_area_m2": seen_m2,
        "n_surface_samples": n_seen,
        # the recall's sampling error: a binomial proportion of the seen samples
        "recall_sd": math.sqrt(recall * (1.0 - recall) / n_seen) if n_seen else 0.0,
        "recall_projected": recall_projected,
        "seen_projected_area_m2": surface.seen_projected_area_m2,
    }
    if pixel_directions is not None:
        ideal = ideal_points_t(caster, hits.pose, pixel_directions)
        _, cap, cap_projected = recall_figures(ideal, surface, tau_m)
        figures["recall_cap"] = cap
        figures["recall_projected_cap"] = cap_projected
    figures["parts"] = _per_part(model, attrs, target, near, surface, recalled, error_m)
    return figures


def _per_part(model, attrs, target, near, surface, recalled, error_m) -> list[dict[str, Any]]:
    """Per part that is seen or gives points: name, points, precision, recall, bias."""
    part_of_point = np.asarray(attrs["part_id"])[target]
    face_part = np.asarray(model.face_part)
    sample_part = face_part[surface.face] if len(surface.face) else np.zeros(0, np.int64)
    rows = []
    for p, name in enumerate(model.part_names):
        mine = part_of_point == p
        seen = surface.seen & (sample_part == p)
        if not mine.any() and not seen.any():
            continue
        rows.append(
            {
                "name": name,
                "n_points": int(mine.sum()),
                "precision": _ratio(near[mine].sum(), mine.sum()),
                "recall": _ratio(recalled[seen].sum(), seen.sum()),
                "range_bias_m": _errors(error_m[mine])["range_bias_m"],
            }
        )
    return rows


def stage_quality(
    scene: Scene, tgt: TargetStage, rays: RayGrid, hits: Hits, cloud: PointCloud
) -> dict:
    """The quality stage: :func:`quality_metrics` of the frame at ``quality.tau_m``."""
    return quality_metrics(
        cloud,
        tgt.caster,
        hits,
        scene.receive.fov_rad,
        scene.quality.tau_m,
        scene.seed,
        pixel_directions=rays.pixel_directions,
    )


QUALITY = Stage(
    name="quality",
    upstream=("target", "rays", "hits", "cloud"),
    reads=lambda s: (s.quality.tau_m, s.seed, s.receive.fov_rad),
    compute=stage_quality,
)
