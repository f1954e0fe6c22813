"""Connection guards of the app's HTTP servers: idle and partial connections closed, a cap per
address, the file-descriptor limit raised, and server logs of one short line per refusal.

Checked against aiohttp 3.14. aiohttp keeps a connection that has sent no request, or only part of
one, open for its keep-alive time (an hour by default): a few hundred such connections (slowloris)
use up a process's file descriptors and stop the server for everyone. :class:`ConnectionGuard`
wraps the server's protocol factory (``loop.create_server(guard.factory(runner.server), ...)``):

* a connection that is not inside a request (no request begun yet, a request line or headers
  still arriving, or a kept-alive connection between requests) for ``idle_s`` is closed; a
  request is "begun" once its headers are complete and the guard's middleware runs, and a
  websocket stays inside its request while it is open;
* each client address holds at most ``per_address`` connections: a new one over the cap closes
  that address's longest-idle connection (half-open ones first, so that a real page load is
  never the one refused), or is itself closed when all of them are busy.

:func:`raise_open_file_limit` lifts the soft ``RLIMIT_NOFILE`` to the hard limit, and
:class:`ShortLog` makes aiohttp's error records (a malformed request logs a traceback that echoes
the request line, access token included) one line without the request, at most a few a second.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import resource
import time
from collections.abc import Callable
from typing import Any

from aiohttp import web

log = logging.getLogger(__name__)

IDLE_S = 10.0  # a connection outside any request this long is closed [s]
# connections the kernel queues for a listening socket; asyncio accepts up to this many at one
# wake-up before any of them is seen by the guard
BACKLOG = 128
# open files kept free for the server's own work (a page load's connection to its session, a
# session's pipes, the files it serves) and for one wake-up's accepts: past the limit less
# this, a new connection closes the longest-idle one of any address first, or is itself closed
# when all are busy
FD_RESERVE = BACKLOG + 64
PER_ADDRESS = 256  # connections of one client address (a reverse proxy is one address)
SWEEP_S = 1.0
AIOHTTP_LOGGERS = ("aiohttp.server", "aiohttp.web", "aiohttp.websocket", "aiohttp.access")


class _Guarded(asyncio.Protocol):
    """One connection: aiohttp's request handler behind the guard's bookkeeping."""

    def __init__(self, guard: ConnectionGuard, inner: asyncio.Protocol):
        self.guard = guard
        self.inner = inner
        self.transport: asyncio.Transport | None = None
        self.address = ""
        self.busy = 0  # requests in progress
        self.idle_since_s = guard.clock()

    def connection_made(self, transport) -> None:
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.address = str(peer[0]) if peer else ""
        self.inner.connection_made(transport)
        self.guard._opened(self)

    def connection_lost(self, exc) -> None:
        self.guard._closed(self)
        self.inner.connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received()

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def close(self) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.close()


class ConnectionGuard:
    """Closes idle and partial connections and caps the connections of each address (see the
    module's docstring).

    idle_s : a connection outside any request this long is closed [s]
    per_address : connections one client address may hold
    clock : seconds, monotonic (tests may replace it)
    """

    def __init__(
        self,
        idle_s: float = IDLE_S,
        per_address: int = PER_ADDRESS,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.idle_s = idle_s
        self.per_address = max(1, per_address)
        self.clock = clock
        self.by_address: dict[str, list[_Guarded]] = {}
        self._by_handler: dict[int, _Guarded] = {}
        self.n_closed_idle = 0
        self.n_evicted = 0
        self.n_refused = 0
        self.sweeper: asyncio.Task | None = None
        self.log = ShortLog(log)

    @property
    def n_open(self) -> int:
        return sum(len(c) for c in self.by_address.values())

    def factory(self, make_handler: Callable[[], asyncio.Protocol]) -> Callable[[], _Guarded]:
        """The protocol factory for ``loop.create_server``: ``make_handler`` (an aiohttp
        ``web.Server``) behind this guard."""

        def make() -> _Guarded:
            return _Guarded(self, make_handler())

        return make

    def files_short(self) -> bool:
        """Whether the process's open files are within ``FD_RESERVE`` of its limit (counted
        only once this guard holds a quarter of the limit: a listing of /proc/self/fd)."""
        soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
        if soft == resource.RLIM_INFINITY or self.n_open < (soft - FD_RESERVE) // 4:
            return False
        try:
            return len(os.listdir("/proc/self/fd")) > soft - FD_RESERVE
        except OSError:
            return False

    def _opened(self, conn: _Guarded) -> None:
        self._by_handler[id(conn.inner)] = conn
        if self.files_short() and not self._make_room(conn):
            return
        mine = self.by_address.setdefault(conn.address, [])
        if len(mine) >= self.per_address:
            idle = [c for c in mine if not c.busy]
            if idle:
                oldest = min(idle, key=lambda c: c.idle_since_s)
                self.n_evicted += 1
                self.log.warning(
                    "evicted",
                    "closed an idle connection of %s: over %d connections",
                    conn.address,
                    self.per_address,
                )
                self._forget(oldest)
                oldest.close()
            else:
                self.n_refused += 1
                self.log.warning(
                    "refused",
                    "refused a connection from %s: %d connections, all busy",
                    conn.address,
                    self.per_address,
                )
                self._by_handler.pop(id(conn.inner), None)
                conn.close()
                return
        mine.append(conn)

    def _make_room(self, conn: _Guarded) -> bool:
        """Near the open-file limit: close the longest-idle connection of any address (True),
        or ``conn`` itself when every one is busy (False)."""
        idle = [c for conns in self.by_address.values() for c in conns if not c.busy]
        if idle:
            oldest = min(idle, key=lambda c: c.idle_since_s)
            self.n_evicted += 1
            self.log.warning(
                "files",
                "closed an idle connection of %s: open files near the limit",
                oldest.address,
            )
            self._forget(oldest)
            oldest.close()
            return True
        self.n_refused += 1
        self.log.warning(
            "files-refused", "refused a connection from %s: open files near the limit", conn.address
        )
        self._by_handler.pop(id(conn.inner), None)
        conn.close()
        return False

    def _closed(self, conn: _Guarded) -> None:
        self._forget(conn)
        self._by_handler.pop(id(conn.inner), None)

    def _forget(self, conn: _Guarded) -> None:
        mine = self.by_address.get(conn.address)
        if mine is not None and conn in mine:
            mine.remove(conn)
            if not mine:
                del self.by_address[conn.address]

    @web.middleware
    async def middleware(self, request: web.Request, handler):
        """Marks the request's connection busy while the request (or its websocket) lasts."""
        conn = self._by_handler.get(id(request.protocol))
        if conn is None:
            return await handler(request)
        conn.busy += 1
        try:
            return await handler(request)
        finally:
            conn.busy -= 1
            conn.idle_since_s = self.clock()

    def sweep(self) -> int:
        """Close the connections idle (outside any request) for ``idle_s``; how many."""
        now = self.clock()
        stale = [
            c
            for conns in self.by_address.values()
            for c in conns
            if not c.busy and now - c.idle_since_s >= self.idle_s
        ]
        for conn in stale:
            self._forget(conn)
            conn.close()
        if stale:
            self.n_closed_idle += len(stale)
            self.log.info(
                "idle", "closed %d connections idle or partial for %g s", len(stale), self.idle_s
            )
        return len(stale)

    async def sweep_forever(self) -> None:
        period_s = min(SWEEP_S, max(0.05, self.idle_s / 4))
        while True:
            await asyncio.sleep(period_s)
            self.sweep()


async def listen(
    runner: web.BaseRunner, guard: ConnectionGuard, host: str, port: int
) -> tuple[asyncio.Server, asyncio.Task, int]:
    """Serve ``runner`` (set up) on ``host``:``port`` behind ``guard``: (the server, the sweeping
    task, the bound port). Raises OSError if it cannot listen."""
    loop = asyncio.get_running_loop()
    server = await loop.create_server(
        guard.factory(runner.server), host or None, port, reuse_address=True, backlog=BACKLOG
    )
    sweeper = asyncio.create_task(guard.sweep_forever())
    return server, sweeper, int(server.sockets[0].getsockname()[1])


async def stop_listening(server: asyncio.Server, sweeper: asyncio.Task) -> None:
    sweeper.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await sweeper
    server.close()


GUARD_KEY = web.AppKey("lmapd_connection_guard", ConnectionGuard)


class GuardedSite(web.TCPSite):
    """aiohttp's TCP site behind the ConnectionGuard its application carries (``GUARD_KEY``;
    without one, a plain TCP site). For servers whose site another library creates (wslink's,
    under trame): :func:`guard_app` sets the guard and its middleware on the application, and
    :func:`guard_wslink_sites` makes wslink create this site. Checked against aiohttp 3.14:
    ``TCPSite.start`` passes ``runner._server`` to ``loop.create_server`` as the protocol
    factory; the guarded factory stands in for it while the site starts."""

    async def start(self) -> None:
        runner = self._runner
        app = getattr(runner, "app", None)
        guard = app.get(GUARD_KEY) if app is not None else None
        if guard is None:
            await super().start()
            return
        server = runner._server
        runner._server = guard.factory(server)
        try:
            await super().start()
        finally:
            runner._server = server
        guard.sweeper = asyncio.create_task(guard.sweep_forever())

    async def stop(self) -> None:
        app = getattr(self._runner, "app", None)
        guard = app.get(GUARD_KEY) if app is not None else None
        if guard is not None and guard.sweeper is not None:
            guard.sweeper.cancel()
        await super().stop()


def guard_app(app: web.Application, guard: ConnectionGuard | None = None) -> ConnectionGuard:
    """Put a ConnectionGuard (and its middleware) on ``app`` (before it starts)."""
    guard = guard or ConnectionGuard()
    app[GUARD_KEY] = guard
    app.middlewares.append(guard.middleware)
    return guard


class _WebWithGuardedSite:
    """aiohttp.web as wslink's aiohttp backend sees it, with GuardedSite as its TCPSite."""

    def __getattr__(self, name: str) -> Any:
        return GuardedSite if name == "TCPSite" else getattr(web, name)


def guard_wslink_sites() -> None:
    """Make wslink's aiohttp backend (wslink 2.6: ``WebAppServer.start`` builds
    ``aiohttp_web.TCPSite``) create GuardedSite; an application without a guard is served as
    before."""
    from wslink.backends import aiohttp as backend  # noqa: PLC0415  (the app's server only)

    if not isinstance(backend.aiohttp_web, _WebWithGuardedSite):
        backend.aiohttp_web = _WebWithGuardedSite()


def raise_open_file_limit() -> tuple[int, int]:
    """Lift the soft ``RLIMIT_NOFILE`` to the hard limit (at most 1,048,576); (soft, hard) after."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = hard if hard != resource.RLIM_INFINITY else 2**20
    target = min(target, 2**20)
    if soft == resource.RLIM_INFINITY or soft >= target:
        return soft, hard
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    except (ValueError, OSError):
        return soft, hard
    return target, hard


class ShortLog:
    """One line per event, at most ``per_window`` lines of one kind in ``window_s``; the lines
    held back are counted in the next line of that kind."""

    def __init__(
        self,
        logger: logging.Logger,
        per_window: int = 5,
        window_s: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.logger = logger
        self.per_window = per_window
        self.window_s = window_s
        self.clock = clock
        self._windows: dict[str, tuple[float, int, int]] = {}  # kind -> (start, lines, held)

    def allow(self, kind: str) -> tuple[bool, int]:
        """(log this one, how many of this kind were held back before it)."""
        now = self.clock()
        start, lines, held = self._windows.get(kind, (now, 0, 0))
        if now - start >= self.window_s:
            start, lines = now, 0
        if lines >= self.per_window:
            self._windows[kind] = (start, lines, held + 1)
            return False, 0
        self._windows[kind] = (start, lines + 1, 0)
        return True, held

    def log(self, level: int, kind: str, msg: str, *args: Any) -> bool:
        ok, held = self.allow(kind)
        if ok:
            suffix = f" ({held} more like it not logged)" if held else ""
            self.logger.log(level, msg + suffix, *args)
        return ok

    def warning(self, kind: str, msg: str, *args: Any) -> bool:
        return self.log(logging.WARNING, kind, msg, *args)

    def info(self, kind: str, msg: str, *args: Any) -> bool:
        return self.log(logging.INFO, kind, msg, *args)


class _OneLine(logging.Filter):
    """aiohttp's records become one line without the request (no traceback: it echoes the
    request line, and with it the token), rate-limited by kind."""

    def __init__(self, short: ShortLog):
        super().__init__()
        self.short = short

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING and not record.exc_info:
            return True
        exc = record.exc_info[1] if record.exc_info else None
        kind = type(exc).__name__ if exc is not None else "error"
        ok, held = self.short.allow(f"{record.name}:{kind}")
        if not ok:
            return False
        remote = _remote(record)
        what = f"refused a malformed request ({kind})" if exc is not None else "a server error"
        record.msg = f"{what}{f' from {remote}' if remote else ''}"
        record.msg += f" ({held} more like it not logged)" if held else ""
        record.args = ()
        record.exc_info = None
        record.exc_text = None
        record.stack_info = None
        if record.levelno > logging.WARNING:
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


def _remote(record: logging.LogRecord) -> str:
    """The client address that aiohttp's "Error handling request from %s" names, if any."""
    args = record.args if isinstance(record.args, tuple) else ()
    if len(args) == 1 and isinstance(args[0], str) and len(args[0]) <= 64:
        return "".join(c for c in args[0] if c.isalnum() or c in ".:[]-")
    return ""


class _AcceptErrors(logging.Filter):
    """asyncio's record of a failed ``accept()`` (out of open files: it logs a traceback at
    every retry, hundreds of thousands under a flood) becomes one line, at most one a second,
    counting those held back; asyncio's other records pass."""

    def __init__(self, short: ShortLog):
        super().__init__()
        self.short = short

    def filter(self, record: logging.LogRecord) -> bool:
        if "socket.accept() out of system resource" not in str(record.msg):
            return True
        ok, held = self.short.allow("accept")
        if not ok:
            return False
        exc = record.exc_info[1] if record.exc_info else None
        why = (getattr(exc, "strerror", None) or type(exc).__name__) if exc else "no reason"
        record.msg = f"could not accept a connection ({why})"
        record.msg += f" ({held} more like it not logged)" if held else ""
        record.args = ()
        record.exc_info = None
        record.exc_text = None
        record.stack_info = None
        record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


_installed: list[logging.Filter] = []


def shorten_server_logs(per_window: int = 5, window_s: float = 10.0) -> None:
    """Make aiohttp's error records one short line each, rate-limited, and asyncio's failed
    accepts one line a second at most (idempotent)."""
    if _installed:
        return
    one_line = _OneLine(ShortLog(logging.getLogger("aiohttp.server"), per_window, window_s))
    accepts = _AcceptErrors(ShortLog(logging.getLogger("asyncio"), 1, 1.0))
    _installed.extend([one_line, accepts])
    for name in AIOHTTP_LOGGERS:
        logging.getLogger(name).addFilter(one_line)
    logging.getLogger("asyncio").addFilter(accepts)
