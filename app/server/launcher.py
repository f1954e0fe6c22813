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
* a session's id is 128 random bits in lowercase hex (trame's client lowercases the address it
  is told to connect to); trame's page asks where to connect at every load (a POST to
  ``/s/<id>/paraview/``, wslink's launcher protocol) and is told its session's websocket,
  ``/s/<id>/ws`` of the address it was loaded from (``index_page.session_manager_answer``);
* under ``/s/<id>/`` only GET and HEAD, and the websocket at ``/s/<id>/ws``, are passed to that
  session's process, with the process's own private token (given on its stdin, never on a
  command line) and origin; the websocket's ``Origin`` and the session's cookie are checked
  first, and frames are limited to wslink's chunk size (the process reassembles messages within
  ``app.server.security``'s limits and screens every call);
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
* heavy frames in flight across the sessions share one memory budget (``caps.frames_bytes``:
  app.server.frame_memory); a session ended or found dead gives its grants back;
* with ``zygote`` (``lmapd app``'s default on Linux) the session processes are forked from one
  preloaded parent (app.server.zygote): they share its modules, target and compiled kernels.

By concern: ``caps`` the limits; ``ending`` when a session ends (the reaper's rules);
``children`` the session processes (started, or forked by the preloaded parent) and stopping
them; ``routes`` what a request's path, headers and cookies say; ``pages`` the launcher's own
pages; ``proxy`` a session's pages and websocket passed to its process. This module: the door,
the sessions and their reaping, and ``serve``.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import re
import secrets
import signal
import time
from collections.abc import Callable

import aiohttp
from aiohttp import web

from app.logic import upload_folders
from app.server import (
    connections,
    ending,
    frame_memory,
    headers,
    index_page,
    pages,
    proxy,
    routes,
    security,
)
from app.server.caps import FORKED_SESSION_BYTES as FORKED_SESSION_BYTES
from app.server.caps import MAX_DEFAULT_SESSIONS as MAX_DEFAULT_SESSIONS
from app.server.caps import MEMORY_SHARE as MEMORY_SHARE
from app.server.caps import MIB, Caps
from app.server.caps import SESSION_RSS_BYTES as SESSION_RSS_BYTES
from app.server.caps import default_caps as default_caps
from app.server.children import Child, StartFailed, Zygote, child_command, start_process
from app.server.children import zygote_command as zygote_command
from app.server.pages import finish, move_html, start_failed_html, starting_page
from app.server.pages import message_page as message_page
from app.server.proxy import FRAME_BYTES as FRAME_BYTES
from app.server.routes import navigation_problem, safe_rest, session_cookie

log = logging.getLogger(__name__)

SESSION_ENDED = proxy.SESSION_ENDED  # the websocket close code of an ended session
NO_STORE = {"Cache-Control": "no-store"}


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
        self.child_env: dict[str, str] = {}  # what the children's environment adds (at startup)
        # sessions forked from a preloaded parent (app.server.zygote): its command, or None
        self.zygote = Zygote(zygote(scene, options), self.child_env) if zygote is not None else None
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
        self.frames = frame_memory.budget_for(caps.frames_bytes, self._all)  # None: no budget

    # -- the application -----------------------------------------------------------------------
    def web_app(self) -> web.Application:
        web_app = web.Application(client_max_size=64 * 1024, middlewares=[self.guard.middleware])
        web_app.router.add_route("*", "/{tail:.*}", self.handle)
        headers.install(web_app)  # CSP, nosniff, no referrer, no-store pages (proxied ones too)
        web_app.on_startup.append(self._on_startup)
        web_app.on_cleanup.append(self._on_cleanup)
        return web_app

    async def _on_startup(self, _app) -> None:
        self._client = proxy.client_session()
        if self.frames is not None:  # the frames' budget: its socket in the children's env
            self.child_env[frame_memory.ENV] = await self.frames.start()
        self._ensure_spare()
        self._reaper = asyncio.create_task(self._reap_forever())

    async def _on_cleanup(self, _app) -> None:
        await self.close()

    # -- requests ------------------------------------------------------------------------------
    async def handle(self, request: web.Request) -> web.StreamResponse:
        websocket = request.headers.get("Upgrade", "").lower() == "websocket"
        path = request.path
        found = routes.SESSION_ID.match(path)
        probe = bool(found) and routes.is_session_manager_probe(request.method, found["rest"])
        if request.method not in ("GET", "HEAD") and not probe:
            self.log.warning("method", "refused a %s request from %s", "non-GET", request.remote)
            return web.Response(status=405, text="Method not allowed\n")
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
            response.set_cookie(token_cookie, self.token, **self.door.cookie_attributes(request))
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
            return pages.not_a_tab(routes.root_link(request))
        problem = None if token_cookie else routes.foreign_navigation(request.headers)
        if problem is not None:  # the cookie alone: only from the app's own pages
            self.n_not_navigation += 1
            self.log.warning("navigation", "no session for %s: %s", request.remote, problem)
            return pages.not_from_here(routes.root_link(request))
        client = request.cookies.get(routes.client_cookie(request), "")
        if not routes.CLIENT_ID.match(client):
            client = secrets.token_urlsafe(16)
        address = routes.client_address(request, behind_proxy=bool(self.door.origins))
        problem = self.over_caps(address)
        if problem:
            return self.refuse(request, problem, address)
        # the tab hears at once that its session is starting (a process may take seconds when a
        # class opens together); its cookies are made now and the way in is sent when it listens
        session_id = routes.new_session_id()
        secret = secrets.token_urlsafe(32)
        page = web.StreamResponse(status=200, headers=NO_STORE)
        page.content_type = "text/html"
        page.charset = "utf-8"
        page.set_cookie(
            session_cookie(session_id),
            secret,
            max_age=int(self.caps.max_age_s) + 60,
            **self.door.cookie_attributes(request, path=f"/s/{session_id}/"),
        )
        page.set_cookie(
            routes.client_cookie(request), client, **self.door.cookie_attributes(request)
        )
        if token_cookie:
            page.set_cookie(token_cookie, self.token, **self.door.cookie_attributes(request))
        nonce = headers.new_nonce(request)  # the page's one script, in the headers sent now
        self.n_starting += 1
        try:
            ahead = self.n_starting - 1
            await page.prepare(request)
            await page.write(starting_page(ahead).encode())
            await self._make_room_for(client)
            child = await self._take_child()
        except StartFailed as exc:
            log.error("a session's process did not start: %s", exc)
            await finish(page, start_failed_html(routes.root_link(request)))
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
        settings = routes.page_settings(request)
        target = f"/s/{session_id}/" + ("?" + routes.query_string(settings) if settings else "")
        if not await finish(page, move_html(f"{target}#token={routes.quoted(self.token)}", nonce)):
            await self.end_session(session_id, "its tab closed before the session started")
        return page

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
        # this machine's own tabs are not capped, unless the server listens beyond it
        exempt = address in security.LOOPBACK_NAMES and self.door.host in security.LOOPBACK_NAMES
        if limit and address and not exempt:
            n_mine = sum(1 for c in self.sessions.values() if c.address == address)
            if n_mine >= limit:
                return f"Your computer has {n_mine} sessions open, the most it may have."
        return None

    def refuse(self, request: web.Request, problem: str, address: str = "") -> web.Response:
        """The 503 page: which cap, and when a session frees (one of this address's if only its
        own cap is reached)."""
        self.n_refused += 1
        self.log.warning("caps", "refused a new session: %s", problem)
        own_cap_only = bool(address) and self.over_caps("") is None
        sessions = [c for c in self.sessions.values() if not own_cap_only or c.address == address]
        frees_in_s = ending.frees_in_s(self.caps, sessions, time.monotonic())
        return pages.no_session_free(
            problem, self.caps, routes.root_link(request), frees_in_s=frees_in_s
        )

    async def in_session(self, request: web.Request, found: re.Match, websocket: bool):
        session_id = found["id"]
        child = self.sessions.get(session_id)
        if child is None or not child.alive:
            if child is not None:
                self._forget(session_id)
            return pages.no_such_session(routes.root_link(request))
        given = request.cookies.get(session_cookie(session_id), "")
        if not (given and hmac.compare_digest(given.encode(), child.secret.encode())):
            self.n_foreign += 1
            self.log.warning("foreign", "refused a request for another browser's session")
            return pages.foreign_session()
        rest = found["rest"]
        if routes.is_session_manager_probe(request.method, rest):
            # trame's page asks where to connect, at every load (wslink's launcher protocol)
            return index_page.session_manager_response(routes.session_manager_answer(session_id))
        if rest is None:  # /s/<id> -> /s/<id>/ (the page's relative addresses need the slash)
            query = request.query_string
            return routes.redirect(f"/s/{session_id}/" + (f"?{query}" if query else ""))
        if not safe_rest(rest):
            return web.Response(status=404, text="Not found\n")
        if websocket:
            if rest != security.WS_PATH:
                return web.Response(status=404, text="Not found\n")
            return await self.proxy_websocket(request, child)
        return await proxy.http(self._client, request, child, rest)

    async def proxy_websocket(self, request: web.Request, child: Child) -> web.StreamResponse:
        problem = self.door.origin_problem(request)
        if problem is not None:
            self.log.warning("origin", "refused a websocket from %s: %s", request.remote, problem)
            self.door.n_refused += 1
            return web.Response(status=403, text="Forbidden\n")
        if child.n_sockets >= self.caps.sockets_per_session:
            self.log.warning("sockets", "refused a websocket: the session has %d", child.n_sockets)
            return web.Response(status=503, text="Too many connections\n")
        return await proxy.websocket(self._client, request, child)

    # -- children ------------------------------------------------------------------------------
    async def start_child(self) -> Child:
        """Start one app process and wait until it listens. Raises StartFailed."""
        if self.zygote is not None:
            return await self.zygote.spawn(self)
        return await start_process(self)

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
        await child.stop(wait_s)
        upload_folders.remove_folders_of(child.pid)  # a session killed leaves its uploads

    def _forget(self, session_id: str) -> Child | None:
        child = self.sessions.pop(session_id, None)
        if child is not None and self.frames is not None:
            self.frames.release_owner(child)  # its frames' grants go back to the budget
        return child

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
                upload_folders.remove_folders_of(child.pid)
                for page in list(child.pages):
                    with contextlib.suppress(Exception):
                        await page.close(code=SESSION_ENDED, message=b"session ended")
                continue
            why = ending.why_end(self.caps, child, now)
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
        if self.frames is not None:
            await self.frames.close()
        if self._client is not None:
            await self._client.close()


def _open(n: int) -> str:
    return "1 session is open" if n == 1 else f"{n} sessions are open"


def _quiet(task: asyncio.Task) -> None:
    """Read a background task's exception (logged where it is awaited)."""
    if not task.cancelled():
        task.exception()


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
