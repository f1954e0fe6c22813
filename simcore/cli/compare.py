"""``lmapd compare``: the same scene with the LM-APD and the Geiger-mode receiver over distance
(100 m to 10 km) and pulse energy; a table, a JSON file and a figure.

lmapd compare [SCENE.toml] [--set NAME=VALUE ...] --out DIR [--quick] [--p-detect 0.95]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path
from typing import Any

from .common import CliError, add_scene_argument, say, scene_from_args


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``compare`` subcommand on ``subparsers``."""
    cmp_ = subparsers.add_parser(
        "compare", help="the same scene with the LM-APD and the Geiger-mode array"
    )
    add_scene_argument(cmp_)
    cmp_.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a key")
    cmp_.add_argument("--out", required=True, help="folder for compare.json and compare.png")
    cmp_.add_argument("--quick", action="store_true", help="32 x 32 pixels (default 64 x 64)")
    cmp_.add_argument(
        "--p-detect", type=float, default=0.95, help="the P_d of the pulses-needed column"
    )
    cmp_.set_defaults(func=run_cli)
    return cmp_


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd compare``; return the exit status (0)."""
    if not 0.0 < args.p_detect < 1.0:
        raise CliError(f"--p-detect = {args.p_detect!r} must lie in (0, 1)")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {args.out}: not a folder")
    scene = scene_from_args(args)
    from ..compare import compare  # noqa: PLC0415
    from ..scene import with_overrides  # noqa: PLC0415

    given = {k.split("=", 1)[0].strip() for k in args.set or []}
    if not given & {"pixels", "detector.pixels"}:
        scene = with_overrides(scene, {"pixels": 32 if args.quick else 64})
    say(
        f"{'receiver':8} {'distance_m':>10} {'energy_j':>9} {'pe':>9} {'points':>6} "
        f"{'rms_m':>8} {'bias_m':>8} {'sd_m':>8} {'pred_b_m':>8} {'pred_sd_m':>9} "
        f"{'outl':>5} {'outl_exp':>8} {'pulses':>6}"
    )

    def line(r) -> None:
        say(
            f"{r.receiver:8} {r.distance_m:10.0f} {r.pulse_energy_j:9.1e} "
            f"{r.signal_pe_median:9.3g} {r.n_points:6d} {r.range_noise_m:8.3g} "
            f"{r.range_bias_m:8.3g} {r.range_sd_m:8.3g} {r.predicted_bias_m:8.3g} "
            f"{r.predicted_sd_m:9.3g} {r.n_outliers:5d} {r.n_false_points_expected:8.3g} "
            f"{r.pulses_needed:6g}"
        )

    rows = compare(scene, p_target=args.p_detect, progress=line)
    out.mkdir(parents=True, exist_ok=True)
    data = [
        {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in r.__dict__.items()
        }
        for r in rows
    ]
    (out / "compare.json").write_text(json.dumps(data, indent=1))
    draw(rows, out / "compare.png", args.p_detect)
    say(f"wrote {out / 'compare.json'} and {out / 'compare.png'}")
    return 0


def draw(rows, path: Path, p_target: float) -> None:
    """Five panels against distance: points, range bias (|median error|), range noise (sd
    about the mean), false points (outliers, and dotted their prediction), pulses for
    ``p_target``; one line per receiver and pulse energy."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, axes = plt.subplots(1, 5, figsize=(20, 3.8))
    panels = (
        ("n_points", "target points"),
        ("range_bias_m", "range bias, |median error| [m]"),
        ("range_sd_m", "range noise, sd [m]"),
        ("n_outliers", "false points per frame (dotted: expected)"),
        ("pulses_needed", f"pulses for P_d = {p_target:g}"),
    )
    kinds = list(dict.fromkeys(r.receiver for r in rows))  # in the order compared
    styles = dict(zip(kinds, itertools.cycle(("-o", "--s", "-.^", ":d")), strict=False))
    for ax, (field, label) in zip(axes, panels, strict=True):
        for kind in kinds:
            for e in sorted({r.pulse_energy_j for r in rows}):
                sel = [r for r in rows if r.receiver == kind and r.pulse_energy_j == e]
                x = [r.distance_m for r in sel]
                y = [getattr(r, field) for r in sel]
                y = [abs(v) for v in y] if field == "range_bias_m" else y
                y = [v if math.isfinite(v) else float("nan") for v in y]
                line = ax.plot(x, y, styles[kind], label=f"{kind}, {e:g} J")[0]
                if field == "n_outliers":  # the prediction on the same basis, beside it
                    expected = [r.n_false_points_expected for r in sel]
                    ax.plot(x, expected, ":", color=line.get_color())
        ax.set_xscale("log")
        if field in ("range_bias_m", "range_sd_m", "pulses_needed"):
            ax.set_yscale("log")
        ax.set_xlabel("distance [m]")
        ax.set_title(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
