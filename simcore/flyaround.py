"""The fly-around: image the target every ``interval_s`` over one orbit (PHYSICS.md section 3).

The two orbits of Table 3 give, at each imaging time, the lidar-target distance and the pose of the
target body in the lidar sensor frame (``orbit.relative_pose_series``); each pose is one flash of
the imaging chain, run through ONE ``Pipeline`` so the mesh and its BVH load once::

    lmapd flyaround [SCENE.toml] [--set NAME=VALUE ...] --out DIR
                    [--interval-s 300] [--duration-s SECONDS] [--j2]

writes ``DIR/frame_000_t00000s.ply`` ... (one point cloud per frame, sensor frame), a JSON record
``DIR/flyaround.json`` and a plot like the paper's Figure 7, ``DIR/flyaround.png``.

Every frame uses the scene's seed, so frame i is reproduced exactly by ``lmapd simulate`` with the
same scene and ``--set pose.quaternion_wxyz=[...] --set distance_m=...`` taken from its record.
The scene's own pose keys are ignored. The range gate follows the distance when
``timing.gate_center_m = 0`` (the default); a fixed gate centre stays fixed.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from tqdm import tqdm

from . import io, orbit
from .materials import MATERIAL_NAMES
from .orbit import PAPER_IMAGING, PAPER_PERIOD_S, PAPER_TARGET, Elements, RelativePose
from .pipeline import Pipeline, Result
from .scene import QUICK, Scene, load_scene, parse_assignment, with_overrides

__all__ = [
    "DEFAULT_INTERVAL_S",
    "JSON_NAME",
    "MAX_FRAMES",
    "PNG_NAME",
    "FlyaroundResult",
    "add_parser",
    "frame_filename",
    "plot_flyaround",
    "run_cli",
    "run_flyaround",
]

DEFAULT_INTERVAL_S = 300.0  # [s] the paper's imaging interval (Section 4.2)
MAX_FRAMES = 10_000  # [-] CLI guard against a mistyped interval (10k frames ~ 20 GB of PLY)
JSON_NAME = "flyaround.json"
PNG_NAME = "flyaround.png"
_PLOT_SAMPLES = 721  # [-] samples of the smooth orbit curves drawn under the frame markers
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
        ``angles_deg`` (3,) [deg], ``n_points``, ``n_outliers``, ``n_dropped``, ``n_hit_pixels``,
        ``snr_median``, ``range_sigma_m_median`` [m] (None without detections), ``frame_s``
        [s] (wall time of the frame, its PLY included) and ``ply`` (file name, or None).
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
        return {
            "scene": self.scene.to_dict(),
            "j2": self.j2,
            "interval_s": self.interval_s,
            "n_frames": len(self.records),
            "orbits": {
                "target": dataclasses.asdict(self.target),
                "imaging": dataclasses.asdict(self.imaging),
            },
            "target": {"name": self.target_name, "credit": self.target_credit},
            "material_names": list(MATERIAL_NAMES),
            "distance_stats": orbit.distance_stats(self.target, self.imaging, j2=self.j2),
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
    times_s: ArrayLike,
    target: Elements = PAPER_TARGET,
    imaging: Elements = PAPER_IMAGING,
    j2: bool = False,
    out_dir: str | Path | None = None,
    progress: bool = True,
    pipeline: Pipeline | None = None,
) -> FlyaroundResult:
    """Image the target at each time of a fly-around.

    Parameters
    ----------
    scene : Scene
        The lidar and target; its pose (pitch, azimuth, roll, quaternion, distance) is replaced in
        each frame by the orbits' relative pose. Every frame uses ``scene.seed``.
    times_s : (n,) float
        Imaging times since the orbits' common epoch [s] (e.g. ``orbit.flyaround_times()``).
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

    Returns
    -------
    FlyaroundResult

    Raises
    ------
    OrbitError
        Invalid times (empty, not finite) or orbits.
    SceneError, TargetError
        From the pipeline, e.g. a mesh that cannot be loaded.
    """
    start = time.perf_counter()
    pose = orbit.relative_pose_series(target, imaging, times_s, j2=j2)
    folder = None if out_dir is None else Path(out_dir)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    pipeline = pipeline if pipeline is not None else Pipeline()
    records: list[dict[str, Any]] = []
    bar = tqdm(
        total=len(pose.t_s), desc="fly-around", unit="frame", file=sys.stderr, disable=not progress
    )
    with bar:
        for i in range(len(pose.t_s)):
            record, result = _image_frame(scene, pose, i, pipeline, folder)
            records.append(record)
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
    )


def _image_frame(
    scene: Scene, pose: RelativePose, i: int, pipeline: Pipeline, folder: Path | None
) -> tuple[dict[str, Any], Result]:
    """Image frame ``i`` of ``pose``; write its PLY into ``folder`` if given; its record."""
    frame_start = time.perf_counter()
    t_s = float(pose.t_s[i])
    frame_scene = with_overrides(
        scene,
        {
            "pose.quaternion_wxyz": pose.quaternion_wxyz[i].tolist(),
            "distance_m": float(pose.distance_m[i]),
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
        "frame_s": time.perf_counter() - frame_start,
        "ply": ply_name,
    }
    return record, result


_SUMMARY_KEYS = (
    "n_points",
    "n_outliers",
    "n_dropped",
    "n_hit_pixels",
    "snr_median",
    "range_sigma_m_median",
)


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


# ----------------------------------------------------------------------------------------------
# The plot (the paper's Figure 7)
# ----------------------------------------------------------------------------------------------
def plot_flyaround(result: FlyaroundResult, path: str | Path) -> None:
    """Write a PNG of the fly-around like the paper's Figure 7 (matplotlib, Agg backend).

    Three panels against time [s]: the relative distance [m], the relative attitude angles [deg]
    (intrinsic x-y'-z'' Euler angles of the target body -> sensor rotation, unwrapped so that a
    curve crossing +-180 deg stays continuous) and the points per frame. Smooth curves sample the
    orbits densely; markers are the imaged frames. Written atomically.

    Parameters
    ----------
    result : FlyaroundResult
        The fly-around to draw.
    path : str or Path
        The PNG file; its folder must exist.
    """
    from matplotlib.figure import Figure  # noqa: PLC0415  (heavy import; only when plotting)

    t = result.t_s
    t_dense = np.linspace(t[0], t[-1], _PLOT_SAMPLES) if len(t) > 1 else t
    dense = orbit.relative_pose_series(result.target, result.imaging, t_dense, j2=result.j2)
    # unwrap frames and dense curve together, so both land on the same branch
    both = np.concatenate([dense.angles_deg, result.pose.angles_deg])
    order = np.argsort(np.concatenate([t_dense, t]), kind="stable")
    unwrapped = np.empty_like(both)
    unwrapped[order] = np.unwrap(both[order], period=360.0, axis=0)
    angles_dense, angles_frames = unwrapped[: len(t_dense)], unwrapped[len(t_dense) :]

    fig = Figure(figsize=(8.0, 8.0), layout="constrained")
    ax_d, ax_a, ax_n = fig.subplots(3, 1, sharex=True, height_ratios=(1.0, 1.3, 0.7))
    interval = result.interval_s
    step = f"every {interval:g} s" if interval is not None else "at given times"
    orbits = "two-body + J2 secular" if result.j2 else "two-body"
    fig.suptitle(
        f"Fly-around of the {result.target_name or 'target'}: {len(t)} frames {step}\n"
        f"(Table 3 orbits, {orbits}; scene {result.scene.name})",
        fontsize=11,
    )

    ax_d.plot(t_dense, dense.distance_m, color="C0", lw=1.5, label="orbit")
    ax_d.plot(t, result.pose.distance_m, "o", color="C0", ms=4, label="frames")
    mean_m = float(np.mean(result.pose.distance_m))
    ax_d.axhline(mean_m, color="0.4", lw=0.8, ls="--", label=f"frame mean {mean_m:.1f} m")
    ax_d.set_ylabel("relative distance [m]")
    ax_d.legend(loc="best", fontsize=8)

    labels = ("about x (a0)", "about y' (a1)", "about z'' (a2)")
    for k, label in enumerate(labels):
        ax_a.plot(t_dense, angles_dense[:, k], color=f"C{k + 1}", lw=1.5, label=label)
        ax_a.plot(t, angles_frames[:, k], "o", color=f"C{k + 1}", ms=4)
    wrapped = bool(np.any(np.abs(angles_dense) > 180.0))
    ax_a.set_ylabel("relative attitude [deg]" + (", unwrapped" if wrapped else ""))
    ax_a.legend(loc="best", fontsize=8, title="target body -> lidar, XYZ Euler", title_fontsize=8)

    spacing_s = interval if interval is not None else float(np.ptp(t)) / max(len(t) - 1, 1)
    width = 0.6 * (spacing_s or 1.0)
    ax_n.bar(t, result.n_points, width=width, color="C7")
    ax_n.set_ylabel("points per frame")
    ax_n.set_xlabel("time since epoch [s]")

    for ax in (ax_d, ax_a, ax_n):
        ax.grid(True, alpha=0.3)
    if result.target_credit:
        fig.text(0.995, 0.002, result.target_credit, ha="right", va="bottom", fontsize=7)
    with io.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)


# ----------------------------------------------------------------------------------------------
# The command line
# ----------------------------------------------------------------------------------------------
def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``flyaround`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    fly = subparsers.add_parser(
        "flyaround",
        help="image the target over a fly-around (Table 3 orbits) and write a PLY per frame",
        description="Image the target every --interval-s over --duration-s of the Table 3 "
        "fly-around; write DIR/frame_*.ply, DIR/flyaround.json and DIR/flyaround.png.",
    )
    fly.add_argument("scene", nargs="?", help="scene TOML file or built-in name (default: paper)")
    fly.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="override a scene key (pixels, pulse_energy_j, tnr, seed, or any dotted key such as "
        "fidelity.subrays); repeatable. The pose comes from the orbits.",
    )
    fly.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    fly.add_argument(
        "--interval-s",
        type=float,
        default=DEFAULT_INTERVAL_S,
        help=f"time between frames [s] (default {DEFAULT_INTERVAL_S:g})",
    )
    fly.add_argument(
        "--duration-s",
        type=float,
        default=PAPER_PERIOD_S,
        help=f"length of the fly-around [s] (default one orbit, {PAPER_PERIOD_S:g})",
    )
    fly.add_argument("--j2", action="store_true", help="propagate with the secular J2 rates")
    fly.set_defaults(func=run_cli)
    return fly


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd flyaround``; return the exit status (0). User errors raise CliError/SceneError.

    Everything is checked (times, scene, output folder) before the first frame is imaged; a
    folder this command created is removed again if the run fails before writing into it.
    """
    from .cli import CliError, say  # noqa: PLC0415  (cli imports this module)

    start = time.perf_counter()
    times_s = _cli_times(args.interval_s, args.duration_s, CliError)
    overrides = dict(parse_assignment(s) for s in args.set or [])
    for key in overrides:
        if QUICK.get(key, key).startswith("pose."):
            raise CliError(
                f"--set {key}: the fly-around takes the pose and distance from the orbits; "
                "drop this key"
            )
    scene = with_overrides(load_scene(args.scene), overrides)
    out = Path(args.out)
    created = _make_folder(out, CliError)
    try:
        result = run_flyaround(scene, times_s, j2=args.j2, out_dir=out, progress=True)
        io.write_json(out / JSON_NAME, result.to_json())
        plot_flyaround(result, out / PNG_NAME)
    except orbit.OrbitError as exc:
        _remove_if_empty(created)
        raise CliError(str(exc)) from None
    except BaseException:
        _remove_if_empty(created)
        raise
    d = result.pose.distance_m
    say(
        f"{len(result.records)} frames, distance {d.min():.1f} / {d.mean():.1f} / {d.max():.1f} m "
        f"(min / mean / max), {int(result.n_points.sum())} points -> {out}/  "
        f"[{time.perf_counter() - start:.1f} s]"
    )
    return 0


def _cli_times(interval_s: float, duration_s: float, error: type[Exception]) -> np.ndarray:
    """The frame times of ``--interval-s`` and ``--duration-s``; ``error`` naming the flag."""
    for flag, value in (("--duration-s", duration_s), ("--interval-s", interval_s)):
        if not (math.isfinite(value) and value > 0.0):
            raise error(f"{flag} must be a finite number of seconds > 0, got {value:g}")
    steps = duration_s / interval_s  # frames = floor(steps) + 1; may overflow to inf
    if not steps < MAX_FRAMES:
        raise error(
            f"--duration-s {duration_s:g} / --interval-s {interval_s:g} gives {steps + 1:.4g} "
            f"frames (at most {MAX_FRAMES}); use a longer --interval-s"
        )
    try:
        times_s = orbit.flyaround_times(interval_s, duration_s)
    except orbit.OrbitError as exc:
        raise error(str(exc)) from None
    return times_s


def _make_folder(out: Path, error: type[Exception]) -> list[Path]:
    """Create ``out`` (and parents) if missing; the folders this call created, deepest first."""
    if out.exists() and not out.is_dir():
        raise error(f"--out {str(out)!r} exists and is not a folder")
    created = [p for p in (out, *out.parents) if not p.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"--out {str(out)!r}: cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise error(f"--out {str(out)!r}: the folder is not writable")
    return created


def _remove_if_empty(created: list[Path]) -> None:
    """Remove the folders this run created (deepest first) as long as they are empty."""
    for folder in created:
        try:
            folder.rmdir()
        except OSError:
            return  # not empty (complete frames stay) or already gone
