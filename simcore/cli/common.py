"""What every ``lmapd`` subcommand shares: the user-error type, output on stdout, ``--set`` parsing,
the scene from the arguments and the checks of output paths.

Light on purpose: the subcommand modules import this at ``lmapd --help`` time, so anything heavy
(the imaging chain, matplotlib, Dask) is imported inside the function that needs it.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

EXIT_USAGE = 2  # [-] exit status of a user error (argparse's own)


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def say(text: str, error: bool = False) -> None:
    """Command output: the one place the commands write from (stdout; stderr for ``error``)."""
    print(text, file=sys.stderr if error else sys.stdout)


def add_scene_argument(parser: argparse.ArgumentParser) -> None:
    """The optional positional SCENE (a TOML file or a built-in name), or the same as ``--scene``
    (:func:`merge_scene_option` joins the two once parsed)."""
    parser.add_argument(
        "scene", nargs="?", help="scene TOML file or built-in name (default: paper)"
    )
    parser.add_argument(
        "--scene",
        dest="scene_option",
        metavar="SCENE",
        help="the same as the positional SCENE (give one or the other)",
    )


def merge_scene_option(args: argparse.Namespace) -> None:
    """Move ``--scene SCENE`` into ``args.scene`` (the positional's place); CliError when both are
    given and differ."""
    option = getattr(args, "scene_option", None)
    if option is None:
        return
    if args.scene is not None and args.scene != option:
        raise CliError(
            f"two scenes given: {args.scene!r} and --scene {option!r}; give the scene once, "
            "as SCENE or as --scene SCENE"
        )
    args.scene = option


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
    """``path`` as a Path if its suffix is one of ``suffixes``, it is not a folder and its folder
    is a folder (None if no path was given); CliError naming the option ``what`` otherwise."""
    if path is None:
        return None
    from ..tomlfile import clip  # noqa: PLC0415

    p = Path(path)
    shown = repr(clip(path))
    if p.suffix.lower() not in suffixes:
        raise CliError(f"{what} {shown}: unsupported format; use {' or '.join(suffixes)}")
    try:
        if p.is_dir():
            raise CliError(f"{what} {shown} is a folder; give a file name")
        parent = p.parent
        if not parent.exists():
            raise CliError(f"{what} {shown}: folder {clip(str(parent))!r} does not exist")
        if not parent.is_dir():
            raise CliError(f"{what} {shown}: {clip(str(parent))!r} is a file, not a folder")
    except OSError as exc:
        raise CliError(f"{what} {shown}: unusable path ({exc.strerror})") from None
    return p


@contextlib.contextmanager
def staged_outputs(outputs: dict[str, Path | None]) -> Iterator[dict[str, Path]]:
    """Write several output files all or none.

    Before any work, a hidden temporary file is created next to each output (so an unwritable
    place fails at once, naming its option); the block writes into those; on success each is
    renamed onto its output, the last one last (the summary, which describes the others). On an
    error nothing is left: no temporary file, no new output. Stale temporary files of killed runs
    in those folders are removed first.

    Parameters
    ----------
    outputs : dict
        Option (``--out``) -> its output path, or None if the option was not given; in the order
        of renaming.

    Yields
    ------
    dict
        Option -> the temporary path to write.
    """
    from .. import io  # noqa: PLC0415
    from ..tomlfile import clip  # noqa: PLC0415

    staged: dict[str, Path] = {}
    targets = {k: v for k, v in outputs.items() if v is not None}
    try:
        for option, path in targets.items():
            io.remove_stale_parts(path.parent)
            if path.exists() and not os.access(path, os.W_OK):
                raise CliError(f"{option} {clip(str(path))!r} is read-only")
            try:
                staged[option] = io.part_path(path)
            except OSError as exc:
                raise CliError(
                    f"{option} {clip(str(path))!r}: cannot write there ({exc.strerror})"
                ) from None
        yield staged
        done = []
        try:
            for option, tmp in staged.items():
                os.replace(tmp, targets[option])
                done.append(targets[option])
        except OSError:
            for path in done:  # none rather than a mix of new and old outputs
                with contextlib.suppress(OSError):
                    path.unlink()
            raise
    finally:
        for tmp in staged.values():
            with contextlib.suppress(OSError):
                tmp.unlink()


def add_cluster_options(parser: argparse.ArgumentParser, what: str) -> None:
    """``--scheduler ADDRESS`` and ``--workers N``: where a command's frames run (``what``)."""
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"a running Dask scheduler for the {what}, tcp://HOST:8786 (default: a local cluster)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes of the local cluster (default: the number of cores); "
        f"0 runs the {what} in this process without Dask",
    )


def check_cluster_options(args: argparse.Namespace) -> None:
    """One message for a --scheduler with --workers, or fewer than 0 workers."""
    if args.scheduler and args.workers is not None:
        raise CliError("--workers sizes the local cluster; with --scheduler give no --workers")
    if args.workers is not None and args.workers < 0:
        raise CliError(f"--workers {args.workers}: give a number >= 0")


def one_line(text: str) -> str:
    """An error message as one line: control characters escaped, each run of more than
    ``tomlfile.MAX_QUOTE_CHARS`` characters without a space clipped, the whole at most about
    four times that."""
    from ..tomlfile import MAX_QUOTE_CHARS, clip  # noqa: PLC0415

    flat = "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)
    words = [clip(w) for w in flat.split(" ")]
    return clip(" ".join(words), 4 * MAX_QUOTE_CHARS)
