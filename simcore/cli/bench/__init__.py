"""``lmapd bench``: the stage timings on the MRO (``stages``), with ``--tradeoff`` each fidelity
preset's time against its error (``tradeoff``), with ``--startup`` the phases of ``lmapd simulate``
in fresh processes (``startup``), with ``--design`` a design study's wall time (``design``), with
``--kernel`` the compiled echo kernel against the numpy path in fresh processes (``kernel``), with
``--sweep`` a sweep's wall time on Dask clusters of 1 and 2 workers (``sweep``), with ``--atlas``
the MRO's whole sphere of attitudes and the quality stage's shared samples (``atlas``), with
``--track`` the pose track's errors and cost against the targets of issue 40 (``track``), with
``--gm`` Geiger mode's cold run and slider changes against an older checkout (``gm``).

    lmapd bench [--quick] [--json FILE] [--tradeoff --out DIR [--pixels N] | --startup |
                --design [--trials N] [--workers N] |
                --kernel [--rounds N] [--repeats N] [--before DIR] |
                --sweep [--frames N] [--pixels N] [--workers N ...] [--backends B ...]
                        [--repeats N] |
                --atlas [--pixels N] [--workers N] [--repeats N] | --track |
                --gm [--rounds N] [--repeats N] [--before DIR]]

The modules load the imaging chain; they are imported when the command runs, not at ``--help``.
The benchmarks that need a browser or a served app stay scripts (``scripts/bench_app.py``,
``bench_sessions.py``, ``bench_session_memory.py``, ``soak_app.py``): they drive the app through
the test suite's browser and server helpers.
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
    bench.add_argument(
        "--kernel",
        action="store_true",
        help="the compiled echo kernel against the numpy path (LMAPD_NO_NUMBA=1), fresh "
        "processes in turn (median and range over the rounds)",
    )
    bench.add_argument(
        "--sweep",
        action="store_true",
        help="a sweep's wall time on Dask clusters of 1 and 2 workers (the best of the rounds)",
    )
    bench.add_argument(
        "--atlas",
        action="store_true",
        help="lmapd atlas of the MRO at 10 deg (614 attitudes) at 64 and 128 px, and the "
        "quality stage with its samples shared against drawn anew",
    )
    bench.add_argument(
        "--track",
        action="store_true",
        help="the pose track's errors on the Table 3 fly-around and on 2 km -> 20 m approaches "
        "(pixels, pulse energy), its cost against the frame's",
    )
    bench.add_argument(
        "--gm",
        action="store_true",
        help="Geiger mode: a cold lmapd simulate at 256 x 256 x 100 pulses and one session's "
        "first frame and pitch, energy, TNR and pulses changes (median and range)",
    )
    bench.add_argument("--trials", type=int, help="designs to screen for --design")
    bench.add_argument(
        "--workers",
        type=int,
        nargs="+",
        help="Dask workers: one count for --design and --atlas (default 2), the counts to "
        "compare for --sweep (default 1 2)",
    )
    bench.add_argument("--out", help="folder for tradeoff.json and tradeoff.png")
    bench.add_argument(
        "--pixels",
        type=int,
        help="array size per side for --tradeoff (default 256, the paper's; 128 with --quick), "
        "--sweep (default 128; 32 with --quick) and --atlas (default: 64, then 128)",
    )
    bench.add_argument(
        "--rounds",
        type=int,
        help="rounds of fresh processes for --kernel and --gm (default 3; 1 quick)",
    )
    bench.add_argument(
        "--repeats",
        type=int,
        help="warm frames a process for --kernel (default 7; 3 quick), timed rounds for --sweep "
        "(default 3; 1 quick), changes of each kind for --gm (default 3; 2 quick)",
    )
    bench.add_argument(
        "--before",
        metavar="DIR",
        help="for --kernel and --gm: also time the code in DIR (an older checkout, first on "
        "PYTHONPATH)",
    )
    bench.add_argument(
        "--frames", type=int, help="frames of the sweep for --sweep (default 200; 20 quick)"
    )
    bench.add_argument(
        "--backends",
        nargs="+",
        choices=("kernel", "numpy"),
        help="echo backends for --sweep, one cluster each (default kernel)",
    )
    bench.set_defaults(func=run_cli)
    return bench


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd bench``; the exit status (0). User errors raise CliError."""
    modes = {
        "--tradeoff": args.tradeoff,
        "--startup": args.startup,
        "--design": args.design,
        "--kernel": args.kernel,
        "--sweep": args.sweep,
        "--atlas": args.atlas,
        "--track": args.track,
        "--gm": args.gm,
    }
    chosen = [name for name, on in modes.items() if on]
    if len(chosen) > 1:
        raise CliError(f"{' and '.join(chosen)} are separate benches: run one at a time")
    _check_options(args, chosen[0] if chosen else None)
    if args.design:
        workers = args.workers[0] if args.workers else 2
        from . import design  # noqa: PLC0415  (the imaging chain, optuna, Dask)

        return design.main(args.quick, args.json, args.trials, workers)
    if args.kernel:
        from . import kernel  # noqa: PLC0415  (starts fresh processes)

        rounds = args.rounds or (1 if args.quick else 3)
        repeats = args.repeats or (3 if args.quick else 7)
        return kernel.main(rounds, repeats, args.json, args.before)
    if args.atlas:
        from . import atlas  # noqa: PLC0415  (the imaging chain, Dask)

        workers = args.workers[0] if args.workers else 2
        pixels = (args.pixels,) if args.pixels else ((32,) if args.quick else (64, 128))
        repeats = args.repeats or (1 if args.quick else 5)
        return atlas.main(pixels, workers, repeats, args.quick, args.json)
    if args.gm:
        from . import gm  # noqa: PLC0415  (starts fresh processes)

        rounds = args.rounds or (1 if args.quick else 3)
        repeats = args.repeats or (2 if args.quick else 3)
        return gm.main(rounds, repeats, args.json, args.before, args.quick)
    if args.sweep:
        from . import sweep  # noqa: PLC0415  (the imaging chain, Dask)

        return sweep.main(
            frames=args.frames or (20 if args.quick else 200),
            pixels=args.pixels or (32 if args.quick else 128),
            workers=tuple(args.workers or (1, 2)),
            backends=tuple(args.backends or ("kernel",)),
            repeats=args.repeats or (1 if args.quick else 3),
            json_path=args.json,
        )
    if args.track:
        from . import track  # noqa: PLC0415  (the imaging chain, the registration)

        return track.main(quick=args.quick, json_path=args.json)
    if args.startup:
        from . import startup  # noqa: PLC0415

        return startup.main(quick=args.quick, json_path=args.json)
    if args.tradeoff:
        from . import tradeoff  # noqa: PLC0415  (the imaging chain)

        return tradeoff.main(args.out, quick=args.quick, pixels=args.pixels)
    from . import stages  # noqa: PLC0415

    return stages.main(quick=args.quick, json_path=args.json)


# the options each bench takes (besides --quick and --json): any other is refused, naming them
OPTIONS = {
    None: (),
    "--tradeoff": ("out", "pixels"),
    "--startup": (),
    "--design": ("trials", "workers"),
    "--kernel": ("rounds", "repeats", "before"),
    "--sweep": ("frames", "pixels", "workers", "backends", "repeats"),
    "--atlas": ("pixels", "workers", "repeats"),
    "--track": (),
    "--gm": ("rounds", "repeats", "before"),
}


def _check_options(args: argparse.Namespace, mode: str | None) -> None:
    """Refuse an option the chosen bench does not take, and counts below their floor."""
    for option in ("out", "pixels", "trials", "workers", "rounds", "repeats", "before"):
        if getattr(args, option) is not None and option not in OPTIONS[mode]:
            takers = [m for m, names in OPTIONS.items() if m and option in names]
            what = "the stage bench" if mode is None else mode
            raise CliError(f"{what} takes no --{option} (it is for {' and '.join(takers)})")
    for option in ("frames", "backends"):
        if getattr(args, option) is not None and option not in OPTIONS[mode]:
            raise CliError(f"--{option} is for --sweep")
    if mode == "--tradeoff" and not args.out:
        raise CliError("--tradeoff needs --out DIR")
    if mode in ("--design", "--atlas") and args.workers is not None and len(args.workers) != 1:
        raise CliError(f"{mode} runs on one number of --workers")
    floors = {"trials": 1, "rounds": 1, "repeats": 1, "frames": 1}  # pixels: the scene checks
    for option, floor in floors.items():
        value = getattr(args, option)
        if value is not None and value < floor:
            raise CliError(f"--{option} {value}: give at least {floor}")
    if args.workers is not None and min(args.workers) < (0 if mode == "--design" else 1):
        raise CliError(f"--workers {' '.join(map(str, args.workers))}: give counts of workers")
