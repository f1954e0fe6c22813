"""The websocket's caps: the connection and memory limits (:class:`Limits`), and the reassembly of
a connection's chunked messages within a memory budget (:class:`BoundedUnChunker`, which replaces
wslink's ``UnChunker``; wslink 2.6.0). Every refusal raises :class:`Refused`, which closes the
connection (:mod:`app.server.guard`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import msgpack
from wslink.chunking import HEADER_LENGTH, _decode_header

from app.logic.upload import MAX_UPLOAD_BYTES

MIB = 2**20
MAX_MESSAGE_BYTES = MAX_UPLOAD_BYTES + 16 * MIB  # an upload plus its envelope, with margin
WS_CHUNK_BYTES = 4 * MIB  # websocket frames (wslink chunks) in both directions


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
