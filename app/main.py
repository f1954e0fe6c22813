"""``lmapd app`` / ``python -m app``: serve the live LM-APD imaging app on 127.0.0.1:8080.

The app is engine (simcore Pipeline + view payloads, in a worker thread) + logic (state ->
scene -> runner -> state) + UI (a Vue 3 / Vuetify 3 page with vtk.js and plotly views).
"""

from __future__ import annotations

import argparse
import itertools
import logging
import sys

from trame.app import get_server

import simcore
from app.engine import Engine
from app.limits import cap_websocket_messages
from app.logic.controller import AppLogic
from app.logic.upload import TargetUploads
from app.ui.layout import build_layout

_server_ids = itertools.count()


class LmapdApp:
    """Engine + logic + UI on one trame server."""

    def __init__(
        self,
        scene: simcore.Scene | None = None,
        server=None,
        engine: Engine | None = None,
        **logic_options,
    ):
        self.scene = scene if scene is not None else simcore.load_scene()
        self.server = server or get_server(f"lmapd-{next(_server_ids)}", client_type="vue3")
        self.engine = engine or Engine(self.scene)
        self.logic = AppLogic(self.server, self.engine, self.scene, **logic_options)
        self.uploads = TargetUploads(self.logic, self.server)
        self.ui = build_layout(self.server)
        self.server.state.trame__title = "lmapd-sim"

    @property
    def state(self):
        return self.server.state

    def start(self, host: str, port: int) -> None:
        """Serve until interrupted: no browser is opened and an idle server stays alive."""
        trame_args = ["--host", host, "--port", str(port), "--server", "--timeout", "0"]
        cli = self.server.cli
        parse = cli.parse_known_args
        # trame reads sys.argv by default; give it exactly our options (sys.argv may hold
        # `lmapd app ...` or a test runner's arguments).
        cli.parse_known_args = lambda args=None, namespace=None: parse(
            trame_args if args is None else args, namespace
        )
        self.server.controller.on_server_ready.add(self._announce)
        cap_websocket_messages()
        self.server.start(
            host=host, port=port, open_browser=False, timeout=0, show_connection_info=False
        )

    def _announce(self, **_) -> None:
        for line in start_message(self.server.server_options.host, self.server.port):
            print(line, flush=True)


LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def start_message(host: str, port: int) -> list[str]:
    """What the server prints once it listens: its address, and a warning if other machines can
    reach it (a --host other than the loopback interface)."""
    lines = [f"lmapd-sim app: http://{host}:{port}/  (Ctrl+C stops it)"]
    if host not in LOOPBACK_HOSTS:
        lines.append(
            f"lmapd-sim app: warning: listening on {host}, not only on this machine: anyone who "
            "can reach this port can drive the simulator and upload meshes (no authentication)"
        )
    return lines


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="lmapd app", description="Serve the live LM-APD imaging app (no browser is opened)."
    )
    parser.add_argument("--host", default="127.0.0.1", help="interface to listen on")
    parser.add_argument("--port", type=int, default=8080, help="TCP port (0: any free port)")
    parser.add_argument(
        "--scene", default=None, help="scene TOML file or built-in name (default: paper)"
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``lmapd app`` and ``python -m app``; returns the exit status."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        scene = simcore.load_scene(args.scene)
        app = LmapdApp(scene)
    except (simcore.SceneError, simcore.TargetError, OSError) as exc:
        print(f"lmapd app: {exc}", file=sys.stderr)
        return 2
    try:
        app.start(args.host, args.port)
    except OSError as exc:  # port in use, bad host
        print(f"lmapd app: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    return 0
