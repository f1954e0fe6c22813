"""What every ``lmapd`` subcommand shares: the user-error type, output on stdout, ``--set`` parsing,
the scene from the arguments and the checks of output paths.

Light on purpose: the subcommand modules import this at ``lmapd --help`` time, so anything heavy
(the imaging chain, matplotlib, Dask) is imported inside the function that needs it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

EXIT_USAGE = 2  # [-] exit status of a user error (argparse's own)


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def say(text: str) -> None:
    """Command output on stdout: the one place the subcommands' handlers write from."""
    print(text)


def add_scene_argument(parser: argparse.ArgumentParser) -> None:
    """The optional positional SCENE (a TOML file or a built-in name)."""
    parser.add_argument(
        "scene", nargs="?", help="scene TOML file or built-in name (default: paper)"
    )


def parse_sets(assignments: list[str] | None) -> dict[str, Any]:
    """The ``--set NAME=VALUE`` overrides, in the order given (a later one wins)."""
    from ..scene import parse_assignment  # noqa: PLC0415  (keeps --help fast)

    return dict(parse_assignment(s) for s in assignments or [])


def scene_from_args(args: argparse.Namespace):
    """The scene of ``args.scene`` with ``--preset`` (if any) and the ``--set`` overrides."""
    from ..scene import load_scene, with_overrides  # noqa: PLC0415

    scene = load_scene(args.scene)
    overrides = parse_sets(args.set)
    if getattr(args, "preset", None):
        overrides = {"preset": args.preset, **overrides}
    return with_overrides(scene, overrides)


def check_output(path: str | None, suffixes, what: str) -> Path | None:
    """``path`` as a Path if its suffix is one of ``suffixes`` and its folder exists (None if no
    path was given); CliError naming the option ``what`` otherwise."""
    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise CliError(f"{what} {path!r}: unsupported format; use {' or '.join(suffixes)}")
    if not p.parent.exists():
        raise CliError(f"{what} {path!r}: folder {str(p.parent)!r} does not exist")
    return p
