"""``lmapd design``: search the design space of a study file for the cheapest lidar that meets
its requirements over its envelope (the library's ``simcore.design``).

    lmapd design STUDY.toml --out DIR [--trials N] [--workers N | --scheduler ADDRESS] [--resume]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import CliError, add_cluster_options, check_cluster_options, say

EXIT_INTERRUPTED = 130  # Ctrl+C: the finished designs are kept; --resume goes on


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``design`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    p = subparsers.add_parser(
        "design",
        help="find the cheapest design that meets a study's requirements (optuna on Dask)",
        description="Screen designs of STUDY.toml over its envelope (optuna, seeded), polish "
        "the cheapest feasible one, confirm the front at the reference preset, and write "
        "DIR/trials.parquet, front.csv, best.toml, figures and report.md. Every finished design "
        "is kept in DIR/records: --resume goes on after an interrupt.",
    )
    p.add_argument("study", help="study file (TOML: [envelope], [variables], [requirements], ...)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument(
        "--trials", type=int, metavar="N", help="designs to screen (default: the study's)"
    )
    add_cluster_options(p, "designs")
    p.add_argument("--resume", action="store_true", help="go on with the designs already in DIR")
    p.set_defaults(func=run_cli)
    return p


def run_cli(args: argparse.Namespace) -> int:
    """``lmapd design``: 0 when a design meets every requirement, 1 when none does."""
    from .. import design, io  # noqa: PLC0415  (the imaging chain, optuna, Dask)

    check_cluster_options(args)
    if args.trials is not None and args.trials < 1:
        raise CliError(f"--trials {args.trials}: give a number >= 1")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {args.out!r} is a file, not a folder")
    study = design.load_study(args.study)
    for folder in (out, out / "records"):  # a killed run's temporary files
        if folder.is_dir():
            io.remove_stale_parts(folder)
    try:
        result = design.run(
            study,
            out,
            trials=args.trials,
            workers=args.workers,
            scheduler=args.scheduler,
            resume=args.resume,
        )
    except KeyboardInterrupt:
        kept = len(list((out / "records").glob("*.json"))) if (out / "records").is_dir() else 0
        say(
            f"design {study.name}: interrupted; {kept} finished designs kept in {out}: "
            "run again with --resume to go on",
            error=True,
        )
        return EXIT_INTERRUPTED
    say(f"design {study.name}: {result.describe()}")
    say(result.tally.line())
    say(f"report: {out / 'report.md'}")
    return 0 if result.winner is not None else 1
