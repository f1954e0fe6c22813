"""The calls a client may make: a wslink ``LinkProtocol`` (registered through trame-server's
``Server.add_protocol_to_configure``; checked against trame-server 4.1.0 and wslink 2.6.0) that

* decides the wslink hello (``validateToken``: only connections the door let in);
* gives each connection a :class:`~app.server.budget.BoundedUnChunker` (one memory budget per
  connection and one in total, a time-out for partial messages);
* wraps four methods of wslink's handler instance: text messages and refused chunks close the
  connection; each call is checked against an allow-list before wslink dispatches it; errors sent
  to a client are one short line (the trace stays in the server log); the answer to a page's
  state update or trigger waits for the state pushes to that page made before it
  (:meth:`Guard.send_state`).
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any

from aiohttp import WSCloseCode
from wslink import protocol as wslink_protocol
from wslink.websocket import LinkProtocol

from app.server.budget import BoundedUnChunker, Limits, PendingBudget, Refused
from app.server.door import AUTHORISED
from app.server.sync import STATE_TOPIC
from app.state import echo

log = logging.getLogger("app.server.security")  # the door's lines keep their logger's name

MAX_TEXT = 500  # a client's error report is logged at most this long
MAX_TRIGGER_NAME = 100
MAX_CHANGES = 256  # state changes in one update
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

    async def close_all(self, code: int, message: bytes) -> None:
        """Close every page's websocket with ``code`` (a session ending itself)."""
        connections = dict(self.handler.connections) if self.handler else {}
        for ws in connections.values():
            if not ws.closed:
                await ws.close(code=code, message=message)

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
        pushed = self.sync.n_pushed_keys
        await dispatch({**rpc, "args": args, "kwargs": {}}, client_id)
        if method == "trame.trigger" and self.sync.n_pushed_keys > pushed:
            self.sync.last_change_s = time.monotonic()  # the trigger changed the state

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
