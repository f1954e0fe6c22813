"""``lmapd app`` / ``python -m app``: serve the live LM-APD imaging app on 127.0.0.1:8080.

The app is engine (simcore Pipeline + view payloads, in a worker thread) + logic (state ->
scene -> runner -> state) + UI (a Vue 3 / Vuetify 3 page with vtk.js and plotly views), joined in
:class:`LmapdApp`; serving it (the door, the launcher, the addresses printed, the session
processes) is app.server's.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import logging
import os
import secrets
import signal
import sys
import time

from trame.app import get_server

import simcore
from app.engine import FRAME_BUDGET_BYTES, Engine
from app.logic import attitudes, flyaround, parts, studies
from app.logic.controller import AppLogic
from app.server import connections, security
from app.server.addresses import public_lines, start_message, trame_arguments
from app.server.children import say
from app.server.frame_memory import FrameGrants
from app.server.process import (
    HEADROOM_BYTES,
    interrupt,
    limit_address_space,
    read_token_and_watch_stdin,
    run_launcher,
    serve_until_stopped,
)
from app.state import state_keys
from app.ui.layout import build_layout

_server_ids = itertools.count()
# Sessions forked from one preloaded parent (app.server.zygote) where the system forks cleanly:
# they hold a fraction of the memory of processes of their own and start sooner (the figures:
# docs/serving.md, "How many students a machine holds"; scripts/bench_session_memory.py)
FORK_BY_DEFAULT = sys.platform.startswith("linux")


class LmapdApp:
    """Engine + logic + UI on one trame server."""

    def __init__(
        self,
        scene: simcore.Scene | None = None,
        server=None,
        engine: Engine | None = None,
        frame_budget_bytes: int = FRAME_BUDGET_BYTES,
        **logic_options,
    ):
        self.scene = scene if scene is not None else simcore.load_scene()
        self.server = server or get_server(f"lmapd-{next(_server_ids)}", client_type="vue3")
        self.engine = engine or Engine(self.scene, frame_budget_bytes=frame_budget_bytes)
        self.logic = AppLogic(self.server, self.engine, self.scene, **logic_options)
        self.uploads = self.logic.uploads  # the upload controls (a child of the logic)
        self.ui = build_layout(self.server)
        self.server.state.trame__title = "lmapd-sim"
        self.token = secrets.token_urlsafe(32)  # this launch's access token
        self.guard: security.Guard | None = None
        self.door: security.Door | None = None
        self.origins: tuple[str, ...] = ()  # a reverse proxy's addresses (--public-url)

    @property
    def state(self):
        return self.server.state

    def start(
        self,
        host: str,
        port: int,
        limits: security.Limits | None = None,
        origins: tuple[str, ...] = (),
        input_idle_s: float | None = None,
    ) -> None:
        """Serve until interrupted: no browser is opened and an idle server stays alive. Only
        the page at the printed address (it carries the access token) can connect.
        ``input_idle_s``: a launcher's session ends itself when no page has changed its scene
        this long (input that changes nothing, a ping, the same value again, does not count)."""
        trame_args = trame_arguments(host, port, self.token)
        cli = self.server.cli
        parse = cli.parse_known_args
        # trame reads sys.argv by default; give it exactly our options (sys.argv may hold
        # `lmapd app ...` or a test runner's arguments).
        cli.parse_known_args = lambda args=None, namespace=None: parse(
            trame_args if args is None else args, namespace
        )
        self.origins = origins
        self.server.controller.on_server_ready.add(self._announce)
        self.guard, self.door = security.install(
            self.server,
            token=self.token,
            host=host,
            client_keys=client_keys(),
            limits=limits,
            origins=origins,
        )
        self.guard.sync.refusals.update(self.uploads.refusals())
        if input_idle_s is not None:
            guard = self.guard
            self.server.controller.on_server_ready.add(
                lambda **_: asyncio.ensure_future(end_when_unused(guard, input_idle_s))
            )
        self.server.start(
            host=host, port=port, open_browser=False, timeout=0, show_connection_info=False
        )

    def _announce(self, **_) -> None:
        host = self.server.server_options.host
        lines = start_message(host, self.server.port, self.token)
        say(*lines, *public_lines(self.origins, self.token))


SESSION_ENDED = 4000  # the close code a page reads as "session ended" (app.server.proxy's)


async def end_when_unused(guard, input_idle_s: float, period_s: float = 1.0) -> None:
    """End this session once no page has changed its scene for ``input_idle_s`` (``guard``:
    the app's Guard; its ClientStateSync's ``last_change_s`` says when): its pages' websockets
    are closed as "session ended", then the process stops (SIGTERM, as the launcher's stop)."""
    while True:
        await asyncio.sleep(period_s)
        unused_s = time.monotonic() - guard.sync.last_change_s
        if unused_s >= input_idle_s:
            say(f"lmapd-sim session: no input that changed the scene for {unused_s:.0f} s: ending")
            await guard.close_all(SESSION_ENDED, b"session ended")
            os.kill(os.getpid(), signal.SIGTERM)
            return


def client_keys() -> dict[str, security.Screen]:
    """The state keys a page may set, each with the screen its values pass at the door (the
    controls' ranges are checked after, by app.state.sanitize_controls and the fly-around)."""
    keys: dict[str, security.Screen] = {key: security.scalar for key in state_keys()}
    keys["materials"] = security.mapping_of_names
    keys.update({key: security.scalar for key in flyaround.STATE_KEYS})
    keys.update({key: security.scalar for key in parts.STATE_KEYS})
    keys.update({key: security.scalar for key in studies.STATE_KEYS})
    keys.update({key: security.scalar for key in attitudes.STATE_KEYS})
    keys.update(
        {
            "fly_playing": security.scalar,
            "fly_track": security.boolean,  # the pose track's switch
            "main_drawer": security.boolean,
            "upload_file": security.file_upload,
            "upload_scale": security.scalar,
            "target_choice": security.scalar,
            "upload_error": security.cleared,
            "error_message": security.cleared,
            "input_message": security.cleared,
            "attitudes_message": security.cleared,
        }
    )
    return keys


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="lmapd app", description="Serve the live LM-APD imaging app (no browser is opened)."
    )
    parser.add_argument("--host", default="127.0.0.1", help="interface to listen on")
    parser.add_argument("--port", type=int, default=8080, help="TCP port (0: any free port)")
    parser.add_argument(
        "--scene", default=None, help="scene TOML file or built-in name (default: paper)"
    )
    parser.add_argument(
        "--no-preview",
        action="store_true",
        help="always wait for the fidelity preset's frame (no quick preview first; for comparison)",
    )
    parser.add_argument(
        "--studies",
        default=None,
        metavar="DIR",
        help="a folder of finished design studies (lmapd design --out DIR/NAME) for the Design "
        "panel to open",
    )
    parser.add_argument(
        "--shared",
        action="store_true",
        help="one process and one scene for every tab (default: each tab its own session)",
    )
    parser.add_argument(
        "--max-sessions",
        type=int,
        default=None,
        help="sessions open at once (default: as many as fit in the memory cap, at most 30, a "
        "class)",
    )
    parser.add_argument(
        "--memory-cap-mb",
        type=float,
        default=None,
        help="no new session while the sessions' processes use this much memory (default: 3/4 "
        "of the memory available at start)",
    )
    parser.add_argument(
        "--idle-s",
        type=float,
        default=60.0,
        help="a session whose page has been closed this long ends (default 60 s)",
    )
    parser.add_argument(
        "--frame-memory-mb",
        type=float,
        default=FRAME_BUDGET_BYTES / 2**20,
        help="a frame estimated to take more memory is refused before it runs; each tab's "
        "session process is limited to its size after start plus this and 1 GB of headroom "
        f"(default {FRAME_BUDGET_BYTES / 2**20:g} MB)",
    )
    parser.add_argument(
        "--frames-in-flight-mb",
        type=float,
        default=None,
        help="the heavy frames being computed in all tabs' sessions together may take this much "
        "memory, by their estimates: a frame that does not fit waits its turn (its page says "
        "how many frames are ahead), one over it is refused (default: the memory cap less the "
        "sessions' own size, at least one --frame-memory-mb; beside --memory-cap-mb, which "
        "admits new sessions)",
    )
    parser.add_argument(
        "--public-url",
        action="append",
        default=[],
        metavar="URL",
        help="the address a reverse proxy serves the app at (https://NAME): its pages may "
        "connect, and it is printed as an address to open; repeatable (docs: serving)",
    )
    parser.add_argument(
        "--input-idle-min",
        type=float,
        default=30.0,
        help="a session whose page has changed nothing (no control moved) this long ends, even "
        "with the page open (default 30 min)",
    )
    parser.add_argument(
        "--max-age-h", type=float, default=8.0, help="a session ends this old (default 8 h)"
    )
    parser.add_argument(
        "--no-spare", action="store_true", help="start no process ahead of the next tab"
    )
    sessions = parser.add_mutually_exclusive_group()
    sessions.add_argument(
        "--fork-sessions",
        action="store_true",
        help="fork each tab's session from one parent process that has loaded the app once "
        "(quicker to start, less memory; the default on Linux)",
    )
    sessions.add_argument(
        "--process-sessions",
        action="store_true",
        help="start each tab's session as a process of its own (the default where processes "
        "cannot be forked: not Linux)",
    )
    # a session's process (started by the launcher): its token is the first line of stdin,
    # and it stops when stdin closes (the launcher is gone)
    parser.add_argument("--token-stdin", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    args.fork_sessions = not args.process_sessions and (args.fork_sessions or FORK_BY_DEFAULT)
    return args


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``lmapd app`` and ``python -m app``; returns the exit status."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    connections.shorten_server_logs()  # one line per malformed request, never the request
    connections.raise_open_file_limit()  # idle sockets must not run a server out of files
    if not args.shared:
        return run_launcher(args)
    try:
        token = read_token_and_watch_stdin() if args.token_stdin else None
        scene = simcore.load_scene(args.scene)
        budget = int(max(1.0, args.frame_memory_mb) * 2**20)
        app = LmapdApp(
            scene,
            previews=not args.no_preview,
            studies_dir=args.studies,
            frame_budget_bytes=budget,
        )
    except (simcore.SceneError, simcore.TargetError, OSError, ValueError) as exc:
        print(f"lmapd app: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # stopped while starting (a session's launcher went away)
        return 0
    if token is not None:
        app.token = token
        app.logic.frame_grants = FrameGrants.from_environment(token)  # the launcher's budget
        signal.signal(signal.SIGTERM, interrupt)  # the launcher stops its sessions gracefully
        limit_address_space(budget + HEADROOM_BYTES)  # one session cannot take the machine
    origins = tuple(args.public_url)
    input_idle_s = max(1.0, 60.0 * args.input_idle_min) if token is not None else None

    def serve() -> None:
        app.start(args.host, args.port, origins=origins, input_idle_s=input_idle_s)

    return serve_until_stopped(serve, args)
