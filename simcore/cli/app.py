"""``lmapd app``: serve the browser app (the ``app`` package, installed with ``.[app]``).

lmapd app [--host 127.0.0.1] [--port 8080] [--scene SCENE] [--shared]
          [--max-sessions N] [--memory-cap-mb MB] [--idle-s S] [--input-idle-min MIN]
          [--max-age-h H] [--frame-memory-mb MB] [--frames-in-flight-mb MB]
          [--public-url URL ...] [--no-spare]
          [--fork-sessions | --process-sessions] [--no-preview] [--studies DIR]
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path
from typing import Any

from .common import CliError


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``app`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    app = subparsers.add_parser("app", help="serve the browser app (127.0.0.1:8080)")
    app.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    app.add_argument("--port", type=int, default=8080)
    app.add_argument("--scene", help="scene TOML file or built-in name (default: paper)")
    app.add_argument(
        "--shared", action="store_true", help="one scene for every tab (default: one per tab)"
    )
    app.add_argument("--max-sessions", type=int, help="sessions at once (default: from memory)")
    app.add_argument("--memory-cap-mb", type=float, help="the sessions' memory cap [MB]")
    app.add_argument("--idle-s", type=float, help="a closed page's session ends after this [s]")
    app.add_argument(
        "--input-idle-min",
        type=float,
        help="a session whose page changes nothing this long ends, open or not [min] (default 30)",
    )
    app.add_argument("--max-age-h", type=float, help="a session ends this old [h] (default 8)")
    app.add_argument(
        "--frame-memory-mb",
        type=float,
        help="a frame estimated to need more memory is refused [MB] (default 1536)",
    )
    app.add_argument(
        "--frames-in-flight-mb",
        type=float,
        help="the heavy frames of every session together, by their estimates: more wait their "
        "turn [MB] (default: the memory cap less the sessions' own size)",
    )
    app.add_argument(
        "--public-url",
        action="append",
        metavar="URL",
        help="the address a reverse proxy serves the app at (https://NAME); repeatable",
    )
    app.add_argument("--no-spare", action="store_true", help="start no process ahead")
    sessions = app.add_mutually_exclusive_group()
    sessions.add_argument(
        "--fork-sessions",
        action="store_true",
        help="fork the sessions from one preloaded parent (quicker, less memory; the default "
        "on Linux)",
    )
    sessions.add_argument(
        "--process-sessions",
        action="store_true",
        help="start each session as a process of its own (the default elsewhere)",
    )
    app.add_argument(
        "--no-preview", action="store_true", help="always wait for the preset's frame (no preview)"
    )
    app.add_argument(
        "--studies",
        metavar="DIR",
        help="a folder of finished design studies (lmapd design --out DIR/NAME) for the app's "
        "Design panel",
    )
    app.set_defaults(func=run_cli)
    return app


def run_cli(args: argparse.Namespace) -> int:
    """Serve the app until it is stopped; its exit status."""
    versions = importlib.import_module("app.server.versions")  # standard library only
    try:
        versions.check_framework_versions()  # before the patches of the framework are imported
    except versions.FrameworkVersionError as exc:
        raise CliError(str(exc)) from None
    try:
        app_main = importlib.import_module("app.main")
    except ImportError as exc:
        raise CliError(f"the app is not installed ({exc}); {versions.INSTALL_HINT}") from None
    argv = ["--host", args.host, "--port", str(args.port)]
    if args.scene:
        argv += ["--scene", args.scene]
    if args.studies:
        if not Path(args.studies).is_dir():
            raise CliError(f"--studies {args.studies!r} is not a folder")
        argv += ["--studies", args.studies]
    for url in args.public_url or []:
        argv += ["--public-url", url]
    options = ("max_sessions", "memory_cap_mb", "idle_s", "input_idle_min", "max_age_h")
    for option in (*options, "frame_memory_mb", "frames_in_flight_mb"):
        value = getattr(args, option, None)
        if value is not None:
            argv += ["--" + option.replace("_", "-"), str(value)]
    argv += ["--shared"] if args.shared else []
    argv += ["--no-spare"] if args.no_spare else []
    argv += ["--fork-sessions"] if args.fork_sessions else []
    argv += ["--process-sessions"] if args.process_sessions else []
    argv += ["--no-preview"] if args.no_preview else []
    return app_main.main(argv) or 0
