"""``lmapd sweep``: run the frames of a sweep file not yet done in a folder, on Dask, and write the
Parquet table of their metrics (the library's ``simcore.sweep``).

    lmapd sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N] [--clouds ply|las|none]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import CliError, add_cluster_options, check_cluster_options, say

CLOUD_FORMATS = ("ply", "las")  # = simcore.sweep.spec.CLOUD_FORMATS (a test checks; --help text)


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``sweep`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    p = subparsers.add_parser(
        "sweep",
        help="run a grid or list of frames on Dask and write a Parquet table of their metrics",
        description="Run every frame of SWEEP.toml not yet done in DIR (each a Dask task), "
        "write DIR/frames/<id>.json per frame and DIR/sweep.parquet. Rerun to resume or to "
        "retry failed frames.",
    )
    p.add_argument("sweep", help="sweep file (TOML: base, [set], [grid], [[list]])")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    add_cluster_options(p, "frames")
    p.add_argument(
        "--clouds",
        choices=(*CLOUD_FORMATS, "none"),
        help="also write each frame's point cloud in DIR/clouds (default: as the sweep file says)",
    )
    p.set_defaults(func=run_cli)
    return p


def run_cli(args: argparse.Namespace) -> int:
    """``lmapd sweep``: 0 if every frame is done, 1 if some failed (they are retried next run)."""
    from ..sweep import load_sweep, run_sweep  # noqa: PLC0415  (the imaging chain)

    check_cluster_options(args)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {args.out!r} is a file, not a folder")
    sweep = load_sweep(args.sweep)
    from .. import io  # noqa: PLC0415
    from ..sweep.spec import CLOUDS_DIR, FRAMES_DIR  # noqa: PLC0415

    for folder in (out, out / FRAMES_DIR, out / CLOUDS_DIR):  # a killed run's temporary files
        if folder.is_dir():
            io.remove_stale_parts(folder)
    clouds = None if args.clouds is None else (False if args.clouds == "none" else args.clouds)
    report = run_sweep(
        sweep, out, workers=args.workers, scheduler=args.scheduler, clouds=clouds, progress=True
    )
    say(f"sweep {sweep.name}: {report.describe()}")
    return 0 if report.n_failed == 0 else 1
