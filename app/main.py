"""``lmapd app`` / ``python -m app``: serve the live LM-APD imaging app on 127.0.0.1:8080.

The app is engine (simcore Pipeline + view payloads, in a worker thread) + logic (state ->
scene -> runner -> state) + UI (a Vue 3 / Vuetify 3 page with vtk.js and plotly views).
"""

from __future__ import annotations

import argparse
import itertools
import logging
import os
import secrets
import signal
import sys
import threading
from collections.abc import Callable

from trame.app import get_server

import simcore
from app.engine import FRAME_BUDGET_BYTES, Engine
from app.logic import flyaround, parts, studies
from app.logic.controller import AppLogic
from app.server import connections, security
from app.state import STATE_KEYS
from app.ui.layout import build_layout

_server_ids = itertools.count()


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
    ) -> None:
        """Serve until interrupted: no browser is opened and an idle server stays alive. Only
        the page at the printed address (it carries the access token) can connect."""
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
        self.server.start(
            host=host, port=port, open_browser=False, timeout=0, show_connection_info=False
        )

    def _announce(self, **_) -> None:
        host = self.server.server_options.host
        lines = start_message(host, self.server.port, self.token)
        for line in lines + public_lines(self.origins, self.token):
            print(line, flush=True)


LOOPBACK_HOSTS = security.LOOPBACK_NAMES


def trame_arguments(host: str, port: int, token: str) -> list[str]:
    """The options the trame server is started with: no browser, no idle time-out, this launch's
    token as its key (never the framework's public default). ``--authKey=TOKEN`` in one word: a
    URL-safe token begins with "-" one time in 64, and would be read as an option."""
    return ["--host", host, "--port", str(port), "--server", "--timeout", "0", f"--authKey={token}"]


def client_keys() -> dict[str, security.Screen]:
    """The state keys a page may set, each with the screen its values pass at the door (the
    controls' ranges are checked after, by app.state.sanitize_controls and the fly-around)."""
    keys: dict[str, security.Screen] = {key: security.scalar for key in STATE_KEYS}
    keys["materials"] = security.mapping_of_names
    keys.update({key: security.scalar for key in flyaround.STATE_KEYS})
    keys.update({key: security.scalar for key in parts.STATE_KEYS})
    keys.update({key: security.scalar for key in studies.STATE_KEYS})
    keys.update(
        {
            "fly_playing": security.scalar,
            "main_drawer": security.boolean,
            "upload_file": security.file_upload,
            "upload_scale": security.scalar,
            "target_choice": security.scalar,
            "upload_error": security.cleared,
            "error_message": security.cleared,
            "input_message": security.cleared,
        }
    )
    return keys


def app_address(host: str, port: int, token: str) -> str:
    """The address to open: the page with this launch's access token."""
    name = f"[{host}]" if ":" in host else host
    return f"http://{name}:{port}/?token={token}"


def lan_addresses(host: str) -> list[str]:
    """The addresses other machines can open when the server listens on every interface (``host``
    0.0.0.0 or ::): this machine's IPv4 addresses (and global IPv6 ones for ::), loopback and
    link-local ones left out."""
    if host not in security.WILDCARD_HOSTS:
        return []
    import ipaddress  # noqa: PLC0415  (only on a wildcard host)
    import socket  # noqa: PLC0415

    import psutil  # noqa: PLC0415

    families = (socket.AF_INET,) if host == "0.0.0.0" else (socket.AF_INET, socket.AF_INET6)
    found = []
    for addrs in psutil.net_if_addrs().values():
        for addr in addrs:
            if addr.family not in families:
                continue
            try:
                ip = ipaddress.ip_address(addr.address.split("%")[0])
            except ValueError:
                continue
            if ip.is_loopback or ip.is_link_local or ip.is_unspecified or ip.is_multicast:
                continue
            if str(ip) not in found:
                found.append(str(ip))
    return found


def start_message(host: str, port: int, token: str, lan: list[str] | None = None) -> list[str]:
    """What the server prints once it listens: the address to open (on one line, with the access
    token), and a warning if other machines can reach it (a --host other than loopback). On a
    wildcard host (0.0.0.0) the first address is this machine's loopback one, then one line for
    each of its LAN addresses (``lan``: found by :func:`lan_addresses` if None), which are what
    other machines open."""
    if host in security.WILDCARD_HOSTS:
        lan = lan_addresses(host) if lan is None else lan
        lines = [f"lmapd-sim app: {app_address('127.0.0.1', port, token)}  (Ctrl+C stops it)"]
        lines += [f"lmapd-sim app: on the network: {app_address(ip, port, token)}" for ip in lan]
        if not lan:
            lines.append("lmapd-sim app: no network address found (only this machine can open it)")
    else:
        lines = [f"lmapd-sim app: {app_address(host, port, token)}  (Ctrl+C stops it)"]
    if host not in LOOPBACK_HOSTS:
        lines.append(
            f"lmapd-sim app: warning: listening on {host}, not only on this machine: anyone who "
            "can reach this port and has the address above (its token) can drive the simulator "
            "and upload meshes"
        )
    return lines


def public_lines(origins: tuple[str, ...], token: str) -> list[str]:
    """The addresses a reverse proxy serves the app at, each with the token, to print."""
    lines = []
    for url in origins:
        origin = security.normal_origin(url)
        if origin is None:
            lines.append(f"lmapd-sim app: warning: --public-url {url!r} is no http(s) address")
            continue
        base = url.strip().rstrip("/")
        lines.append(f"lmapd-sim app: through the proxy: {base}/?token={token}")
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
        help="a session whose page has sent nothing (no control moved) this long ends, even with "
        "the page open (default 30 min)",
    )
    parser.add_argument(
        "--max-age-h", type=float, default=8.0, help="a session ends this old (default 8 h)"
    )
    parser.add_argument(
        "--no-spare", action="store_true", help="start no process ahead of the next tab"
    )
    parser.add_argument(
        "--fork-sessions",
        action="store_true",
        help="fork each tab's session from one parent process that has loaded the app once "
        "(quicker to start, less memory; Linux)",
    )
    # a session's process (started by the launcher): its token is the first line of stdin,
    # and it stops when stdin closes (the launcher is gone)
    parser.add_argument("--token-stdin", action="store_true", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def read_token_and_watch_stdin() -> str:
    """A session process's token (the first line of stdin); then stop the process (as Ctrl+C
    would) when stdin closes, so that no process outlives its launcher."""
    token = sys.stdin.readline().strip()
    if not token:
        raise ValueError("no token on stdin")

    def watch() -> None:
        while sys.stdin.readline():
            pass
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=watch, name="lmapd-stdin-watch", daemon=True).start()
    return token


HEADROOM_BYTES = 2**30  # a session's address space beyond its size at start and its frame budget


def limit_address_space(extra_bytes: int) -> int | None:
    """Limit this process's address space (``RLIMIT_AS``) to its size now plus ``extra_bytes``:
    an allocation beyond fails (MemoryError) in this process only. The limit [bytes], or None
    where it cannot be set."""
    import resource  # noqa: PLC0415  (sessions only)

    import psutil  # noqa: PLC0415

    try:
        limit = int(psutil.Process().memory_info().vms) + int(extra_bytes)
        hard = resource.getrlimit(resource.RLIMIT_AS)[1]
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (ValueError, OSError, psutil.Error):
        return None
    return limit


def _interrupt(*_) -> None:
    raise KeyboardInterrupt


def run_launcher(args: argparse.Namespace) -> int:
    """Each tab its own session: the launcher (app.server.launcher) until Ctrl+C or SIGTERM."""
    import asyncio  # noqa: PLC0415  (the launcher's loop: only without --shared)

    from app.server import launcher  # noqa: PLC0415

    mib = launcher.MIB
    caps = launcher.default_caps(
        session_rss_bytes=launcher.FORKED_SESSION_BYTES
        if args.fork_sessions
        else launcher.SESSION_RSS_BYTES,
        max_sessions=args.max_sessions,
        memory_cap_bytes=None if args.memory_cap_mb is None else int(args.memory_cap_mb * mib),
        idle_s=max(0.0, args.idle_s),
        spare=not args.no_spare,
        input_idle_s=max(1.0, 60.0 * args.input_idle_min),
        max_age_s=max(1.0, 3600.0 * args.max_age_h),
    )
    try:
        scene = simcore.load_scene(args.scene)  # the sessions' scene, checked once here
        del scene
    except (simcore.SceneError, simcore.TargetError, OSError) as exc:
        print(f"lmapd app: {exc}", file=sys.stderr)
        return 2
    token = secrets.token_urlsafe(32)
    options = ("--no-preview",) if args.no_preview else ()
    options += ("--frame-memory-mb", f"{args.frame_memory_mb:g}")
    if args.studies:
        options += ("--studies", os.path.abspath(args.studies))
    origins = tuple(args.public_url)
    door = launcher.Launcher(
        token,
        args.host,
        caps,
        scene=args.scene,
        options=options,
        origins=origins,
        zygote=launcher.zygote_command if args.fork_sessions else None,
    )

    def announce(port: int) -> None:
        for line in start_message(args.host, port, token) + public_lines(origins, token):
            print(line, flush=True)
        print(
            f"lmapd-sim app: each tab its own session: at most {caps.max_sessions} at once, "
            f"{caps.memory_cap_bytes / mib:,.0f} MB for their processes, a closed page's session "
            f"ends after {caps.idle_s:g} s, one without input after "
            f"{caps.input_idle_s / 60:g} min (--shared: one scene for every tab)",
            flush=True,
        )
        print(class_line(caps), flush=True)

    return serve_until_stopped(
        lambda: asyncio.run(launcher.serve(door, args.host, args.port, announce)), args
    )


def class_line(caps) -> str:
    """What the session cap means for a class of 30."""
    from app.server import launcher  # noqa: PLC0415  (launcher mode only)

    need_gb = launcher.MAX_DEFAULT_SESSIONS * caps.session_bytes / 1e9
    if caps.max_sessions >= launcher.MAX_DEFAULT_SESSIONS:
        return f"lmapd-sim app: room for a class of {launcher.MAX_DEFAULT_SESSIONS} tabs"
    return (
        f"lmapd-sim app: room for {caps.max_sessions} tabs, not a class of "
        f"{launcher.MAX_DEFAULT_SESSIONS} (that needs about {need_gb:.0f} GB for the sessions: "
        "--memory-cap-mb and --max-sessions set it)"
    )


def serve_until_stopped(serve: Callable[[], object], args: argparse.Namespace) -> int:
    """Run ``serve()`` until Ctrl+C; the exit status (2, with one line, if it cannot listen)."""
    try:
        serve()
    except OSError as exc:  # port in use, bad host
        print(f"lmapd app: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    return 0


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
        signal.signal(signal.SIGTERM, _interrupt)  # the launcher stops its sessions gracefully
        limit_address_space(budget + HEADROOM_BYTES)  # one session cannot take the machine
    origins = tuple(args.public_url)
    return serve_until_stopped(lambda: app.start(args.host, args.port, origins=origins), args)
