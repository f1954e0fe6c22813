"""Reproduce the paper's results from the simulator, side by side with its own forms.

``lmapd reproduce --out DIR [--quick] [--seed N]`` regenerates, with one command, each result of
Wang et al., *Analysis and Simulation of Space-Based LM-APD 3D Imaging*, Electronics 2023, 12, 2261
that this simulator can produce, and writes one PNG per figure plus ``DIR/report.json`` with every
number behind them, the scene of every run, the seed and the simulator's version:

1. ``fig02_brdf.png`` -- Eq. 6 against the incidence angle for the Table 1 materials (Figure 2).
2. ``fig09_detection.png`` -- P_d and false alarms against TNR: Eqs. 27-28 (ours and the paper's)
   with waveform Monte Carlo points, R_gate = 1 km and df = 12 MHz as in Figure 9.
3. ``fig14_waveforms.png`` -- single-pixel echoes found in the echo data: dish rim over the bus
   (a double peak) and a steep part of the dish (a spread echo), with the emitted pulse (Figure 14).
4. ``fig16_pitch.png``, ``fig17_azimuth.png`` -- point clouds over pitch and azimuth steps,
   front and top views, coloured by material (Figures 16, 17).
5. ``fig18_20_resolution.png`` -- 32 to 256 pixels per side at 500 m and 1000 m with the field of
   view (and the illumination cone) matched to the target, and the point counts (Figures 18-20).
6. ``fig07_flyaround.png``, ``fig24_frames.png`` -- the Table 3 fly-around: distance and attitude
   curves (Figure 7) and the frames at t = 3000, 4200 and 5400 s (Figure 24).
7. ``conventions.png`` -- each of the paper's literal forms (``simcore.PAPER_FORMS``) alone against
   ours: its change to SNR, range sigma, outliers and point count on the paper scene.

The numbers (settings, analyses) are the library's ``simcore.reproduce``; this package runs the
scenes and draws the figures: ``report`` (the run), ``items_echo`` and ``items_clouds`` (the items),
``draw`` (figure helpers), ``run`` (the run's context).

Every random draw comes from a generator seeded by ``seed``, so a run is reproduced exactly by the
same seed (and ``quick`` flag); only the wall times in ``report["timings_s"]`` differ.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from ..common import CliError, say

__all__ = ["add_parser", "run_cli"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``reproduce`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    rep = subparsers.add_parser(
        "reproduce",
        help="regenerate the paper's figures from the simulator (PNGs + report.json)",
        description="Regenerate each of the paper's results with the simulator, side by side with "
        "the paper's own forms: DIR/*.png and DIR/report.json (every number, scene, seed, "
        "version). See docs/reproduction.md.",
    )
    rep.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    rep.add_argument(
        "--quick", action="store_true", help="fewer pixels and Monte Carlo trials (a draft)"
    )
    rep.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    rep.set_defaults(func=run_cli)
    return rep


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd reproduce``; return the exit status (0). User errors raise CliError."""
    from .report import REPORT_NAME, run_reproduction  # noqa: PLC0415  (the imaging chain)

    start = time.perf_counter()
    if args.seed < 0:
        raise CliError(f"--seed must be a whole number >= 0, got {args.seed}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {str(out)!r} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CliError(f"--out {str(out)!r}: cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise CliError(f"--out {str(out)!r}: the folder is not writable")
    from ... import io  # noqa: PLC0415

    io.remove_stale_parts(out)  # temporary files of a killed run in this folder
    report = run_reproduction(out, quick=args.quick, seed=args.seed, progress=True)
    say(
        f"{len(report['items'])} items, {len(report['figures'])} figures and {REPORT_NAME} "
        f"-> {out}/  [{time.perf_counter() - start:.1f} s]"
    )
    return 0
