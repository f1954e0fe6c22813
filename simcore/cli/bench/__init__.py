"""``lmapd bench``: the stage timings on the MRO (``stages``), with ``--tradeoff`` each fidelity
preset's time against its error (``tradeoff``), with ``--startup`` the phases of ``lmapd simulate``
in fresh processes (``startup``).

    lmapd bench [--quick] [--json FILE] [--tradeoff --out DIR [--pixels N] | --startup]

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
    if args.tradeoff and args.startup:
        raise CliError("--tradeoff and --startup are two benches: run one at a time")
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
