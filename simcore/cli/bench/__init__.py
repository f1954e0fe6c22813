"""``lmapd bench``: the stage timings on the MRO (``stages``), with ``--tradeoff`` each fidelity
preset's time against its error (``tradeoff``), with ``--startup`` the phases of ``lmapd simulate``
in fresh processes (``startup``), with ``--design`` a design study's wall time (``design``).

    lmapd bench [--quick] [--json FILE] [--tradeoff --out DIR [--pixels N] | --startup |
                --design [--trials N] [--workers N]]

The modules load the imaging chain; they are imported when the command runs, not at ``--help``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..common import CliError


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``bench`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    bench = subparsers.add_parser("bench", help="median stage timings on the MRO")
    bench.add_argument("--quick", action="store_true", help="fewer repeats and sizes")
    bench.add_argument("--json", help="also write the figures to this JSON file")
    bench.add_argument(
        "--tradeoff",
        action="store_true",
        help="each preset's time against its error relative to reference (needs --out)",
    )
    bench.add_argument(
        "--startup",
        action="store_true",
        help="lmapd simulate's import, target load, BVH build, first frame and write times, "
        "in fresh processes (median and range)",
    )
    bench.add_argument(
        "--design",
        action="store_true",
        help="the built-in design study's wall time (200 trials x 8 envelope points at "
        "128 x 128; 20 trials with --quick) and its stage reuse",
    )
    bench.add_argument("--trials", type=int, help="designs to screen for --design")
    bench.add_argument(
        "--workers", type=int, default=2, help="Dask workers for --design (default 2)"
    )
    bench.add_argument("--out", help="folder for tradeoff.json and tradeoff.png")
    bench.add_argument(
        "--pixels",
        type=int,
        help="array size per side for --tradeoff (default 256, the paper's; 128 with --quick)",
    )
    bench.set_defaults(func=run_cli)
    return bench


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd bench``; the exit status (0). User errors raise CliError."""
    if sum((args.tradeoff, args.startup, args.design)) > 1:
        raise CliError("--tradeoff, --startup and --design are three benches: run one at a time")
    if args.design:
        if args.trials is not None and args.trials < 1:
            raise CliError(f"--trials {args.trials}: give at least 1")
        if args.workers < 0:
            raise CliError(f"--workers {args.workers}: give a number >= 0")
        from . import design  # noqa: PLC0415  (the imaging chain, optuna, Dask)

        return design.main(args.quick, args.json, args.trials, args.workers)
    if args.trials is not None:
        raise CliError("--trials is for --design")
    if args.startup:
        if args.pixels is not None or args.out:
            raise CliError("--startup runs the paper scene: it takes no --pixels or --out")
        from . import startup  # noqa: PLC0415

        return startup.main(quick=args.quick, json_path=args.json)
    if args.tradeoff:
        if not args.out:
            raise CliError("--tradeoff needs --out DIR")
        from . import tradeoff  # noqa: PLC0415  (the imaging chain)

        return tradeoff.main(args.out, quick=args.quick, pixels=args.pixels)
    if args.pixels is not None:
        raise CliError("--pixels is for --tradeoff (the stage bench runs its own sizes)")
    from . import stages  # noqa: PLC0415

    return stages.main(quick=args.quick, json_path=args.json)
