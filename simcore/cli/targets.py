"""``lmapd targets``: the built-in targets, one line each: name, size, title, credit.

lmapd targets
"""

from __future__ import annotations

import argparse
from typing import Any

from .common import say


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``targets`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    targets = subparsers.add_parser(
        "targets", help="list the built-in targets (target.mesh = NAME) with sizes and credits"
    )
    targets.set_defaults(func=run_cli)
    return targets


def run_cli(args: argparse.Namespace) -> int:
    """Print one line per built-in target, beginning with its name; exit status 0."""
    from ..target import builtin_settings, builtin_targets  # noqa: PLC0415

    names = builtin_targets()
    width = max(len(n) for n in names)
    for name in names:
        settings = builtin_settings(name)
        size = settings.get("longest_extent_m")
        size_text = f"{size:g} m" if size else "-"
        what = "calibration: target.size_m sets its size" if "shape" in settings else ""
        credit = settings.get("credit", "") or what
        say(f"{name:<{width}}  {size_text:>7}  {settings.get('name', name)}  [{credit}]")
    return 0
