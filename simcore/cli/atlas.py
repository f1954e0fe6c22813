"""``lmapd atlas``: imaging quality over every view direction of the target, as a table, a map
and the best and worst attitudes' scene files (the library's ``simcore.atlas``).

    lmapd atlas [SCENE] --out DIR [--step-deg 10] [--set NAME=VALUE ...] [--metric f_score]
                [--require "recall >= 0.6" ...] [--resume] [--workers N | --scheduler ADDRESS]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import (
    CliError,
    add_cluster_options,
    add_scene_argument,
    check_cluster_options,
    say,
    scene_from_args,
)

EXIT_INTERRUPTED = 130  # Ctrl+C: the finished attitudes are kept; --resume goes on
# = simcore.atlas.METRICS and its defaults (a test checks): --help without the imaging chain
METRIC_NAMES = (
    "f_score",
    "precision",
    "recall",
    "recall_projected",
    "recall_cap",
    "range_bias_m",
    "range_rmse_m",
    "n_points",
    "n_target_points",
    "seen_area_m2",
    "n_lit_pixels",
    "point_density_per_m2",
)


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``atlas`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    p = subparsers.add_parser(
        "atlas",
        help="imaging quality over every view direction: a table, a map, the best and worst",
        description="Image the target from every attitude of a pole-to-pole grid of pitch and "
        "azimuth with the scene's settings; write DIR/atlas.parquet (a row per attitude), "
        "DIR/atlas.json (the grid, best, worst, median, shares meeting --require), DIR/atlas.png "
        "(the map, equal-area) and DIR/best.toml, DIR/worst.toml (for lmapd simulate). "
        "Ctrl+C keeps what is done; --resume finishes it.",
    )
    add_scene_argument(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument(
        "--step-deg",
        type=float,
        default=10.0,
        metavar="DEG",
        help="grid step in pitch and azimuth, 1 to 90 deg (rounded to divide 180 and 360; "
        "default 10: 614 attitudes)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="override a scene key (repeatable); pitch_deg and azimuth_deg are the grid's",
    )
    p.add_argument(
        "--metric",
        default="f_score",
        choices=METRIC_NAMES,
        help="the figure the map shows and best/worst rank by (default f_score)",
    )
    p.add_argument(
        "--require",
        action="append",
        default=[],
        metavar='"METRIC >= X"',
        help='a requirement each attitude meets or not ("recall >= 0.6", "range_rmse_m <= 0.05");'
        " repeatable; atlas.json gives the share of the sphere that meets them all",
    )
    p.add_argument("--resume", action="store_true", help="finish an interrupted atlas in DIR")
    add_cluster_options(p, "attitudes")
    p.set_defaults(func=run_cli)
    return p


def run_cli(args: argparse.Namespace) -> int:
    """``lmapd atlas``: 0 when every attitude is done, 1 if some failed, 130 when interrupted."""
    from ..atlas import AtlasError, build_atlas, run_atlas  # noqa: PLC0415  (the imaging chain)

    check_cluster_options(args)
    out = Path(args.out)  # a file there, or a folder that cannot be written: run_atlas says so
    scene = scene_from_args(args)
    try:
        atlas = build_atlas(scene, args.step_deg, args.metric, tuple(args.require))
        say(
            f"atlas: {len(atlas)} attitudes ({atlas.grid.pitch_step_deg:g} deg in pitch, "
            f"{atlas.grid.azimuth_step_deg:g} deg in azimuth) of {scene.name} at "
            f"{scene.detector.pixels} x {scene.detector.pixels} px -> {out}"
        )
        report = run_atlas(
            atlas,
            out,
            resume=args.resume,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=True,
        )
    except AtlasError as exc:
        raise CliError(str(exc)) from None
    except KeyboardInterrupt as exc:
        say(
            f"atlas: interrupted; {exc} attitudes kept in {out} (atlas.parquet): run again with "
            "--resume to finish",
            error=True,
        )
        return EXIT_INTERRUPTED
    say(f"atlas: {report.describe()}")
    s = report.summary
    for which in ("best", "worst"):
        if s.get(which):
            a = s[which]
            say(
                f"  {which}: pitch {a['pitch_deg']:g} deg, azimuth {a['azimuth_deg']:g} deg, "
                f"{args.metric} {a['value']:.4g} -> {out / (which + '.toml')}"
            )
    if s.get("median") is not None:
        say(f"  median over the sphere (by solid angle): {args.metric} {s['median']:.4g}")
    say(f"  target seen from {100 * s['share_seen_of_sphere']:.1f} % of the sphere")
    if "meets_requirements" in s:
        say(
            f"  meets {' and '.join(args.require)} from "
            f"{100 * s['meets_requirements']['share_of_sphere']:.1f} % of the sphere"
        )
    say(f"  map: {out / 'atlas.png'}")
    return 0 if report.n_failed == 0 else 1
