"""``lmapd target-info``: a target's parts (name, triangles, area share, material, transparent),
size and the distance at which it fills the field of view.

lmapd target-info MESH_OR_NAME [--set target.KEY=VALUE ...] [--json]
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from .common import parse_sets, say


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``target-info`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    info = subparsers.add_parser(
        "target-info", help="list a mesh's or built-in target's parts and materials"
    )
    info.add_argument("mesh", metavar="MESH_OR_NAME", help="a mesh file or a built-in target")
    info.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="a scene key (target.size_m, target.scale_m_per_unit, target.material_map, "
        "target.alpha_threshold, target.materials, receive.fov_rad); repeatable",
    )
    info.add_argument("--json", action="store_true", help="print the table as JSON")
    info.set_defaults(func=run_cli)
    return info


def run_cli(args: argparse.Namespace) -> int:
    """Print the target's parts table; exit status 0. User errors raise."""
    import warnings  # noqa: PLC0415

    from ..scene import Scene, validate, with_overrides  # noqa: PLC0415
    from ..target import (  # noqa: PLC0415
        fov_fill_distance_m,
        load_target,
        parts_table,
        with_materials,
    )

    scene = with_overrides(Scene(), {"target.mesh": args.mesh, **parse_sets(args.set)})
    validate(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the notes are printed below
        model = with_materials(load_target(scene.target), scene.target.materials)
    rows = parts_table(model)
    fill_m = fov_fill_distance_m(model.radius_m, scene.receive.fov_rad)
    if args.json:
        say(
            json.dumps(
                {
                    "name": model.name,
                    "source": model.source,
                    "credit": model.credit,
                    "extents_m": [float(x) for x in model.extents_m],
                    "fov_fill_distance_m": fill_m,
                    "parts": rows,
                    "notes": list(model.notes),
                },
                indent=1,
            )
        )
        return 0
    x, y, z = model.extents_m
    say(f"{model.name}  ({model.source})")
    if model.credit:
        say(f"credit: {model.credit}")
    say(
        f"size: {x:.3g} x {y:.3g} x {z:.3g} m, {sum(model.part_triangles)} triangles; fills the "
        f"{scene.receive.fov_rad:g} rad field of view at {fill_m:.4g} m"
    )
    width = max(len("part"), *(len(r["name"]) for r in rows))
    say(f"{'part':<{width}}  {'triangles':>9}  {'area':>6}  {'material':<14} transparent")
    for r in rows:
        material = r["material"] + ("" if r["matched"] else " (default)")
        say(
            f"{r['name']:<{width}}  {r['triangles']:>9}  {100 * r['area_share']:>5.1f}%  "
            f"{material:<14} {'yes' if r['transparent'] else 'no'}"
        )
    for note in model.notes:
        say(f"warning: {note}")
    return 0
