"""The ``lmapd`` command: simulate one flash, list scene keys, benchmark, serve the app.

    lmapd --version
    lmapd simulate [SCENE.toml | --scene SCENE.toml] [--set NAME=VALUE ...] --out cloud.ply
                   [--summary summary.json] [--waveforms waveforms.npz]
    lmapd keys [--markdown]
    lmapd targets
    lmapd target-info MESH_OR_NAME [--set target.KEY=VALUE ...] [--json]
    lmapd bench [--quick] [--json FILE] [--tradeoff --out DIR [--pixels N]]
    lmapd app [--host 127.0.0.1] [--port 8080] [--scene SCENE]
    lmapd flyaround [SCENE.toml] [--set NAME=VALUE ...] --out DIR [--interval-s 300]
                    [--duration-s SECONDS] [--j2]
    lmapd reproduce --out DIR [--quick] [--seed N]
    lmapd sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N]
    lmapd design STUDY.toml --out DIR [--trials N] [--workers N | --scheduler ADDRESS] [--resume]
    lmapd compare [SCENE.toml] [--set NAME=VALUE ...] --out DIR [--quick] [--p-detect 0.95]
    lmapd atlas [SCENE.toml] [--set NAME=VALUE ...] --out DIR [--step-deg 10] [--metric f_score]

One module per subcommand (``add_parser`` registers it, ``run_cli`` runs it), ``common`` for what
they share. Errors in the user's input (unknown key, value out of range, missing or broken file)
print one message naming what is wrong and exit with status 2; no output file is left
half-written. Nothing outside this package imports it: it is the front end of the library.
"""

from __future__ import annotations

import argparse
import os
import sys

from . import (
    app,
    atlas,
    bench,
    compare,
    design,
    flyaround,
    keys,
    reproduce,
    simulate,
    sweep,
    target_info,
    targets,
)
from .common import EXIT_USAGE, CliError, merge_scene_option, one_line, say

__all__ = ["EXIT_USAGE", "CliError", "build_parser", "main", "run", "say"]

# in --help's order
SUBCOMMANDS = (
    simulate,
    keys,
    targets,
    target_info,
    bench,
    app,
    flyaround,
    reproduce,
    sweep,
    design,
    compare,
    atlas,
)
# commands after which the process ends without the interpreter's teardown (unloading numpy,
# scipy and the rest takes ~0.1 s once the work is done): they leave no thread that must finish,
# no child process and no open file behind (their outputs are written and renamed into place)
QUICK_EXIT = ("simulate", "keys")


def build_parser() -> argparse.ArgumentParser:
    """The ``lmapd`` parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="lmapd", description="Space-based LM-APD flash-lidar imaging simulator"
    )
    parser.add_argument(
        "--version", action=_VersionAction, help="print the installed version and exit"
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for module in SUBCOMMANDS:
        command = module.add_parser(sub)
        command.add_argument(
            "--threads",
            type=int,
            metavar="N",
            help="threads per frame (default: the cores this process may use, or "
            "$LMAPD_THREADS); results do not depend on it",
        )
    return parser


def package_version() -> str:
    """The installed distribution's version (its metadata), or the source tree's when the package
    runs uninstalled."""
    from importlib import metadata  # noqa: PLC0415  (only for --version)

    try:
        return metadata.version("lmapd-sim")
    except metadata.PackageNotFoundError:
        from .._version import __version__  # noqa: PLC0415

        return __version__


class _VersionAction(argparse.Action):
    """``--version``: the version read from the package metadata only when asked for (``action=
    "version"`` would need it while the parser is built, at every command's start)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, **kw):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"lmapd {package_version()}")
        parser.exit()


def _user_errors() -> tuple[type[BaseException], ...]:
    """The exception types that are the user's input, not a bug (imported when needed)."""
    from ..scene import SceneError  # noqa: PLC0415
    from ..target import TargetError  # noqa: PLC0415  (loaded by then if it could be raised)

    return (CliError, SceneError, TargetError, FileNotFoundError)


def _set_threads(n: int | None) -> None:
    """``--threads N``: threads per frame for this command."""
    if n is None:
        return
    if n < 1:
        raise CliError(f"--threads {n}: give a whole number >= 1")
    from ..parallel import THREADS_ENV, set_threads  # noqa: PLC0415  (only when asked for)

    set_threads(n)
    os.environ[THREADS_ENV] = str(n)  # and the processes it starts (the app's sessions)


def main(argv: list[str] | None = None) -> int:
    """Run ``lmapd`` with ``argv`` (default ``sys.argv[1:]``); the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        merge_scene_option(args)
        _set_threads(getattr(args, "threads", None))
        return args.func(args)
    except KeyboardInterrupt:
        say("lmapd: interrupted", error=True)
        return 130
    except Exception as exc:
        if isinstance(exc, _user_errors()):
            say(f"lmapd: error: {one_line(str(exc))}", error=True)
            return EXIT_USAGE
        if isinstance(exc, OSError) and exc.strerror:  # the system refused a file: name it
            where = f"{exc.filename}: " if exc.filename is not None else ""
            say(f"lmapd: error: {one_line(where + exc.strerror)}", error=True)
            return EXIT_USAGE
        if os.environ.get("LMAPD_DEBUG"):  # a bug, not the user's input: one line, or the trace
            raise
        say(
            f"lmapd: internal error: {type(exc).__name__}: {one_line(str(exc))} (a bug: please "
            "report it; LMAPD_DEBUG=1 shows the traceback)",
            error=True,
        )
        return 1


def run() -> None:
    """The ``lmapd`` script: :func:`main` on the command line, then exit with its status (at once
    after the commands of QUICK_EXIT, once the output streams are flushed)."""
    argv = sys.argv[1:]
    status = main(argv)
    if argv and argv[0] in QUICK_EXIT:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    sys.exit(status)
