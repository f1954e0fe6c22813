"""``lmapd app``: each browser tab its own scene, one app process per session behind a launcher.

trame keeps one state per server process, so every page of one app server shows the same scene:
a freshly opened page shows the last visitor's pose, and two tabs steer each other. The launcher
gives each page load its own app process (``python -m app --shared`` on 127.0.0.1 and a free
port) and proxies everything under ``/s/<session id>/`` to it:

* the door, ``GET /?token=T&<settings>`` (the printed address, or a shared link), checks the token
  (or its cookie) as the app's door does. Only a browser's navigation opens a session: a HEAD, a
  prefetch or a subresource request (``Sec-Fetch-Mode`` other than ``navigate``, an ``<img>`` or
  a ``fetch`` from another page, even one on another 127.0.0.1 port) starts nothing. A session is
  bound to the browser that opened it: its id comes with a secret in an HttpOnly, SameSite=Strict
  cookie scoped to ``/s/<id>/``, and its pages and websocket need that cookie (whoever reads the
  id off a projected address bar cannot join). The door answers with a page that moves the tab
  to ``/s/<id>/?<settings>#token=T`` (a same-site navigation, so the Strict cookie goes with it,
  even when the link was opened from another site); the page keeps the token for its share
  links and then shows only ``/`` in the address bar (app/static/link.js), so a reload
  or a shared link always opens a new session;
* under ``/s/<id>/`` only GET and HEAD, and the websocket at ``/s/<id>/ws`` (trame's page builds
  it from its own path), are passed to that session's process, with the process's own private
  token (given on its stdin, never on a command line) and origin; the websocket's ``Origin`` and
  the session's cookie are checked first, and frames are limited to wslink's chunk size (the
  process reassembles messages within ``app.server.security``'s limits and screens every call);
* an unknown or ended session gets a page saying so, with a link that starts a new one; over the
  caps (``Caps``: sessions, the processes' total memory, sessions per browser and per address) a
  503 page says how many are open;
* a session ends when its websocket has been closed for ``idle_s`` (a reload reconnects well
  within it), when its page has sent nothing for ``input_idle_s`` (even with its socket held
  open), or at ``max_age_s``; its page then says "session ended: reload for a new one". A
  process that dies is noticed and forgotten; SIGINT or SIGTERM stops every child, and a child
  whose launcher vanishes (even by SIGKILL) stops when its stdin closes;
* connections (app.server.connections): idle or partial ones are closed after 10 s, each address
  holds at most a few hundred, and refusals are logged one short line each, never with the token;
* with ``zygote`` (``lmapd app``'s default on Linux) the session processes are forked from one
  preloaded parent (app.server.zygote) instead of started afresh: they share its modules, target and
  compiled kernels.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import hashlib
import hmac
import html
import json
import logging
import os
import re
import secrets
import signal
import sys
import time
from collections.abc import Callable
from urllib.parse import quote

import aiohttp
import psutil
from aiohttp import web

from app.server import connections, security

log = logging.getLogger(__name__)

MIB = 2**20
# One session process's resident memory after its first frame with the paper scene at 256 x 256
# (354-370 MB, median 357 MB, with its preview's stages, scripts/bench_sessions.py, 2026-11-25);
# the default session cap is derived from it.
SESSION_RSS_BYTES = 370 * MIB
# A session forked from the zygote (the default on Linux): 30 such sessions and their parent held
# 3,018 MB of proportional set size after each one's first 256 x 256 frame (101 MB a session,
# the parent's share included; 7,112 MB as processes of their own; they share the parent's
# target stage: scripts/bench_session_memory.py, 2026-11-26); counted at 128 MB.
FORKED_SESSION_BYTES = 128 * MIB
MAX_DEFAULT_SESSIONS = 30  # a class
MEMORY_SHARE = 0.75  # of the memory available at start, for the children together
FRAME_BYTES = security.WS_CHUNK_BYTES + 4096  # one websocket frame: a wslink chunk and its header
CLIENT_ID = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
SESSION_ENDED = 4000  # the websocket close code of an ended session (the page says so)
NO_STORE = {"Cache-Control": "no-store"}
SESSION_ID = re.compile(r"^/s/(?P<id>[A-Za-z0-9_-]{1,64})(?P<rest>/.*)?$")
FORKED_LINE = re.compile(r"^lmapd-sim zygote: forked (?P<pid>\d+) for (?P<digest>[0-9a-f]{16})$")
SESSION_LINE = re.compile(
    r"^lmapd-sim app: http://127\.0\.0\.1:(?P<port>\d+)/\?token=(?P<token>[A-Za-z0-9_-]+)"
)
ADDRESS_LINE = re.compile(r"^lmapd-sim app: http://127\.0\.0\.1:(?P<port>\d+)/")
CHILD_HOST = "127.0.0.1"
PASSED_HEADERS = (
    "Content-Type",
    "Content-Encoding",
    "Cache-Control",
    "Expires",
    "Pragma",
    "Last-Modified",
    "ETag",
    "Location",
)


@dataclasses.dataclass(frozen=True)
class Caps:
    """The launcher's limits.

    max_sessions : sessions open at once; the warm spare counts too (at most this many processes)
    memory_cap_bytes : the children's total memory that no new session may take beyond [bytes]
    idle_s : a session whose websocket has been closed this long is stopped [s]
    spare : keep one process started ahead
    start_timeout_s : a process that has not listened after this long is given up [s]
    input_idle_s : a session whose page has sent nothing this long is stopped, socket or not [s]
    max_age_s : a session this old is stopped [s]
    per_client : sessions of one browser (its client cookie); a new one ends its oldest
    per_address : sessions of one client address other than loopback (a reverse proxy on this
        machine is loopback) [0: no limit]
    sockets_per_session : websockets open at once on one session
    session_bytes : what a session is counted at in the memory cap until it measures more [bytes]
    """

    max_sessions: int
    memory_cap_bytes: int
    idle_s: float = 60.0
    spare: bool = True
    start_timeout_s: float = 120.0
    input_idle_s: float = 1800.0
    max_age_s: float = 8 * 3600.0
    per_client: int = 3
    per_address: int = 6
    sockets_per_session: int = 4
    session_bytes: int = SESSION_RSS_BYTES


def default_caps(
    available_bytes: int | None = None,
    session_rss_bytes: int = SESSION_RSS_BYTES,
    max_sessions: int | None = None,
    memory_cap_bytes: int | None = None,
    idle_s: float = 60.0,
    spare: bool = True,
    **more,
) -> Caps:
    """The caps for this machine: the children may use ``MEMORY_SHARE`` of the memory available
    now [bytes], and as many sessions as fit in it at ``session_rss_bytes`` each (at least 1, at
    most ``MAX_DEFAULT_SESSIONS``); explicit values win; ``more``: the other fields of Caps."""
    if available_bytes is None:
        available_bytes = int(psutil.virtual_memory().available)
    if memory_cap_bytes is None:
        memory_cap_bytes = int(MEMORY_SHARE * available_bytes)
    if max_sessions is None:
        fits = memory_cap_bytes // max(1, session_rss_bytes)
        max_sessions = int(min(MAX_DEFAULT_SESSIONS, max(1, fits)))
    return Caps(
        max(1, max_sessions),
        max(0, memory_cap_bytes),
        idle_s,
        spare,
        session_bytes=session_rss_bytes,
        **more,
    )


class StartFailed(Exception):
    """A child process exited or did not listen in time."""


@dataclasses.dataclass(eq=False)
class Child:
    """One app process: its port on 127.0.0.1, its private token and its open websockets; once
    it serves a session, that session's cookie secret, its browser and its client address."""

    proc: asyncio.subprocess.Process
    port: int
    token: str
    started_s: float
    n_sockets: int = 0
    idle_since_s: float = 0.0
    drain: asyncio.Task | None = None
    secret: str = ""
    client: str = ""
    address: str = ""
    opened_s: float = 0.0
    last_input_s: float = 0.0
    pages: set = dataclasses.field(default_factory=set)  # the open page websockets

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def alive(self) -> bool:
        return self.proc.returncode is None

    def rss_bytes(self) -> int:
        """Resident memory [bytes] (0 once the process is gone); of a process forked from the
        zygote, its proportional share (PSS: the pages it shares with its parent and siblings
        split between them), which the kernel sums cheaply in ``smaps_rollup``."""
        if isinstance(self.proc, ForkedProcess):
            pss = _pss_bytes(self.pid)
            if pss is not None:
                return pss
        try:
            return int(psutil.Process(self.pid).memory_info().rss)
        except (psutil.Error, OSError):
            return 0

    @property
    def cookie(self) -> str:
        return f"lmapd-token-{self.port}={self.token}"

    @property
    def origin(self) -> str:
        return f"http://{CHILD_HOST}:{self.port}"


def child_command(scene: str | None, options: tuple[str, ...] = ()) -> list[str]:
    """The command of one session's process: the one-scene app on loopback, any free port, its
    token read from stdin (never on the command line, where other users could read it), and the
    launcher's own app ``options`` (``--no-preview``)."""
    cmd = [sys.executable, "-m", "app", "--shared", "--host", CHILD_HOST, "--port", "0"]
    cmd.append("--token-stdin")
    if scene:
        cmd += ["--scene", scene]
    return cmd + list(options)


def safe_rest(rest: str) -> bool:
    """A path inside a session that stays inside it: no dot segments, no backslashes, no
    empty segments, no control characters."""
    if not rest.startswith("/") or "\\" in rest or "//" in rest:
        return False
    if any(ord(c) < 32 or ord(c) == 127 for c in rest):
        return False
    return not any(seg in (".", "..") for seg in rest.split("/"))


def message_page(status: int, title: str, text: str, link: str, link_text: str) -> web.Response:
    """A short HTML page (never a trace): a title, a sentence, a link."""
    body = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>lmapd-sim: {html.escape(title)}</title></head>"
        "<body style='font-family: sans-serif; max-width: 40em; margin: 3em auto'>"
        f"<h1 class='launcher-title'>{html.escape(title)}</h1>"
        f"<p class='launcher-message'>{html.escape(text)}</p>"
        f"<p><a class='launcher-link' href='{html.escape(link, quote=True)}'>"
        f"{html.escape(link_text)}</a></p></body></html>"
    )
    return web.Response(
        status=status,
        text=body,
        content_type="text/html",
        headers={"Cache-Control": "no-store"},
    )


class Launcher:
    """The launcher's HTTP side and its children (see the module's docstring).

    Parameters
    ----------
    token : the launch's access token (the printed address carries it)
    host : the interface the launcher listens on (the origin check depends on it)
    caps : the limits
    scene : the scene every session starts from (a file or a built-in name; None: paper)
    command : builds a child's command from ``scene`` and ``options`` (tests may replace it)
    options : the sessions' app options (``--no-preview``)
    origins : the addresses a reverse proxy serves the launcher at (their pages may connect)
    """

    def __init__(
        self,
        token: str,
        host: str,
        caps: Caps,
        scene: str | None = None,
        command: Callable[..., list[str]] = child_command,
        options: tuple[str, ...] = (),
        origins: tuple[str, ...] = (),
        zygote: Callable[..., list[str]] | None = None,
    ):
        self.token = token
        # sessions forked from a preloaded parent (app.server.zygote): its command, or None
        self.zygote = Zygote(zygote(scene, options)) if zygote is not None else None
        self.caps = caps
        self.scene = scene
        self.command = command
        self.options = options
        self.door = security.Door(token, host, security.Limits(), origins)
        self.sessions: dict[str, Child] = {}
        self.spare: asyncio.Task | None = None
        self.n_starting = 0  # sessions being created (counted against the cap)
        self.n_refused = 0
        self.n_not_navigation = 0  # door requests that were no navigation (no session)
        self.n_foreign = 0  # session requests without that session's cookie
        self.log = connections.ShortLog(log)
        self.guard = connections.ConnectionGuard()
        self.n_reaped = 0
        self.n_start_failures = 0
        self._lock = asyncio.Lock()
        self._client: aiohttp.ClientSession | None = None
        self._reaper: asyncio.Task | None = None
        self._closing = False
        self._all: set[Child] = set()  # every child not yet stopped (sessions, spare)

    # -- the application -----------------------------------------------------------------------
    def web_app(self) -> web.Application:
        web_app = web.Application(client_max_size=64 * 1024, middlewares=[self.guard.middleware])
        web_app.router.add_route("*", "/{tail:.*}", self.handle)
        web_app.on_startup.append(self._on_startup)
        web_app.on_cleanup.append(self._on_cleanup)
        return web_app

    async def _on_startup(self, _app) -> None:
        self._client = aiohttp.ClientSession(
            auto_decompress=False,
            timeout=aiohttp.ClientTimeout(total=None, sock_connect=10),
            # closed by this side before a session's guard closes an idle one (its 10 s)
            connector=aiohttp.TCPConnector(keepalive_timeout=connections.IDLE_S / 2),
        )
        self._ensure_spare()
        self._reaper = asyncio.create_task(self._reap_forever())

    async def _on_cleanup(self, _app) -> None:
        await self.close()

    # -- requests ------------------------------------------------------------------------------
    async def handle(self, request: web.Request) -> web.StreamResponse:
        websocket = request.headers.get("Upgrade", "").lower() == "websocket"
        path = request.path
        if request.method not in ("GET", "HEAD"):
            self.log.warning("method", "refused a %s request from %s", "non-GET", request.remote)
            return web.Response(status=405, text="Method not allowed\n")
        found = SESSION_ID.match(path)
        if found:  # a session's own cookie lets in, not the token
            return await self.in_session(request, found, websocket)
        authorised, from_address = self.door.token_ok(request)
        if not authorised:
            self.door.n_refused += 1
            self.log.warning("token", "refused a request without the token from %s", request.remote)
            return web.Response(
                status=403,
                text="Forbidden: open the address that `lmapd app` printed (it carries the "
                "access token).\n",
            )
        if path not in ("/", "/index.html") or websocket:
            return web.Response(status=404, text="Not found\n")
        # the token from the address goes into the browser's cookie, on every page the door
        # answers (a streamed one sends its headers before the handler returns)
        token_cookie = self.door.cookie_name(request) if from_address else None
        response = await self.new_session(request, token_cookie)
        if token_cookie and not response.prepared:
            response.set_cookie(token_cookie, self.token, httponly=True, samesite="Strict")
        return response

    async def new_session(
        self, request: web.Request, token_cookie: str | None = None
    ) -> web.StreamResponse:
        """Start a session for a browser's navigation (the spare process if one is ready) and
        send the tab to it; anything else (HEAD, a prefetch, a subresource) starts nothing.
        ``token_cookie``: the name of the cookie that keeps the launch's token in the browser,
        if the page it answers must set it."""
        if request.method == "HEAD":
            return web.Response(status=200, content_type="text/html", headers=NO_STORE)
        problem = navigation_problem(request.headers)
        if problem is not None:
            self.n_not_navigation += 1
            self.log.warning("navigation", "no session for %s: %s", request.remote, problem)
            return message_page(
                403,
                "Open this address in a browser tab",
                "A session starts only when this address is opened in a tab of its own (not "
                "from another page's image, script or prefetch).",
                self._root_link(request),
                "Open it here",
            )
        client = request.cookies.get(self._client_cookie(request), "")
        if not CLIENT_ID.match(client):
            client = secrets.token_urlsafe(16)
        address = request.remote or ""
        problem = self.over_caps(address)
        if problem:
            return self.refuse(request, problem)
        # the tab hears at once that its session is starting (a process may take seconds when a
        # class opens together); its cookies are made now and the way in is sent when it listens
        session_id = secrets.token_urlsafe(16)
        secret = secrets.token_urlsafe(32)
        page = web.StreamResponse(status=200, headers=NO_STORE)
        page.content_type = "text/html"
        page.charset = "utf-8"
        page.set_cookie(
            session_cookie(session_id),
            secret,
            path=f"/s/{session_id}/",
            httponly=True,
            samesite="Strict",
            max_age=int(self.caps.max_age_s) + 60,
        )
        page.set_cookie(
            self._client_cookie(request), client, httponly=True, samesite="Strict", path="/"
        )
        if token_cookie:
            page.set_cookie(token_cookie, self.token, httponly=True, samesite="Strict")
        self.n_starting += 1
        try:
            ahead = self.n_starting - 1
            await page.prepare(request)
            await page.write(starting_page(ahead).encode())
            await self._make_room_for(client)
            child = await self._take_child()
        except StartFailed as exc:
            log.error("a session's process did not start: %s", exc)
            await _finish(page, start_failed_html(self._root_link(request)))
            return page
        finally:
            self.n_starting -= 1
        now = time.monotonic()
        child.secret = secret
        child.client, child.address = client, address
        child.idle_since_s = child.opened_s = child.last_input_s = now
        self.sessions[session_id] = child
        self._ensure_spare()
        log.info("session %s: process %d on port %d", session_id[:6], child.pid, child.port)
        settings = [(k, v) for k, v in request.query.items() if k != "token"]
        target = f"/s/{session_id}/" + ("?" + _query(settings) if settings else "")
        if not await _finish(page, move_html(f"{target}#token={_q(self.token)}")):
            await self.end_session(session_id, "its tab closed before the session started")
        return page

    def _client_cookie(self, request: web.Request) -> str:
        return f"lmapd-client-{security._local_port(request)}"

    async def _make_room_for(self, client: str) -> None:
        """A browser at its ``per_client`` sessions gives up its least recently used ones."""
        mine = [(c.last_input_s, sid) for sid, c in self.sessions.items() if c.client == client]
        mine.sort()
        while len(mine) >= max(1, self.caps.per_client):
            _, session_id = mine.pop(0)
            await self.end_session(session_id, "its browser opened another")

    def over_caps(self, address: str = "") -> str | None:
        """Why no session may start now for a client at ``address``, or None."""
        n_open = len(self.sessions) + self.n_starting
        if n_open >= self.caps.max_sessions:
            return (
                f"{_open(n_open)}, the most this server allows "
                f"(--max-sessions {self.caps.max_sessions})."
            )
        used = self.children_bytes() + self.n_starting * self.caps.session_bytes
        if used + self.caps.session_bytes > self.caps.memory_cap_bytes:
            return (
                f"{_open(n_open)} and use {used / MIB:,.0f} MB; another would pass the most this "
                f"server allows ({self.caps.memory_cap_bytes / MIB:,.0f} MB)."
            )
        limit = self.caps.per_address
        if limit and address and address not in security.LOOPBACK_NAMES:
            n_mine = sum(1 for c in self.sessions.values() if c.address == address)
            if n_mine >= limit:
                return f"Your computer has {n_mine} sessions open, the most it may have."
        return None

    def refuse(self, request: web.Request, problem: str) -> web.Response:
        self.n_refused += 1
        self.log.warning("caps", "refused a new session: %s", problem)
        idle = f"{self.caps.idle_s:g}"
        return message_page(
            503,
            "No session free",
            f"{problem} Close a tab of this app that you no longer use (its session ends {idle} s "
            "after), then try again; or ask whoever runs the server to start it with a higher "
            "--max-sessions.",
            self._root_link(request),
            "Try again",
        )

    @staticmethod
    def _root_link(request: web.Request) -> str:
        """The launcher's root with the request's settings (its token stays in the cookie)."""
        query = [(k, v) for k, v in request.query.items() if k != "token"]
        return "/" + ("?" + _query(query) if query else "")

    async def in_session(self, request: web.Request, found: re.Match, websocket: bool):
        session_id = found["id"]
        child = self.sessions.get(session_id)
        if child is None or not child.alive:
            if child is not None:
                self._forget(session_id)
            return message_page(
                404,
                "No such session",
                "This page's session has ended (it was closed, left idle, or the server "
                "restarted) or never existed. Each tab has a session of its own: start a new one.",
                self._root_link(request),
                "Start a new session",
            )
        given = request.cookies.get(session_cookie(session_id), "")
        if not (given and hmac.compare_digest(given.encode(), child.secret.encode())):
            self.n_foreign += 1
            self.log.warning("foreign", "refused a request for another browser's session")
            return message_page(
                403,
                "This session is another tab's",
                "Each session belongs to the browser tab that opened it. Open the address "
                "that `lmapd app` printed to start a session of your own.",
                "/",
                "Start a session of your own",
            )
        rest = found["rest"]
        if rest is None:  # /s/<id> -> /s/<id>/ (the page's relative addresses need the slash)
            query = request.query_string
            return _redirect(f"/s/{session_id}/" + (f"?{query}" if query else ""))
        if not safe_rest(rest):
            return web.Response(status=404, text="Not found\n")
        if websocket:
            if rest != security.WS_PATH:
                return web.Response(status=404, text="Not found\n")
            return await self.proxy_websocket(request, child)
        return await self.proxy_http(request, child, rest)

    async def proxy_http(self, request: web.Request, child: Child, rest: str) -> web.Response:
        query = [(k, v) for k, v in request.query.items() if k != "token"]
        url = f"{child.origin}{_path(rest)}"
        headers = {"Cookie": child.cookie}
        if "Accept-Encoding" in request.headers:
            headers["Accept-Encoding"] = request.headers["Accept-Encoding"]
        try:
            async with self._client.request(
                request.method, url, params=query, headers=headers, allow_redirects=False
            ) as answer:
                body = await answer.read()
                passed = {k: answer.headers[k] for k in PASSED_HEADERS if k in answer.headers}
                return web.Response(status=answer.status, body=body, headers=passed)
        except (aiohttp.ClientError, OSError) as exc:
            log.warning("session process %d did not answer: %s", child.pid, exc)
            return web.Response(status=502, text="The session's process did not answer\n")

    async def proxy_websocket(self, request: web.Request, child: Child) -> web.StreamResponse:
        problem = self.door.origin_problem(request)
        if problem is not None:
            self.log.warning("origin", "refused a websocket from %s: %s", request.remote, problem)
            self.door.n_refused += 1
            return web.Response(status=403, text="Forbidden\n")
        if child.n_sockets >= self.caps.sockets_per_session:
            self.log.warning("sockets", "refused a websocket: the session has %d", child.n_sockets)
            return web.Response(status=503, text="Too many connections\n")
        child.n_sockets += 1
        page = web.WebSocketResponse(max_msg_size=FRAME_BYTES, heartbeat=30.0)
        upstream = None
        try:
            try:
                upstream = await self._client.ws_connect(
                    f"{child.origin}{security.WS_PATH}",
                    headers={"Origin": child.origin, "Cookie": child.cookie},
                    max_msg_size=FRAME_BYTES,
                    compress=0,
                    autoping=True,
                )
            except (aiohttp.ClientError, OSError) as exc:
                log.warning("session process %d refused its websocket: %s", child.pid, exc)
                return web.Response(status=502, text="The session's process did not answer\n")
            await page.prepare(request)
            child.pages.add(page)
            tasks = [
                asyncio.create_task(_pump(page, upstream, child)),
                asyncio.create_task(_pump(upstream, page)),
            ]
            _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in pending:
                task.cancel()
            await asyncio.gather(*pending, return_exceptions=True)
        finally:
            child.n_sockets -= 1
            child.pages.discard(page)
            child.idle_since_s = time.monotonic()
            if upstream is not None:
                await upstream.close()
            if page.prepared:
                await page.close()
        return page

    # -- children ------------------------------------------------------------------------------
    async def start_child(self) -> Child:
        """Start one app process and wait until it listens. Raises StartFailed."""
        if self.zygote is not None:
            return await self.zygote.spawn(self)
        token = secrets.token_urlsafe(32)
        # two malloc arenas: each thread's own (64 MB of address space apiece) would eat the
        # session's address-space limit (app.server.process.limit_address_space) without using
        # memory
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "MALLOC_ARENA_MAX": "2"}
        proc = await asyncio.create_subprocess_exec(
            *self.command(self.scene, self.options),
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            env=env,
            start_new_session=True,  # a Ctrl+C in the terminal reaches the launcher only
        )
        child = Child(proc, 0, token, time.monotonic())
        self._all.add(child)
        proc.stdin.write(token.encode() + b"\n")
        try:
            await proc.stdin.drain()
            port = await asyncio.wait_for(self._read_port(proc), self.caps.start_timeout_s)
        except (TimeoutError, StartFailed, ConnectionError) as exc:
            await self.stop_child(child)
            self.n_start_failures += 1
            raise StartFailed(str(exc) or type(exc).__name__) from None
        child.port = port
        child.drain = asyncio.create_task(_drain(proc.stdout))
        return child

    @staticmethod
    async def _read_port(proc: asyncio.subprocess.Process) -> int:
        while True:
            line = await proc.stdout.readline()
            if not line:
                await proc.wait()
                raise StartFailed(f"the process exited with {proc.returncode} before listening")
            found = ADDRESS_LINE.match(line.decode(errors="replace"))
            if found:
                return int(found["port"])

    async def _take_child(self) -> Child:
        async with self._lock:
            spare, self.spare = self.spare, None
        if spare is not None:
            try:
                child = await spare
                if child.alive:
                    return child
                await self.stop_child(child)
            except StartFailed as exc:
                log.warning("the spare process failed: %s", exc)
        return await self.start_child()

    def _ensure_spare(self) -> None:
        """Start a spare process if there is none and the caps leave room for one."""
        if not self.caps.spare or self._closing or self.spare is not None:
            return
        if len(self.sessions) + self.n_starting + 1 > self.caps.max_sessions:
            return
        if self.children_bytes() + self.caps.session_bytes > self.caps.memory_cap_bytes:
            return
        self.spare = asyncio.create_task(self.start_child())
        self.spare.add_done_callback(_quiet)

    def children_rss_bytes(self) -> int:
        """The children's total resident memory [bytes]."""
        return sum(child.rss_bytes() for child in self._all)

    def children_bytes(self) -> int:
        """What the sessions' processes count in the memory cap [bytes]: each at least
        ``caps.session_bytes`` (a process still starting has not yet grown to its size)."""
        floor = self.caps.session_bytes
        return sum(max(floor, child.rss_bytes()) for child in self.sessions.values())

    async def stop_child(self, child: Child, wait_s: float = 10.0) -> None:
        """Stop one process: SIGTERM, then SIGKILL after ``wait_s``."""
        self._all.discard(child)
        proc = child.proc
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.terminate()
            try:
                await asyncio.wait_for(proc.wait(), wait_s)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
        if proc.stdin is not None:
            proc.stdin.close()
        if child.drain is not None:
            child.drain.cancel()

    def _forget(self, session_id: str) -> Child | None:
        return self.sessions.pop(session_id, None)

    async def end_session(self, session_id: str, why: str) -> None:
        """Stop a session: its pages are told (a websocket close that the page shows as "session
        ended: reload for a new one"), then its process is stopped."""
        child = self._forget(session_id)
        if child is None:
            return
        log.info("session %s: ended, %s", session_id[:6], why)
        self.n_reaped += 1
        for page in list(child.pages):
            with contextlib.suppress(Exception):
                await page.close(code=SESSION_ENDED, message=b"session ended")
        await self.stop_child(child)

    def why_end(self, child: Child, now: float) -> str | None:
        """Why a live session should end now, or None."""
        caps = self.caps
        if child.n_sockets == 0 and now - child.idle_since_s >= caps.idle_s:
            return f"its page closed for {caps.idle_s:g} s"
        if now - child.last_input_s >= caps.input_idle_s:
            return f"no input from its page for {caps.input_idle_s:g} s"
        if now - child.opened_s >= caps.max_age_s:
            return f"open for {caps.max_age_s:g} s, the most allowed"
        return None

    async def reap(self) -> None:
        """Forget sessions whose process died; end those idle (page closed, or no input even
        with a socket open) or too old; replace a dead spare."""
        now = time.monotonic()
        for session_id, child in list(self.sessions.items()):
            if not child.alive:
                code = child.proc.returncode
                log.warning("session %s: its process exited (%s)", session_id[:6], code)
                self._forget(session_id)
                self._all.discard(child)
                for page in list(child.pages):
                    with contextlib.suppress(Exception):
                        await page.close(code=SESSION_ENDED, message=b"session ended")
                continue
            why = self.why_end(child, now)
            if why is not None:
                await self.end_session(session_id, why)
        spare = self.spare
        if spare is not None and spare.done():
            if spare.exception() is not None or not spare.result().alive:
                self.spare = None
                if spare.exception() is None:
                    await self.stop_child(spare.result())
        if self.n_start_failures < 3:  # a process that cannot start is not restarted forever
            self._ensure_spare()

    async def _reap_forever(self) -> None:
        period_s = min(1.0, max(0.05, self.caps.idle_s / 4))
        while not self._closing:
            await asyncio.sleep(period_s)
            try:
                await self.reap()
            except Exception:  # the reaper must outlive any one failure
                log.exception("reaping sessions failed")

    async def close(self) -> None:
        """Stop every child (sessions and spare), the reaper and the zygote."""
        self._closing = True
        if self._reaper is not None:
            self._reaper.cancel()
        spare, self.spare = self.spare, None
        if spare is not None:
            spare.cancel()
            with contextlib.suppress(BaseException):
                await spare
        self.sessions.clear()
        await asyncio.gather(*(self.stop_child(c) for c in list(self._all)))
        if self.zygote is not None:
            await self.zygote.close()
        if self._client is not None:
            await self._client.close()


def navigation_problem(headers) -> str | None:
    """None if a request to the door is a browser's navigation of a tab (or comes from a client
    that sends no fetch metadata, such as an older browser or a script), else why not: a
    subresource (``<img>``, ``fetch``), a frame, or a prefetch."""
    mode = headers.get("Sec-Fetch-Mode", "").lower()
    if mode and mode != "navigate":
        return f"a {security.echo(mode)} request, not a navigation"
    dest = headers.get("Sec-Fetch-Dest", "").lower()
    if dest and dest != "document":
        return f"a request for a {security.echo(dest)}, not a page"
    purpose = " ".join(headers.get(k, "") for k in ("Sec-Purpose", "Purpose", "X-Moz")).lower()
    if "prefetch" in purpose or "prerender" in purpose or "preview" in purpose:
        return "a prefetch"
    return None


def session_cookie(session_id: str) -> str:
    """The name of the cookie that binds a session to its browser."""
    return f"lmapd-session-{session_id}"


STARTING_HEAD = (
    "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
    "<title>lmapd-sim: starting</title></head>"
    "<body style='font-family: sans-serif; max-width: 40em; margin: 3em auto'>"
)


def starting_page(ahead: int) -> str:
    """The first words a tab gets from the door, before its session's process is ready."""
    queue = f" ({ahead} more starting before it)" if ahead > 0 else ""
    return (
        f"{STARTING_HEAD}<h1 class='launcher-title'>lmapd-sim</h1>"
        f"<p class='launcher-message' role='status'>Starting your session{queue}…</p>\n"
    )


def move_html(location: str) -> str:
    """The end of the door's page: moves its tab to ``location`` (in place, so Back does not
    reopen the door). A script's navigation is same-site, so the session's SameSite=Strict
    cookie is sent even when the door was opened from a link on another site (a redirect would
    not send it)."""
    target = html.escape(location, quote=True)
    script = json.dumps(location).replace("<", "\\u003c")
    return (
        f"<p><a class='launcher-link' href='{target}'>Open the simulator</a></p>"
        f"<script>window.location.replace({script});</script></body></html>"
    )


def start_failed_html(link: str) -> str:
    """The end of the door's page when the session's process did not start."""
    return (
        "<h1 class='launcher-title'>The session could not start</h1>"
        "<p class='launcher-message'>The simulator's process for this tab did not start (the "
        "server's log says why). Try again in a moment.</p>"
        f"<p><a class='launcher-link' href='{html.escape(link, quote=True)}'>Try again</a></p>"
        "</body></html>"
    )


async def _finish(page: web.StreamResponse, rest: str) -> bool:
    """Send the rest of a streamed page and end it; False if the tab had gone."""
    try:
        await page.write(rest.encode())
        await page.write_eof()
    except (ConnectionError, RuntimeError):
        return False
    return True


def _query(pairs) -> str:
    return "&".join(f"{_q(k)}={_q(v)}" for k, v in pairs)


def _pss_bytes(pid: int) -> int | None:
    """A process's proportional set size from /proc/PID/smaps_rollup [bytes] (Linux 4.14+), or
    None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as f:
            for line in f:
                if line.startswith(b"Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


ZYGOTE_READY = "lmapd-sim zygote: ready"  # what app.server.zygote prints once it can fork


def token_digest(token: str) -> str:
    """How app.server.zygote names a session's token in its output (never the token itself)."""
    return hashlib.sha256(token.encode()).hexdigest()[:16]


def zygote_command(scene: str | None, options: tuple[str, ...] = ()) -> list[str]:
    """The command of the sessions' preloaded parent (app.server.zygote)."""
    return [
        sys.executable,
        "-m",
        "app.server.zygote",
        *(["--scene", scene] if scene else []),
        *options,
    ]


class ForkedProcess:
    """A session process forked by the zygote (not this process's child), seen through the
    parts of ``asyncio.subprocess.Process`` the launcher uses; its exit status is unknown (-1)
    once it is gone."""

    stdin = None

    def __init__(self, pid: int):
        self.pid = pid
        self._returncode: int | None = None

    @property
    def returncode(self) -> int | None:
        if self._returncode is None:
            try:
                gone = psutil.Process(self.pid).status() == psutil.STATUS_ZOMBIE
            except psutil.NoSuchProcess:
                gone = True
            if gone:
                self._returncode = -1
        return self._returncode

    def _signal(self, sig: int) -> None:
        if self.returncode is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self._signal(signal.SIGTERM)

    def kill(self) -> None:
        self._signal(signal.SIGKILL)

    async def wait(self) -> int:
        while self.returncode is None:
            await asyncio.sleep(0.05)
        return self._returncode


class Zygote:
    """The launcher's end of app.server.zygote: started on the first spawn, asked for one session
    per ``spawn TOKEN`` line; its output tells each token's process and, once it listens, its
    port."""

    def __init__(self, command: list[str]):
        self.command = command
        self.proc: asyncio.subprocess.Process | None = None
        self.reader: asyncio.Task | None = None
        self.ready: asyncio.Future | None = None
        self.pids: dict[str, asyncio.Future] = {}  # token digest -> pid
        self.ports: dict[str, asyncio.Future] = {}  # token -> port
        self._lock = asyncio.Lock()

    async def _start(self, timeout_s: float) -> None:
        loop = asyncio.get_running_loop()
        self.ready = loop.create_future()
        self.proc = await asyncio.create_subprocess_exec(
            *self.command,
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            env={
                **os.environ,
                "PYTHONUNBUFFERED": "1",
                "MALLOC_ARENA_MAX": "2",
                "NUMBA_THREADING_LAYER": "workqueue",  # GNU OpenMP's aborts forked processes
            },
            start_new_session=True,
        )
        self.reader = asyncio.create_task(self._read())
        await asyncio.wait_for(asyncio.shield(self.ready), timeout_s)

    async def _read(self) -> None:
        while line := await self.proc.stdout.readline():
            text = line.decode(errors="replace").strip()
            if text == ZYGOTE_READY and not self.ready.done():
                self.ready.set_result(True)
            elif found := FORKED_LINE.match(text):
                future = self.pids.get(found["digest"])
                if future is not None and not future.done():
                    future.set_result(int(found["pid"]))
            elif found := SESSION_LINE.match(text):
                future = self.ports.get(found["token"])
                if future is not None and not future.done():
                    future.set_result(int(found["port"]))
        problem = StartFailed(f"the sessions' parent exited with {await self.proc.wait()}")
        for future in (self.ready, *self.pids.values(), *self.ports.values()):
            if future is not None and not future.done():
                future.set_exception(problem)

    async def spawn(self, launcher: Launcher) -> Child:
        """Fork one session and wait until it listens. Raises StartFailed."""
        timeout_s = launcher.caps.start_timeout_s
        token = secrets.token_urlsafe(32)
        loop = asyncio.get_running_loop()
        pid_future = self.pids[token_digest(token)] = loop.create_future()
        port_future = self.ports[token] = loop.create_future()
        child = None
        try:
            async with self._lock:
                if self.proc is None or self.proc.returncode is not None:
                    await self._start(timeout_s)
                self.proc.stdin.write(f"spawn {token}\n".encode())
                await self.proc.stdin.drain()
            pid = await asyncio.wait_for(pid_future, timeout_s)
            child = Child(ForkedProcess(pid), 0, token, time.monotonic())  # type: ignore[arg-type]
            launcher._all.add(child)
            child.port = await asyncio.wait_for(port_future, timeout_s)
            return child
        except (TimeoutError, StartFailed, ConnectionError, OSError) as exc:
            if child is not None:
                await launcher.stop_child(child)
            launcher.n_start_failures += 1
            raise StartFailed(str(exc) or type(exc).__name__) from None
        finally:
            self.pids.pop(token_digest(token), None)
            self.ports.pop(token, None)
            for future in (pid_future, port_future):
                if future.done() and not future.cancelled():
                    future.exception()  # read: never "never retrieved"

    async def close(self) -> None:
        proc = self.proc
        if proc is None:
            return
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.terminate()
            try:
                await asyncio.wait_for(proc.wait(), 10)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
        if self.reader is not None:
            self.reader.cancel()


def _open(n: int) -> str:
    return "1 session is open" if n == 1 else f"{n} sessions are open"


def _redirect(location: str) -> web.Response:
    return web.Response(status=302, headers={"Location": location, "Cache-Control": "no-store"})


def _q(text: str) -> str:
    return quote(text, safe="")


def _path(rest: str) -> str:
    return quote(rest, safe="/-_.~")


def _quiet(task: asyncio.Task) -> None:
    """Read a background task's exception (logged where it is awaited)."""
    if not task.cancelled():
        task.exception()


async def _pump(source, sink, child: Child | None = None) -> None:
    """Pass one websocket's frames to another until either closes; frames from a page
    (``child`` given) are its session's input."""
    async for msg in source:
        if child is not None:
            child.last_input_s = time.monotonic()
        if msg.type == aiohttp.WSMsgType.BINARY:
            await sink.send_bytes(msg.data)
        elif msg.type == aiohttp.WSMsgType.TEXT:
            await sink.send_str(msg.data)  # refused by the process's guard (closes)
        else:
            break


async def _drain(stream: asyncio.StreamReader) -> None:
    """Read a child's stdout to its end (its pipe must not fill up)."""
    while await stream.readline():
        pass


async def serve(launcher: Launcher, host: str, port: int, announce: Callable[[int], None]) -> None:
    """Serve until SIGINT or SIGTERM (behind the launcher's connection guard); then stop every
    child."""
    runner = web.AppRunner(
        launcher.web_app(), handle_signals=False, access_log=None, keepalive_timeout=75.0
    )
    await runner.setup()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    listening = None
    try:
        listening = await connections.listen(runner, launcher.guard, host, port)
        announce(listening[2])
        await stop.wait()
    finally:
        if listening is not None:
            await connections.stop_listening(*listening[:2])
        await runner.cleanup()  # the launcher's on_cleanup stops the children
        await launcher.close()
