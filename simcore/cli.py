"""The ``lmapd`` command: simulate one flash, list scene keys, benchmark, serve the app.

    lmapd simulate [SCENE.toml] [--set NAME=VALUE ...] --out cloud.ply
                   [--summary summary.json] [--waveforms waveforms.npz]
    lmapd keys [--markdown]
    lmapd bench [--quick] [--json FILE] [--tradeoff --out DIR [--pixels N]]
    lmapd app [--host 127.0.0.1] [--port 8080] [--scene SCENE]
    lmapd flyaround [SCENE.toml] [--set NAME=VALUE ...] --out DIR [--interval-s 300]
                    [--duration-s SECONDS] [--j2]
    lmapd reproduce --out DIR [--quick] [--seed N]
    lmapd sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N]

Errors in the user's input (unknown key, value out of range, missing or broken file) print one
message naming what is wrong and exit with status 2; no output file is left half-written.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

from . import flyaround, io, reproduce, sweep
from .materials import MATERIAL_NAMES
from .scene import (
    PRESETS,
    SceneError,
    key_reference,
    load_scene,
    parse_assignment,
    with_overrides,
)
from .target import TargetError

EXIT_USAGE = 2
OUTPUT_SUFFIXES = io.CLOUD_SUFFIXES


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def say(text: str) -> None:
    """Command output on stdout: the one place the subcommands' handlers write from."""
    print(text)


def _scene_from_args(args):
    scene = load_scene(args.scene)
    overrides = dict(parse_assignment(s) for s in args.set or [])
    if getattr(args, "preset", None):
        overrides = {"preset": args.preset, **overrides}
    return with_overrides(scene, overrides)


def _check_output(path: str | None, suffixes, what: str) -> Path | None:
    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise CliError(f"{what} {path!r}: unsupported format; use {' or '.join(suffixes)}")
    if not p.parent.exists():
        raise CliError(f"{what} {path!r}: folder {str(p.parent)!r} does not exist")
    return p


def cmd_simulate(args) -> int:
    out = _check_output(args.out, OUTPUT_SUFFIXES, "--out")
    summary_path = _check_output(args.summary, (".json",), "--summary")
    wave_path = _check_output(args.waveforms, io.WAVEFORM_SUFFIXES, "--waveforms")
    scene = _scene_from_args(args)
    from .pipeline import Pipeline  # noqa: PLC0415  (keeps `lmapd keys` and --help fast)

    result = Pipeline().run(scene)
    summary = result.summary()
    summary["material_names"] = list(MATERIAL_NAMES)
    comments = (
        "lmapd-sim point cloud, sensor frame (x right, y down, z boresight), metres",
        f"scene {scene.name}",
        f"target {result.target.name}; {result.target.credit}",
        f"material_id indexes: {' '.join(MATERIAL_NAMES)}",
    )
    io.write_cloud(out, result.cloud, comments)
    if summary_path:
        io.write_json(summary_path, summary)
    if wave_path:
        io.write_waveforms(wave_path, result)
    total_ms = 1e3 * sum(result.timings_s.values())
    print(
        f"{summary['n_points']} points ({summary['n_outliers']} outliers, "
        f"{summary['n_dropped']} of {summary['n_hit_pixels']} hit pixels dropped) "
        f"-> {out}  [{total_ms:.0f} ms]"
    )
    return 0


def cmd_keys(args) -> int:
    rows = key_reference()
    if args.markdown:
        print("| key | unit | default | valid | meaning |")
        print("|---|---|---|---|---|")
        for r in rows:
            print(f"| `{r['key']}` | {r['unit']} | {r['default']} | {r['valid']} | {r['doc']} |")
    else:
        width = max(len(r["key"]) for r in rows)
        for r in rows:
            cells = f"{r['unit']:<4} {r['default']:<22} {r['valid']:<28}"
            print(f"{r['key']:<{width}}  {cells} {r['doc']}")
    return 0


def cmd_bench(args) -> int:
    if args.tradeoff:
        if not args.out:
            raise CliError("--tradeoff needs --out DIR")
        from . import tradeoff  # noqa: PLC0415

        return tradeoff.main(args.out, quick=args.quick, pixels=args.pixels)
    if args.pixels is not None:
        raise CliError("--pixels is for --tradeoff (the stage bench runs its own sizes)")
    from . import bench  # noqa: PLC0415

    return bench.main(quick=args.quick, json_path=args.json)


def cmd_app(args) -> int:
    try:
        app_main = importlib.import_module("app.main")
    except ImportError as exc:
        raise CliError(f"the app is not installed ({exc}); pip install -e '.[app]'") from None
    argv = ["--host", args.host, "--port", str(args.port)]
    if args.scene:
        argv += ["--scene", args.scene]
    return app_main.main(argv) or 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lmapd", description="Space-based LM-APD flash-lidar imaging simulator"
    )
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="simulate one flash and write its point cloud")
    sim.add_argument("scene", nargs="?", help="scene TOML file or built-in name (default: paper)")
    sim.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="override a scene key (pitch_deg, azimuth_deg, distance_m, pixels, pulse_energy_j, "
        "tnr, seed, or any dotted key such as laser.pulse_width_s); repeatable",
    )
    sim.add_argument(
        "--preset", choices=sorted(PRESETS), help="fidelity preset (sub-rays, time step)"
    )
    sim.add_argument("--out", required=True, help="point cloud file (.ply or .las, by suffix)")
    sim.add_argument("--summary", help="JSON summary file")
    sim.add_argument("--waveforms", help="waveform cube of the lit pixels (.npz or .h5)")
    sim.set_defaults(func=cmd_simulate)

    keys = sub.add_parser("keys", help="list every scene key with its unit, default and range")
    keys.add_argument("--markdown", action="store_true", help="as a Markdown table")
    keys.set_defaults(func=cmd_keys)

    bench = sub.add_parser("bench", help="median stage timings on the MRO (README table)")
    bench.add_argument("--quick", action="store_true", help="fewer repeats and sizes")
    bench.add_argument("--json", help="also write the figures to this JSON file")
    bench.add_argument(
        "--tradeoff",
        action="store_true",
        help="each preset's time against its error relative to reference (needs --out)",
    )
    bench.add_argument("--out", help="folder for tradeoff.json and tradeoff.png")
    bench.add_argument(
        "--pixels",
        type=int,
        help="array size per side for --tradeoff (default 256, the paper's; 128 with --quick)",
    )
    bench.set_defaults(func=cmd_bench)

    app = sub.add_parser("app", help="serve the browser app (127.0.0.1:8080)")
    app.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    app.add_argument("--port", type=int, default=8080)
    app.add_argument("--scene", help="scene TOML file or built-in name (default: paper)")
    app.set_defaults(func=cmd_app)

    flyaround.add_parser(sub)
    reproduce.add_parser(sub)
    sweep.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (CliError, SceneError, TargetError, FileNotFoundError) as exc:
        print(f"lmapd: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("lmapd: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug, not the user's input: one line, the trace on request
        if os.environ.get("LMAPD_DEBUG"):
            raise
        print(
            f"lmapd: internal error: {type(exc).__name__}: {exc} (a bug: please report it; "
            "LMAPD_DEBUG=1 shows the traceback)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
