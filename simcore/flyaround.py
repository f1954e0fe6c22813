"""The fly-around: image the target every ``interval_s`` over one orbit (PHYSICS.md section 3).

The two orbits of Table 3 give, at each imaging time, the lidar-target distance and the pose of the
target body in the lidar sensor frame (``orbit.relative_pose_series``); each pose is one flash of
the imaging chain, run through ONE ``Pipeline`` so the mesh and its BVH load once::

    fly = run_flyaround(scene, orbit.flyaround_times(300.0), out_dir="frames")

writes ``frames/frame_000_t00000s.ply`` ... (one point cloud per frame, sensor frame) and returns
the per-frame records. The ``lmapd flyaround`` command (``simcore.cli.flyaround``) adds the JSON
record and the plot of the paper's Figure 7.

The scene's ``[trajectory]`` section chooses the relative motion (``simcore.trajectory``): the
orbits (the default, below), an approach along the line of sight or a hold at one range, each with
an optional tumble of the target. Every frame's ground truth (``FlyaroundResult.truth``: the
target's pose in the sensor frame and the lidar's in the target frame, the Sun's direction) goes
into its record, and ``FlyaroundResult.track`` registers the clouds to the model
(``simcore.tracking``) when the frames were kept (``keep_clouds=True``).

The orbits are Table 3's (``target``, ``imaging``) or, when the scene gives them
(``orbit.target_tle``, ``orbit.imaging_tle``), two TLEs propagated by SGP4, so real satellite
pairs can be imaged. Each frame's time since ``orbit.epoch_utc`` goes into its scene
(``orbit.time_s``): with ``sun.mode = "orbit"`` the Sun and the Earth's shadow follow the orbit
(``simcore.sun``), and every record carries the Sun's angle from the line of sight and whether
the target is in eclipse.

Every frame uses the scene's seed, so frame i is reproduced exactly by ``lmapd simulate`` with the
same scene and ``--set pose.quaternion_wxyz=[...] --set distance_m=...`` taken from its record.
The scene's own pose keys are ignored. The range gate follows the distance when
``timing.gate_center_m = 0`` (the default); a fixed gate centre stays fixed.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from tqdm import tqdm

from . import io, orbit, trajectory
from .materials import MATERIAL_NAMES
from .orbit import PAPER_IMAGING, PAPER_TARGET, Elements, RelativePose
from .orbit.inputs import time_array
from .pipeline import Pipeline, Result
from .pointcloud import PointCloud
from .scene import Scene, with_overrides
from .trajectory import GroundTruth

__all__ = [
    "DEFAULT_INTERVAL_S",
    "FlyaroundResult",
    "frame_filename",
    "pose_series",
    "run_flyaround",
]

DEFAULT_INTERVAL_S = 300.0  # [s] the paper's imaging interval (Section 4.2)
_UNIFORM_RTOL = 1e-9  # [-] relative spread of time steps still reported as one interval_s


@dataclass(frozen=True, eq=False)
class FlyaroundResult:
    """One fly-around: the per-frame records and the relative pose series they were imaged at.

    Attributes
    ----------
    scene : Scene
        The base scene; each frame replaced its ``pose.quaternion_wxyz`` and ``distance_m``.
    target, imaging : Elements
        The two orbits (common epoch t = 0).
    j2 : bool
        Whether the orbits were propagated with the secular J2 rates.
    pose : RelativePose
        Pose of the target body in the lidar sensor frame at each frame time.
    records : list of dict
        One per frame, in time order: ``t_s`` [s], ``distance_m`` [m], ``quaternion_wxyz`` (4,),
        ``angles_deg`` (3,) [deg], ``n_points``, ``n_outliers``, ``n_dropped``, ``n_unlit``,
        ``n_hit_pixels``, ``snr_median``, ``range_sigma_m_median`` [m] (None without
        detections), ``sun_angle_deg`` (at the target, between the Sun and the lidar) [deg],
        ``eclipsed`` (the target in the Earth's shadow), ``background_power_w_median`` [W],
        ``n_sunlit_pixels``, ``frame_s`` [s] (wall time of the frame, its PLY included) and
        ``ply`` (file name, or None).
    target_name, target_credit : str
        The target model's display name and the credit line its use requires.
    wall_s : float
        Wall time of the whole run [s].
    """

    scene: Scene
    target: Elements
    imaging: Elements
    j2: bool
    pose: RelativePose
    records: list[dict[str, Any]]
    target_name: str
    target_credit: str
    wall_s: float
    tles: tuple[str, str] | None = None
    truth: GroundTruth | None = None
    clouds: tuple[PointCloud, ...] = ()
    target_model: Any = None

    @property
    def kind(self) -> str:
        """The trajectory's kind: orbit, approach or hold (``trajectory.kind``)."""
        return self.scene.trajectory.kind

    def track(self, **options: Any) -> Any:
        """Register each frame's cloud to the target's model (``simcore.tracking.track``);
        needs the clouds (``run_flyaround(..., keep_clouds=True)``). ``options``: those of
        ``tracking.track``. Returns its ``TrackResult``."""
        from . import tracking  # noqa: PLC0415  (the registration library)

        if not self.clouds:
            raise ValueError("track() needs the clouds: run_flyaround(..., keep_clouds=True)")
        assert self.truth is not None
        return tracking.track(self.clouds, self.target_model, self.truth, **options)

    def pose_series(self, t_s) -> RelativePose:
        """The relative pose at the times ``t_s`` [s] from the same orbits (TLEs or elements)."""
        return _pose_series(self.scene, self.target, self.imaging, t_s, self.j2)

    @property
    def t_s(self) -> np.ndarray:
        """(n,) frame times [s]."""
        return self.pose.t_s

    @property
    def n_points(self) -> np.ndarray:
        """(n,) int points per frame (target points plus outliers)."""
        return np.array([r["n_points"] for r in self.records], dtype=np.int64)

    @property
    def interval_s(self) -> float | None:
        """The time between frames [s] if they are equally spaced, else None (one frame: None)."""
        steps = np.diff(self.pose.t_s)
        if len(steps) == 0 or not np.allclose(steps, steps[0], rtol=_UNIFORM_RTOL, atol=0.0):
            return None
        return float(steps[0])

    def to_json(self) -> dict[str, Any]:
        """A plain dict for ``io.write_json``: settings, per-frame records and distance figures.

        ``distance_stats`` holds the orbit's min/mean/max distance [m] over one period of the
        target (dense sampling, ``orbit.distance_stats``) and ``frame_distance_m`` the same
        figures over the imaged frames only.
        """
        d = self.pose.distance_m
        if self.kind != "orbit":
            orbits: dict[str, Any] = {}
            stats = {"min_m": float(d.min()), "mean_m": float(d.mean()), "max_m": float(d.max())}
        elif self.tles is None:
            orbits = {
                "target": dataclasses.asdict(self.target),
                "imaging": dataclasses.asdict(self.imaging),
            }
            stats = orbit.distance_stats(self.target, self.imaging, j2=self.j2)
        else:
            orbits = {"target_tle": self.tles[0], "imaging_tle": self.tles[1]}
            dense = self.pose_series(np.linspace(0.0, self.target.period_s, 2000, endpoint=False))
            stats = {
                "min_m": float(dense.distance_m.min()),
                "mean_m": float(dense.distance_m.mean()),
                "max_m": float(dense.distance_m.max()),
            }
        return {
            "scene": self.scene.to_dict(),
            "j2": self.j2,
            "trajectory": dataclasses.asdict(self.scene.trajectory),
            "conventions": trajectory.CONVENTIONS,
            "interval_s": self.interval_s,
            "n_frames": len(self.records),
            "orbits": orbits,
            "target": {"name": self.target_name, "credit": self.target_credit},
            "material_names": list(MATERIAL_NAMES),
            "distance_stats": stats,
            "frame_distance_m": {
                "min_m": float(d.min()),
                "mean_m": float(d.mean()),
                "max_m": float(d.max()),
            },
            "n_points_total": int(self.n_points.sum()),
            "wall_s": self.wall_s,
            "frames": self.records,
        }


def frame_filename(index: int, t_s: float) -> str:
    """PLY file name of frame ``index`` at time ``t_s`` [s]: ``frame_007_t02100s.ply``."""
    return f"frame_{index:03d}_t{t_s:05.0f}s.ply"


def run_flyaround(
    scene: Scene,
    times_s: ArrayLike | None = None,
    target: Elements = PAPER_TARGET,
    imaging: Elements = PAPER_IMAGING,
    j2: bool = False,
    out_dir: str | Path | None = None,
    progress: bool = True,
    pipeline: Pipeline | None = None,
    keep_clouds: bool = False,
) -> FlyaroundResult:
    """Image the target at each time of a fly-around.

    Parameters
    ----------
    scene : Scene
        The lidar and target; its pose (pitch, azimuth, roll, quaternion, distance) is replaced in
        each frame by the trajectory's (``scene.trajectory``: the orbits, an approach or a hold,
        with the target's tumble). Every frame uses ``scene.seed``.
    times_s : (n,) float, optional
        Imaging times since the epoch [s] (e.g. ``orbit.flyaround_times()``); None: those of the
        trajectory (approach, hold: ``trajectory.frame_times``; orbit: every
        ``DEFAULT_INTERVAL_S`` over one period of the target).
    target, imaging : Elements
        Orbits of the target (nadir-pointing) and of the imaging satellite (tracking lidar).
    j2 : bool
        Propagate with the secular J2 rates.
    out_dir : str or Path, optional
        If given, write one binary PLY per frame there (``frame_filename``), created if missing.
        Each file is written atomically, so a failed frame leaves no file behind.
    progress : bool
        Show a progress bar on stderr.
    pipeline : Pipeline, optional
        The pipeline to run the frames through (reuse one to keep the loaded mesh); a new one if
        None.
    keep_clouds : bool
        Keep every frame's point cloud in the result (``FlyaroundResult.clouds``; for
        ``track`` and the bag).

    Returns
    -------
    FlyaroundResult

    Raises
    ------
    OrbitError
        Invalid times (empty, not finite) or orbits.
    SceneError, TargetError
        From the pipeline, e.g. a mesh that cannot be loaded, or an approach that ends inside the
        target (refused before the first frame).
    """
    start = time.perf_counter()
    tles = None
    if scene.orbit.target_tle:  # real satellites: SGP4 states; their osculating elements
        tles = (scene.orbit.target_tle, scene.orbit.imaging_tle)
        target, imaging = (_osculating(scene, which) for which in ("target", "imaging"))
    if times_s is None:
        times_s = (
            orbit.flyaround_times(DEFAULT_INTERVAL_S, target.period_s)
            if scene.trajectory.kind == "orbit"
            else trajectory.frame_times(scene)
        )
    pose = _pose_series(scene, target, imaging, times_s, j2)
    pipeline = pipeline if pipeline is not None else Pipeline()
    if scene.trajectory.kind != "orbit":  # before any frame: not into the target
        from .target import load_target  # noqa: PLC0415

        trajectory.check_trajectory_target(scene, load_target(scene.target).surface.radius_m)
    from . import sun  # noqa: PLC0415  (the ephemeris: the Sun at each frame)

    suns = sun.orbit_sun_geometry(scene, pose.t_s, j2=j2)
    truth = trajectory.ground_truth(scene, pose, np.array([g.direction_body for g in suns]))
    truth_records = truth.records()
    folder = None if out_dir is None else Path(out_dir)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    records: list[dict[str, Any]] = []
    clouds = []
    bar = tqdm(
        total=len(pose.t_s), desc="fly-around", unit="frame", file=sys.stderr, disable=not progress
    )
    with bar:
        for i in range(len(pose.t_s)):
            record, result = _image_frame(scene, pose, i, pipeline, folder, suns[i], j2)
            record["truth"] = truth_records[i]
            records.append(record)
            if keep_clouds:
                clouds.append(result.cloud)
            bar.set_postfix_str(f"{record['distance_m']:.0f} m, {record['n_points']} points")
            bar.update()
    return FlyaroundResult(
        scene=scene,
        target=target,
        imaging=imaging,
        j2=bool(j2),
        pose=pose,
        records=records,
        target_name=result.target.name,
        target_credit=result.target.credit,
        wall_s=time.perf_counter() - start,
        tles=tles,
        truth=truth,
        clouds=tuple(clouds),
        target_model=result.target if keep_clouds else None,
    )


def _osculating(scene: Scene, which: str) -> Elements:
    """The osculating elements at the epoch of a satellite given by its TLE (for the record's
    period and the plot's labels; the frames use SGP4 itself)."""
    from .sun import satellite_states  # noqa: PLC0415

    r, v = satellite_states(scene, which, [0.0])
    return orbit.state_to_elements(r[0], v[0])


def pose_series(scene: Scene, times_s: ArrayLike, j2: bool = False) -> RelativePose:
    """The relative pose of the fly-around at ``times_s`` [s]: the scene's TLEs (SGP4) if it
    has them, else the paper's orbits (Table 3), as :func:`run_flyaround` images them."""
    target, imaging = PAPER_TARGET, PAPER_IMAGING
    if scene.orbit.target_tle:
        target, imaging = (_osculating(scene, which) for which in ("target", "imaging"))
    return _pose_series(scene, target, imaging, times_s, j2)


def _pose_series(scene: Scene, target: Elements, imaging: Elements, t_s, j2: bool):
    """The pose at ``t_s`` [s] of the scene's trajectory: the line of sight (approach, hold),
    else the SGP4 states of the scene's TLEs or the elements; the target's attitude on top."""
    kind = scene.trajectory.kind
    if kind != "orbit":
        t = time_array(t_s, allow_empty=False)
        base = trajectory.line_of_sight_poses(scene, t)
    elif not scene.orbit.target_tle:
        base = orbit.relative_pose_series(target, imaging, t_s, j2=j2)
    else:
        from .sun import satellite_states  # noqa: PLC0415

        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        r_t, v_t = satellite_states(scene, "target", t)
        r_i, v_i = satellite_states(scene, "imaging", t)
        base = orbit.relative_pose_from_states(t, r_t, v_t, r_i, v_i)
    if kind == "orbit" and not _turned(scene):
        return base  # the orbits' own series, bit for bit
    return trajectory.with_attitude(base, trajectory.attitude_offsets(scene, base.t_s))


def _turned(scene: Scene) -> bool:
    """Whether the target's attitude differs from its trajectory frame's (a tumble or an initial
    attitude other than the identity)."""
    tr = scene.trajectory
    return tr.tumble_rate_deg_s != 0.0 or tuple(tr.initial_quaternion_wxyz) != (1.0, 0, 0, 0)


def _image_frame(
    scene: Scene,
    pose: RelativePose,
    i: int,
    pipeline: Pipeline,
    folder: Path | None,
    sun_geo,
    j2: bool,
) -> tuple[dict[str, Any], Result]:
    """Image frame ``i`` of ``pose``; write its PLY into ``folder`` if given; its record."""
    frame_start = time.perf_counter()
    t_s = float(pose.t_s[i])
    frame_scene = with_overrides(
        scene,
        {
            "pose.quaternion_wxyz": pose.quaternion_wxyz[i].tolist(),
            "distance_m": float(pose.distance_m[i]),
            "orbit.time_s": t_s,
            "orbit.j2": bool(j2),
        },
    )
    result = pipeline.run(frame_scene)
    ply_name = None
    if folder is not None:
        ply_name = frame_filename(i, t_s)
        io.write_ply(folder / ply_name, result.cloud, _ply_comments(frame_scene, result, i, pose))
    summary = result.summary()
    record = {
        "t_s": t_s,
        "distance_m": float(pose.distance_m[i]),
        "quaternion_wxyz": pose.quaternion_wxyz[i].tolist(),
        "angles_deg": pose.angles_deg[i].tolist(),
        **{key: summary[key] for key in _SUMMARY_KEYS},
        "sun_angle_deg": _sun_angle_deg(sun_geo.direction_body, pose.relative_position_lvlh_m[i]),
        "eclipsed": bool(sun_geo.eclipsed),
        "frame_s": time.perf_counter() - frame_start,
        "ply": ply_name,
    }
    return record, result


_SUMMARY_KEYS = (
    "n_points",
    "n_outliers",
    "n_dropped",
    "n_unlit",
    "n_hit_pixels",
    "snr_median",
    "range_sigma_m_median",
    "background_power_w_median",
    "n_sunlit_pixels",
)


def _sun_angle_deg(sun_body, lidar_body_m) -> float:
    """Angle at the target between the Sun and the lidar [deg] (0: the Sun behind the lidar)."""
    u = np.asarray(lidar_body_m, dtype=np.float64)
    c = float(np.dot(sun_body, u) / np.linalg.norm(u))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _ply_comments(scene: Scene, result, index: int, pose: RelativePose) -> tuple[str, ...]:
    """Header comments of frame ``index``'s PLY: frame, scene, time, pose and the model credit."""
    q = " ".join(f"{v:.12g}" for v in pose.quaternion_wxyz[index])
    return (
        "lmapd-sim point cloud, sensor frame (x right, y down, z boresight), metres",
        f"fly-around frame {index} of {len(pose.t_s)}; scene {scene.name}",
        f"t_s {pose.t_s[index]:.3f}; distance_m {pose.distance_m[index]:.6f}",
        f"quaternion_wxyz (target body -> sensor) {q}",
        f"target {result.target.name}; {result.target.credit}",
        f"material_id indexes: {' '.join(MATERIAL_NAMES)}",
    )
