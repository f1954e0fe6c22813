"""The app's websocket door: who may connect, what they may send, how much memory they may hold.

Checked against trame-server 4.1.0, wslink 2.6.0 and aiohttp 3.14; every hook into those libraries
is in this module (and the state synchronisation in ``app.server.sync``):

* an aiohttp middleware (added through trame's ``on_server_bind`` hook, before the server starts)
  refuses, before the websocket is upgraded: a foreign or missing ``Origin`` (browsers always send
  one on websockets), a missing or wrong per-launch access token (from the cookie that the
  tokenised address sets, or ``?token=`` on ``/ws``), and connections over the cap. Pages and
  files are served only with the token (or its cookie) too;
* a wslink ``LinkProtocol`` (registered through ``Server.add_protocol_to_configure``) decides the
  wslink hello (``validateToken``: only connections let in by the middleware), gives each
  connection a :class:`BoundedUnChunker` (one memory budget per connection and one in total, a
  time-out for partial messages) and wraps four methods of wslink's handler instance: text
  messages and refused chunks close the connection; each call is checked against an allow-list
  before wslink dispatches it; errors sent to a client are one short line (the trace stays in
  the server log); answers wait for the state pushes (next);
* the state pushes (``app.server.sync``) are sent at once, in order, and the answer to a page's
  state update or trigger waits for the pushes to that page made before it, the state the call
  caused (wslink's publish would send that on a later turn of the event loop, after the answer:
  :meth:`Guard.send_state`).

Browsers always send ``Origin`` on websockets, so a websocket without one is refused too: a
non-browser client (the tests) must send the served address as its ``Origin``, as a page would.
"""

from __future__ import annotations

import asyncio
import hmac
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import msgpack
from aiohttp import WSCloseCode, web
from wslink import protocol as wslink_protocol
from wslink.chunking import HEADER_LENGTH, _decode_header
from wslink.websocket import LinkProtocol

from app.logic.upload import MAX_UPLOAD_BYTES
from app.server import connections
from app.server.sync import STATE_TOPIC, ClientStateSync
from app.state import MAX_MATERIAL_ENTRIES, echo

log = logging.getLogger(__name__)

MIB = 2**20
MAX_MESSAGE_BYTES = MAX_UPLOAD_BYTES + 16 * MIB  # an upload plus its envelope, with margin
WS_CHUNK_BYTES = 4 * MIB  # websocket frames (wslink chunks) in both directions
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
WILDCARD_HOSTS = ("0.0.0.0", "::", "")
WS_PATH = "/ws"
AUTHORISED = "lmapd_authorised"  # set on a websocket request the middleware let in
MAX_TEXT = 500  # a client's error report is logged at most this long
MAX_TRIGGER_NAME = 100
MAX_CHANGES = 256  # state changes in one update
MAX_SCALAR_CHARS = 256  # a string value of a control
STATE_PUSH_ID = f"publish:{STATE_TOPIC}:0"  # the id of wslink's publish of a state push
# the calls answered after the state pushes to their page made before the answer (not
# trame.state.get: its answer is a copy of the state, which a newer push must follow)
ANSWERED_AFTER_PUSHES = ("trame.state.update", "trame.trigger")

# what a client is told when a call fails or is refused: one short line, never a trace or a path
SHORT_ERRORS = {
    wslink_protocol.AUTHENTICATION_ERROR: "Authentication failed",
    wslink_protocol.METHOD_NOT_FOUND: "Unknown method",
    wslink_protocol.EXCEPTION_ERROR: "The server could not handle this request",
    wslink_protocol.RESULT_SERIALIZE_ERROR: "The server could not send its answer",
}
REFUSED = -32600  # JSON-RPC "invalid request": a call this app does not accept

Screen = Callable[[Any], Any]  # a client value -> the value to store; ValueError: drop it


@dataclass(frozen=True)
class Limits:
    """Connection and memory caps (the defaults are the app's; tests pass small ones).

    message_bytes : largest message a client may send (an upload with its envelope) [bytes]
    connection_budget_bytes : partial (chunked) messages of one connection, together [bytes]
    total_budget_bytes : partial messages of all connections, together [bytes]
    partial_timeout_s : a partial message not completed in this time closes its connection [s]
    """

    max_connections: int = 32
    message_bytes: int = MAX_MESSAGE_BYTES
    connection_budget_bytes: int = MAX_MESSAGE_BYTES
    total_budget_bytes: int = 4 * MAX_MESSAGE_BYTES
    max_pending_messages: int = 4
    partial_timeout_s: float = 120.0


class Refused(Exception):
    """A message that closes its connection; the text goes to the server log only."""


# -- the memory budget of partial messages ---------------------------------------------------------
class PendingBudget:
    """Bytes announced by the partial messages of every connection (reserved on their first chunk,
    released when they complete or their connection closes)."""

    def __init__(self, limit_bytes: int):
        self.limit_bytes = limit_bytes
        self.reserved_bytes = 0

    def reserve(self, n_bytes: int) -> bool:
        if self.reserved_bytes + n_bytes > self.limit_bytes:
            return False
        self.reserved_bytes += n_bytes
        return True

    def release(self, n_bytes: int) -> None:
        self.reserved_bytes = max(0, self.reserved_bytes - n_bytes)


@dataclass
class _Partial:
    total: int
    started_s: float
    content: bytearray


class BoundedUnChunker:
    """Reassembles one connection's chunked messages within a memory budget (replaces wslink's
    ``UnChunker``, which allocates whatever size a first chunk announces).

    A new message is refused if it announces more than ``limits.message_bytes``, if the
    connection already has ``max_pending_messages`` partial messages, or if its announced size
    does not fit the connection's or the server's budget; chunks must come in order (the trame
    client sends them so) and memory grows only with the bytes received. Partial messages older
    than ``partial_timeout_s`` close the connection. Every refusal raises :class:`Refused`.
    """

    def __init__(self, limits: Limits, budget: PendingBudget, clock=time.monotonic):
        self.limits = limits
        self.budget = budget
        self.clock = clock
        self.pending: dict[int, _Partial] = {}

    @property
    def reserved_bytes(self) -> int:
        return sum(p.total for p in self.pending.values())

    def set_max_message_size(self, size: int) -> None:
        """wslink grants 4 GB after the hello; the limits here stay."""

    def release_pending_messages(self) -> None:
        for partial in self.pending.values():
            self.budget.release(partial.total)
        self.pending = {}

    def expired(self) -> bool:
        """A partial message has waited longer than the time-out."""
        now = self.clock()
        limit = self.limits.partial_timeout_s
        return any(now - p.started_s > limit for p in self.pending.values())

    def process_chunk(self, chunk: bytes) -> Any:
        """The decoded message if ``chunk`` completes one, else None. Raises Refused."""
        if len(chunk) < HEADER_LENGTH:
            raise Refused("a chunk shorter than its header")
        if self.expired():
            raise Refused(f"a partial message took over {self.limits.partial_timeout_s:g} s")
        msg_id, offset, total = _decode_header(chunk[:HEADER_LENGTH])
        content = chunk[HEADER_LENGTH:]
        partial = self.pending.get(msg_id)
        if partial is None:
            partial = self._open(msg_id, total)
        if total != partial.total or offset != len(partial.content):
            self._drop(msg_id)
            raise Refused("a chunk out of order or with another size")
        if offset + len(content) > total:
            self._drop(msg_id)
            raise Refused("a chunk past the end of its message")
        partial.content += content
        if len(partial.content) < total:
            return None
        self._drop(msg_id)
        try:
            return msgpack.unpackb(bytes(partial.content))
        except Exception as exc:  # malformed msgpack: many types
            raise Refused(f"an undecodable message ({type(exc).__name__})") from None

    def _open(self, msg_id: int, total: int) -> _Partial:
        limits = self.limits
        if total > limits.message_bytes:
            raise Refused(f"a message of {total:,} bytes (the limit is {limits.message_bytes:,})")
        if len(self.pending) >= limits.max_pending_messages:
            raise Refused(f"more than {limits.max_pending_messages} partial messages")
        if self.reserved_bytes + total > limits.connection_budget_bytes:
            raise Refused("partial messages over the connection's budget")
        if not self.budget.reserve(total):
            raise Refused("partial messages over the server's budget")
        partial = _Partial(total, self.clock(), bytearray())
        self.pending[msg_id] = partial
        return partial

    def _drop(self, msg_id: int) -> None:
        partial = self.pending.pop(msg_id, None)
        if partial is not None:
            self.budget.release(partial.total)


# -- values a client may write ---------------------------------------------------------------------
def scalar(value: Any) -> Any:
    """A number, a short string, a boolean or None (the controls' validators do the rest)."""
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, str) and len(value) <= MAX_SCALAR_CHARS:
        return value
    raise ValueError(f"not a scalar: {echo(value)}")


def boolean(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    raise ValueError(f"not a boolean: {echo(value)}")


def cleared(value: Any) -> str:
    """A message the page may only clear (closing its alert)."""
    if value in ("", None):
        return ""
    raise ValueError(f"a message may only be cleared, not set to {echo(value)}")


def mapping_of_names(value: Any) -> dict[str, str]:
    """A part -> material mapping of short strings."""
    if not isinstance(value, dict) or len(value) > MAX_MATERIAL_ENTRIES:
        raise ValueError(f"not a short mapping: {echo(value)}")
    for k, v in value.items():
        if not (isinstance(k, str) and isinstance(v, str)) or max(len(k), len(v)) > 256:
            raise ValueError("a mapping entry that is no short string")
    return value


def file_upload(value: Any) -> Any:
    """What trame's file input sends: a dict (or a list of at most one), or nothing."""
    if value is None or isinstance(value, dict):
        return value
    if isinstance(value, list) and len(value) <= 1 and all(isinstance(v, dict) for v in value):
        return value
    raise ValueError(f"not a file upload: {echo(value)}")


# -- the door: origin, token, connection cap -------------------------------------------------------
class Door:
    """The HTTP side: the access token, the allowed origins and the connection count."""

    def __init__(self, token: str, host: str, limits: Limits, origins: tuple[str, ...] = ()):
        self.token = token
        self.host = host.strip("[]").lower()
        self.limits = limits
        # the addresses a reverse proxy serves the app at (https://name[:port]): their pages
        # are the app's own too
        self.origins = {o for o in (normal_origin(u) for u in origins) if o}
        self.n_connections = 0
        self.n_refused = 0
        self.log = connections.ShortLog(log)  # one line per refusal, a few a second at most

    def cookie_name(self, request: web.Request) -> str:
        return f"lmapd-token-{_local_port(request)}"

    def token_ok(self, request: web.Request) -> tuple[bool, bool]:
        """(authorised, from the address): the token is in the query or in our cookie."""
        query = request.query.get("token", "")
        if query and hmac.compare_digest(query.encode(), self.token.encode()):
            return True, True
        cookie = request.cookies.get(self.cookie_name(request), "")
        return bool(cookie) and hmac.compare_digest(cookie.encode(), self.token.encode()), False

    def origin_problem(self, request: web.Request) -> str | None:
        """None if the request's Origin is the served page, else why not."""
        origin = request.headers.get("Origin")
        if not origin:
            return "no Origin header"
        try:
            parts = urlsplit(origin)
            port = parts.port or {"http": 80, "https": 443}.get(parts.scheme, 0)
        except ValueError:
            return f"a malformed Origin {echo(origin)}"
        name = (parts.hostname or "").lower()
        if normal_origin(origin) in self.origins:
            return None
        if parts.scheme not in ("http", "https") or port != _local_port(request):
            return f"a foreign Origin {echo(origin)}"
        if self.host in WILDCARD_HOSTS:  # any name may reach us: the page's own (same origin)
            allowed = {(request.url.host or "").strip("[]").lower()}
        elif self.host in LOOPBACK_NAMES:
            allowed = set(LOOPBACK_NAMES)
        else:
            allowed = {self.host}
        return None if name in allowed else f"a foreign Origin {echo(origin)}"

    @web.middleware
    async def middleware(self, request: web.Request, handler):
        authorised, from_address = self.token_ok(request)
        if request.path == WS_PATH or request.headers.get("Upgrade", "").lower() == "websocket":
            return await self._websocket(request, handler, authorised)
        if not authorised:
            self.n_refused += 1
            self.log.warning("token", "refused a request without the token from %s", request.remote)
            return web.Response(
                status=403,
                text="Forbidden: open the address that `lmapd app` printed (it carries the "
                "access token).\n",
            )
        response = await handler(request)
        if from_address:
            response.set_cookie(
                self.cookie_name(request), self.token, httponly=True, samesite="Strict", path="/"
            )
        return response

    async def _websocket(self, request: web.Request, handler, authorised: bool):
        problem = self.origin_problem(request)
        if problem is None and not authorised:
            problem = "no valid access token"
        if problem is None and self.n_connections >= self.limits.max_connections:
            self.log.warning(
                "cap", "refused a websocket: %d connections already", self.n_connections
            )
            self.n_refused += 1
            return web.Response(status=503, text="Too many connections\n")
        if problem is not None:
            self.log.warning(
                "websocket", "refused a websocket from %s: %s", request.remote, problem
            )
            self.n_refused += 1
            return web.Response(status=403, text="Forbidden\n")
        request[AUTHORISED] = True
        self.n_connections += 1
        try:
            return await handler(request)
        finally:
            self.n_connections -= 1


def normal_origin(url: str) -> str | None:
    """``scheme://host:port`` of an http(s) address (the port written out), or None."""
    try:
        parts = urlsplit(url.strip())
        port = parts.port or {"http": 80, "https": 443}.get(parts.scheme, 0)
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return None
    return f"{parts.scheme}://{parts.hostname.lower()}:{port}"


def _local_port(request: web.Request) -> int:
    sockname = request.transport.get_extra_info("sockname") if request.transport else None
    return int(sockname[1]) if sockname else 0


# -- the calls a client may make -------------------------------------------------------------------
class Guard(LinkProtocol):
    """Decides the wslink hello, bounds each connection's memory and screens every call."""

    def __init__(self, server, sync, limits: Limits):
        super().__init__()
        self.server = server
        self.sync = sync
        self.limits = limits
        self.budget = PendingBudget(limits.total_budget_bytes)
        self.handler = None
        self.authorised: set[str] = set()
        self.unchunkers: dict[str, BoundedUnChunker] = {}
        self.n_refused_calls = 0
        self.n_closed = 0
        self._sending: dict[str, set[asyncio.Task]] = {}  # page -> its state pushes under way
        self._send_now = None  # wslink's handler's own sendWrappedMessage (see _wrap)
        self._calls = {
            "trame.state.get": self._no_args,
            "trame.state.update": self._state_update,
            "trame.trigger": self._trigger,
            "trame.lifecycle.update": self._lifecycle,
            "trame.error.client": self._error_report,
        }

    # -- wslink's hooks --------------------------------------------------------------------------
    def init(self, publish, addAttachment, stopServer):  # wslink's names
        """wslink hands every link protocol its handler's ``publish``: wrap that handler."""
        super().init(publish, addAttachment, stopServer)
        handler = getattr(publish, "__self__", None)
        if handler is not None and handler is not self.handler:
            self.handler = handler
            self.sync.clients = self.clients
            self.sync.send = self.send_state
            self._wrap(handler)

    def onConnect(self, request, client_id):  # wslink's name
        getter = getattr(request, "get", None)
        if getter is not None and getter(AUTHORISED, False):
            self.authorised.add(client_id)
        unchunker = BoundedUnChunker(self.limits, self.budget)
        self.unchunkers[client_id] = unchunker
        if self.handler is not None:
            self.handler.unchunkers[client_id] = unchunker

    def onClose(self, client_id):  # wslink's name
        self.authorised.discard(client_id)
        unchunker = self.unchunkers.pop(client_id, None)
        if unchunker is not None:
            unchunker.release_pending_messages()
        self.sync.forget(client_id)
        self._sending.pop(client_id, None)

    async def validateToken(self, token, client_id):  # wslink's name
        """The hello succeeds only on a connection the middleware let in (origin and token)."""
        return client_id in self.authorised

    def clients(self) -> list[str]:
        """The connections that completed the hello."""
        handler = self.handler
        if handler is None:
            return []
        return [c for c in list(handler.connections) if handler.isClientAuthenticated(c)]

    def send_state(self, client_id: str, update: dict) -> None:
        """Send page ``client_id`` a state push now (the sync's ``send``). wslink's publish sends
        it on a later turn of the event loop, so the answer to the page's state update, sent at
        once, went ahead of the values the update caused (``busy``, a correction): the page saw its
        change answered and the server idle. A task started now keeps the pushes in order (tasks
        start in the order they are made, wslink's send lock queues them in turn) and the answers
        to the page wait for it (:meth:`_pushed`, see ``_wrap``)."""
        handler, send = self.handler, self._send_now
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if handler is None or send is None or loop is None:  # not on the server's loop
            self.sync.protocol.publish(STATE_TOPIC, update, client_id=client_id)
            return
        monitor = handler.network_monitor  # what wslink's publish counts, for trame's waits
        monitor.on_enter()
        task = loop.create_task(send(STATE_PUSH_ID, update, client_id=client_id))
        pending = self._sending.setdefault(client_id, set())
        pending.add(task)

        def done(task: asyncio.Task) -> None:
            pending.discard(task)
            monitor.on_exit()
            if not task.cancelled() and task.exception() is not None:
                log.info("a state push was not sent: %s", task.exception())

        task.add_done_callback(done)

    async def _pushed(self, client_id: str) -> None:
        """Wait until the state pushes to ``client_id`` made so far have been sent."""
        pending = self._sending.get(client_id)
        if pending:
            await asyncio.wait(list(pending))

    # -- wrapping wslink's handler ---------------------------------------------------------------
    def _wrap(self, handler) -> None:
        on_message = handler.onMessage
        on_complete = handler.onCompleteMessage
        send_error = handler.sendWrappedError
        self._send_now = send_message = handler.sendWrappedMessage

        async def guarded_message(is_binary, msg, client_id):
            try:
                if not is_binary:
                    raise Refused("a text message")
                await on_message(is_binary, msg, client_id)
            except Refused as exc:
                await self._close(client_id, str(exc))
            else:
                unchunker = self.unchunkers.get(client_id)
                if unchunker is not None and unchunker.pending:
                    self._watch_timeout(client_id)

        async def guarded_call(rpc, client_id):
            try:
                await self._screen_call(rpc, client_id, on_complete)
            except Exception:
                log.exception("handling a client's call failed")
                rpcid = rpc.get("id") if isinstance(rpc, dict) else None
                if isinstance(rpcid, str):
                    code = wslink_protocol.EXCEPTION_ERROR
                    await send_error(rpcid, code, SHORT_ERRORS[code], client_id=client_id)

        async def short_error(rpcid, code, message, data=None, client_id=None):
            if data:
                log.info("not sent to the client (%s): %s", message, str(data)[:MAX_TEXT])
            text = message if code == REFUSED else SHORT_ERRORS.get(code, "Request refused")
            await send_error(rpcid, code, text, client_id=client_id)

        async def answer_after_pushes(
            rpcid, content, method="", client_id=None, skip_last_active_client=False
        ):
            if client_id is not None and method in ANSWERED_AFTER_PUSHES:
                await self._pushed(client_id)  # the state the call caused goes first
            await send_message(
                rpcid,
                content,
                method=method,
                client_id=client_id,
                skip_last_active_client=skip_last_active_client,
            )

        handler.onMessage = guarded_message
        handler.onCompleteMessage = guarded_call
        handler.sendWrappedError = short_error
        handler.sendWrappedMessage = answer_after_pushes

    async def _close(self, client_id: str, why: str) -> None:
        log.warning("closing a connection: %s", why)
        self.n_closed += 1
        unchunker = self.unchunkers.get(client_id)
        if unchunker is not None:
            unchunker.release_pending_messages()
        ws = self.handler.connections.get(client_id) if self.handler else None
        if ws is not None and not ws.closed:
            await ws.close(code=WSCloseCode.POLICY_VIOLATION, message=b"refused")

    def _watch_timeout(self, client_id: str) -> None:
        def check() -> None:
            unchunker = self.unchunkers.get(client_id)
            if unchunker is not None and unchunker.expired():
                asyncio.ensure_future(self._close(client_id, "a partial message timed out"))

        asyncio.get_running_loop().call_later(self.limits.partial_timeout_s + 0.1, check)

    async def _screen_call(self, rpc: Any, client_id: str, dispatch) -> None:
        """Check one decoded call; pass the allowed ones to wslink, answer the rest short."""
        if not isinstance(rpc, dict) or not isinstance(rpc.get("id"), str):
            log.warning("dropped a message with no call id")
            return
        rpcid, method = rpc["id"], rpc.get("method")
        args, kwargs = rpc.get("args", []), rpc.get("kwargs", {})
        if rpcid.startswith("system:"):  # the hello: wslink asks validateToken
            await dispatch(rpc, client_id)
            return
        if not self.handler.isClientAuthenticated(client_id):
            await dispatch(rpc, client_id)  # wslink answers "Unauthorized"
            return
        check = self._calls.get(method) if isinstance(method, str) else None
        if check is None:
            await self._refuse(rpcid, client_id, "This call is not allowed", method)
            return
        if not isinstance(args, list) or not isinstance(kwargs, dict) or kwargs:
            await self._refuse(rpcid, client_id, "Malformed call", method)
            return
        problem, args = check(args)
        if problem:
            await self._refuse(rpcid, client_id, problem, method)
            return
        if method == "trame.state.update":
            self.sync.apply_client_changes(client_id, args[0])
            # answered after the state it caused (busy, corrections): answer_after_pushes
            await self.handler.sendWrappedMessage(rpcid, None, method=method, client_id=client_id)
            return
        await dispatch({**rpc, "args": args, "kwargs": {}}, client_id)

    async def _refuse(self, rpcid: str, client_id: str, text: str, method: Any) -> None:
        self.n_refused_calls += 1
        log.warning("refused a call to %s: %s", echo(method), text)
        await self.handler.sendWrappedError(rpcid, REFUSED, text, client_id=client_id)

    # -- the allowed calls, each: (problem or None, the arguments to pass on) --------------------
    @staticmethod
    def _no_args(args: list) -> tuple[str | None, list]:
        return (None, args) if not args else ("Malformed call", args)

    @staticmethod
    def _state_update(args: list) -> tuple[str | None, list]:
        if len(args) != 1 or not isinstance(args[0], list) or len(args[0]) > MAX_CHANGES:
            return "Malformed state update", args
        changes = []
        for change in args[0]:
            if not isinstance(change, dict) or not isinstance(change.get("key"), str):
                return "Malformed state update", args
            changes.append((change["key"], change.get("value")))
        return None, [changes]

    def _trigger(self, args: list) -> tuple[str | None, list]:
        if not 1 <= len(args) <= 3:
            return "Malformed trigger", args
        name, t_args, t_kwargs = (list(args) + [[], {}])[:3]
        if t_args is None:
            t_args = []
        if t_kwargs is None:
            t_kwargs = {}
        if not isinstance(name, str) or len(name) > MAX_TRIGGER_NAME:
            return "Malformed trigger", args
        if not isinstance(t_args, list) or not isinstance(t_kwargs, dict):
            return "Malformed trigger", args
        if not all(isinstance(k, str) for k in t_kwargs):
            return "Malformed trigger", args
        if not self.server.controller.trigger_fn(name):
            return "Unknown action", args
        return None, [name, t_args, t_kwargs]

    @staticmethod
    def _lifecycle(args: list) -> tuple[str | None, list]:
        # the trame page reports its own connection and exit; the server's own life cycle
        # (server_exited, server_ready, ...) is the server's business only
        if args in (["client_connected"], ["client_exited"]):
            return None, args
        return "This life-cycle call is not allowed", args

    @staticmethod
    def _error_report(args: list) -> tuple[str | None, list]:
        if len(args) != 1:
            return "Malformed call", args
        return None, [str(args[0])[:MAX_TEXT]]


def install(
    server,
    *,
    token: str,
    host: str,
    client_keys: Mapping[str, Screen],
    limits: Limits | None = None,
    origins: tuple[str, ...] = (),
):
    """Lock ``server`` (a trame Server, before it starts) to its own page (and the pages of
    ``origins``, a reverse proxy's addresses): returns the guard and the door (their counters
    are read by tests)."""
    limits = limits or Limits()
    sync = ClientStateSync(server.state, client_keys)
    guard = Guard(server, sync, limits)
    door = Door(token, host, limits, origins)

    def configure(core_protocol) -> None:
        core_protocol.registerLinkProtocol(guard)
        sync.attach(core_protocol)

    def bind(web_app) -> None:
        connections.guard_app(web_app.app)  # idle and partial connections closed
        web_app.app.middlewares.append(door.middleware)

    connections.guard_wslink_sites()
    server.add_protocol_to_configure(configure)
    server.controller.on_server_bind.add(bind)
    server.options["ws_max_msg_size"] = WS_CHUNK_BYTES
    return guard, door
