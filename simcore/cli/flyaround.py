"""``lmapd flyaround``: image the target along its trajectory (the Table 3 fly-around, an
approach or a hold: the scene's ``[trajectory]``); a PLY per frame, the ground truth, the JSON
record and the plot of the paper's Figure 7; with ``--track`` a pose track scored against the
truth, with ``--bag`` a ROS 2 bag.

    lmapd flyaround [SCENE.toml] [--set NAME=VALUE ...] --out DIR
                    [--interval-s 300] [--duration-s SECONDS] [--j2] [--track] [--bag FILE.mcap]

writes ``DIR/frame_000_t00000s.ply`` ... (one point cloud per frame, sensor frame), the true poses
``DIR/poses.csv``, a JSON record ``DIR/flyaround.json`` and a plot like the paper's Figure 7,
``DIR/flyaround.png``; ``--track`` adds ``DIR/tracking.csv`` and ``DIR/tracking.png``. The frames
are imaged by the library's ``simcore.flyaround.run_flyaround``; this module adds the command and
the plot.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .common import CliError, add_scene_argument, parse_sets, say

if TYPE_CHECKING:
    import numpy as np

    from ..flyaround import FlyaroundResult

__all__ = [
    "JSON_NAME",
    "MAX_FRAMES",
    "PNG_NAME",
    "POSES_NAME",
    "TRACK_CSV_NAME",
    "TRACK_PNG_NAME",
    "add_parser",
    "plot_flyaround",
    "run_cli",
]

DEFAULT_INTERVAL_S = 300.0  # [s] the paper's imaging interval (= flyaround.DEFAULT_INTERVAL_S)
PAPER_PERIOD_S = 5924.521  # [s] the paper's orbit period (= orbit.PAPER_PERIOD_S; --help text)
MAX_FRAMES = 10_000  # [-] guard against a mistyped interval (10k frames ~ 20 GB of PLY)
JSON_NAME = "flyaround.json"
PNG_NAME = "flyaround.png"
POSES_NAME = "poses.csv"
TRACK_CSV_NAME = "tracking.csv"
TRACK_PNG_NAME = "tracking.png"
_PLOT_SAMPLES = 721  # [-] samples of the smooth orbit curves drawn under the frame markers


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
    import numpy as np  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415  (heavy import; only when plotting)

    from .. import io  # noqa: PLC0415

    t = result.t_s
    t_dense = np.linspace(t[0], t[-1], _PLOT_SAMPLES) if len(t) > 1 else t
    dense = result.pose_series(t_dense)
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
    source = "two TLEs, SGP4" if result.tles else f"Table 3 orbits, {orbits}"
    fig.suptitle(
        f"Fly-around of the {result.target_name or 'target'}: {len(t)} frames {step}\n"
        f"({source}; scene {result.scene.name})",
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
    add_scene_argument(fly)
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
        help=f"time between frames of an orbit trajectory [s] (default {DEFAULT_INTERVAL_S:g}; "
        "approach and hold: trajectory.frame_rate_hz)",
    )
    fly.add_argument(
        "--duration-s",
        type=float,
        help="length of an orbit trajectory [s] (default one orbit, "
        f"{PAPER_PERIOD_S:g}; approach and hold: trajectory.duration_s)",
    )
    fly.add_argument("--j2", action="store_true", help="propagate with the secular J2 rates")
    fly.add_argument(
        "--track",
        action="store_true",
        help="register each frame's cloud to the target's model (small_gicp), scored against "
        "the truth: DIR/tracking.csv and DIR/tracking.png",
    )
    fly.add_argument(
        "--bag",
        metavar="FILE.mcap",
        help="also write a ROS 2 bag (MCAP): PointCloud2 per frame, the true /tf and, with "
        "--track, the estimated pose",
    )
    fly.set_defaults(func=run_cli)
    return fly


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd flyaround``; return the exit status (0). User errors raise CliError/SceneError.

    Everything is checked (times, scene, output folder) before the first frame is imaged; a
    folder this command created is removed again if the run fails before writing into it.
    """
    from .. import io, orbit  # noqa: PLC0415  (the imaging chain: not at --help time)
    from ..flyaround import run_flyaround  # noqa: PLC0415
    from ..scene import QUICK, load_scene, with_overrides  # noqa: PLC0415
    from ..trajectory import POSE_COLUMNS  # noqa: PLC0415
    from .track_plot import write_csv  # noqa: PLC0415

    start = time.perf_counter()
    overrides = parse_sets(args.set)
    for key in overrides:
        if QUICK.get(key, key).startswith("pose."):
            raise CliError(
                f"--set {key}: the fly-around takes the pose and distance from its trajectory; "
                "drop this key"
            )
    scene = with_overrides(load_scene(args.scene), overrides)
    times_s = _trajectory_times(scene, args)
    bag = _bag_path(args.bag)
    out = Path(args.out)
    created = _make_folder(out, CliError)
    io.remove_stale_parts(out)  # temporary files of a killed run in this folder
    try:
        result = run_flyaround(
            scene,
            times_s,
            j2=args.j2,
            out_dir=out,
            progress=True,
            keep_clouds=bool(args.track or bag),
        )
        tracked = _track(result, out) if args.track else None
        assert result.truth is not None  # run_flyaround always sets it
        write_csv(out / POSES_NAME, POSE_COLUMNS, result.truth.rows())
        record = result.to_json()
        if tracked is not None:
            record["tracking"] = tracked.summary()
        io.write_json(out / JSON_NAME, record)
        plot_flyaround(result, out / PNG_NAME)
        if bag is not None:
            from ..bag import write_bag  # noqa: PLC0415

            write_bag(bag, result, tracked)
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
    if tracked is not None:
        s = tracked.summary()
        med = (
            f"median error {s['rotation_error_deg_median']:.3g} deg, "
            f"{s['translation_error_m_median']:.3g} m"
            if s["rotation_error_deg_median"] is not None
            else "no frame tracked"
        )
        say(f"track: {s['n_frames'] - s['n_lost']} of {s['n_frames']} frames held, {med}")
    return 0


def _track(result, out: Path):
    """Track the fly-around; write DIR/tracking.csv and DIR/tracking.png; the TrackResult."""
    from ..tracking import TRACK_COLUMNS  # noqa: PLC0415
    from .track_plot import plot_tracking, write_csv  # noqa: PLC0415

    tracked = result.track()
    write_csv(out / TRACK_CSV_NAME, TRACK_COLUMNS, tracked.rows())
    plot_tracking(result, tracked, out / TRACK_PNG_NAME)
    return tracked


def _trajectory_times(scene, args: argparse.Namespace):
    """The frame times: --interval-s and --duration-s for an orbit trajectory, the scene's
    trajectory.frame_rate_hz and duration_s for an approach or a hold (the flags refused)."""
    if scene.trajectory.kind == "orbit":
        return _cli_times(
            DEFAULT_INTERVAL_S if args.interval_s is None else args.interval_s,
            PAPER_PERIOD_S if args.duration_s is None else args.duration_s,
            CliError,
        )
    for flag, value in (("--interval-s", args.interval_s), ("--duration-s", args.duration_s)):
        if value is not None:
            raise CliError(
                f"{flag} is for trajectory.kind = orbit; trajectory.kind = "
                f"{scene.trajectory.kind} takes trajectory.frame_rate_hz and trajectory.duration_s"
            )
    from ..trajectory import frame_times  # noqa: PLC0415

    return frame_times(scene)


def _bag_path(bag: str | None) -> Path | None:
    """``--bag``'s file, checked: a .mcap name in an existing, writable folder."""
    if bag is None:
        return None
    path = Path(bag)
    if path.suffix != ".mcap":
        raise CliError(f"--bag {bag!r}: give a file name ending in .mcap")
    if path.is_dir():
        raise CliError(f"--bag {bag!r} is a folder")
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK | os.X_OK):
        raise CliError(f"--bag {bag!r}: its folder does not exist or is not writable")
    return path


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
    from .. import orbit  # noqa: PLC0415

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
