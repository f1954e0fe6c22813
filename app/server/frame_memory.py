"""One memory budget for the heavy frames of every session at once (``lmapd app`` with sessions).

Each session refuses a frame estimated over its own limit (``--frame-memory-mb``,
app.engine.check_memory), but sessions running heavy frames together could still take the
machine: two 256 px frames at the *reference* preset grew the launcher's tree by about 1.3 GB.
So the launcher holds a budget for the frames in flight across its sessions
(``--frames-in-flight-mb``, :class:`FrameMemory`), and a session asks it before a heavy frame
(:class:`FrameGrants`, in its frame runner's thread, never on the page's event loop):

* the launcher listens on a Unix socket in a folder of its own (mode 0700), whose path its
  children find in the environment (``LMAPD_FRAMES_SOCKET``); a session connects once per heavy
  frame and sends one line, ``{"token": T, "bytes": N}``: ``T`` its private token (the launcher
  gave it on stdin), ``N`` the frame's estimate (app.engine.frame_bytes). The launcher answers
  ``{"granted": true}`` when the estimate fits beside the frames in flight, else
  ``{"ahead": K}`` (the frame waits in a first-come queue with ``K`` frames ahead of it; again
  each time ``K`` changes) and the grant later, or ``{"refused": TEXT}`` at once when the
  estimate is over the whole budget (it could never run);
* the grant lasts as long as the connection: the session closes it when its frame is done, when
  the frame is overtaken while it waits (the slider moved again: its place in the queue is given
  up), or by dying (the kernel closes a dead process's sockets); the launcher also closes the
  connections of a session it stops;
* frames estimated under ``LIGHT_FRAME_BYTES`` (the interactive preset up to 256 x 256 pixels)
  ask nothing: normal use pays no round trip.

A session that cannot reach the launcher (no socket in its environment: ``--shared``) runs its
frames under its own limit only.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import hmac
import json
import logging
import os
import shutil
import socket
import tempfile
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from app.engine import FrameRefused
from app.runner import StaleRequest

log = logging.getLogger(__name__)

MIB = 2**20
ENV = "LMAPD_FRAMES_SOCKET"  # the launcher's socket, in its children's environment
LIGHT_FRAME_BYTES = 64 * MIB  # a frame estimated under this asks nothing
LINE_LIMIT = 4096  # the longest line a session may send [bytes]
HELLO_TIMEOUT_S = 10.0  # a connection that sends no request line in this time is closed
POLL_S = 0.1  # how often a waiting session checks whether its frame was overtaken [s]


# -- the launcher's side --------------------------------------------------------------------------
@dataclass(eq=False)
class _Ask:
    owner: object  # the session's process (app.server.children.Child)
    need_bytes: int
    writer: asyncio.StreamWriter
    granted: bool = False
    ahead: int = -1  # the place in the queue last told (-1: none yet)


class FrameMemory:
    """The launcher's budget for frames in flight across its sessions (see the module).

    budget_bytes : what the granted frames' estimates may add up to [bytes]
    find : the session process whose private token is the given one, or None
    """

    def __init__(self, budget_bytes: int, find: Callable[[str], object | None]):
        self.budget_bytes = int(budget_bytes)
        self.find = find
        self.in_use_bytes = 0
        self.granted: list[_Ask] = []
        self.queue: collections.deque[_Ask] = collections.deque()
        self.folder: str | None = None
        self.path: str | None = None
        self._server: asyncio.AbstractServer | None = None
        # what happened, for the log, the tests and the benchmark
        self.n_asked = 0
        self.n_granted = 0
        self.n_waited = 0  # grants that had to wait in the queue
        self.n_refused = 0  # over the whole budget
        self.n_dropped = 0  # gave up their place, or their session ended, before a grant
        self.most_in_use_bytes = 0
        self.most_at_once = 0  # granted frames at once
        self.most_waiting = 0

    async def start(self) -> str:
        """Listen on a new socket in a private folder; its path (also in ``self.path``)."""
        self.folder = tempfile.mkdtemp(prefix="lmapd-frames-")  # mode 0700: this user only
        self.path = os.path.join(self.folder, "frames.sock")
        self._server = await asyncio.start_unix_server(self._serve, self.path, limit=LINE_LIMIT)
        os.chmod(self.path, 0o600)
        return self.path

    async def close(self) -> None:
        for ask in [*self.granted, *self.queue]:
            ask.writer.close()
        self.granted, self.queue = [], collections.deque()
        self.in_use_bytes = 0
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)

    @property
    def waiting(self) -> int:
        return len(self.queue)

    def release_owner(self, owner: object) -> int:
        """Close the connections of ``owner``'s frames (a session stopped or found dead): its
        grants go back to the budget and its waiting frames leave the queue. How many."""
        mine = [a for a in (*self.granted, *self.queue) if a.owner is owner]
        for ask in mine:
            self._drop(ask)
            ask.writer.close()
        if mine:
            self._pump()
        return len(mine)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        ask = None
        try:
            ask = await self._read_ask(reader, writer)
            if ask is None:
                return
            self.n_asked += 1
            if ask.need_bytes > self.budget_bytes:
                self.n_refused += 1
                _send(writer, {"refused": refusal(ask.need_bytes, self.budget_bytes)})
                return
            self.queue.append(ask)
            self._pump()
            # the grant lasts until the session closes the connection (or dies)
            while await reader.read(LINE_LIMIT):
                pass
        except (ConnectionError, OSError, asyncio.IncompleteReadError, ValueError):
            pass
        finally:
            if ask is not None:
                self._drop(ask)
                self._pump()
            writer.close()

    async def _read_ask(self, reader, writer) -> _Ask | None:
        try:
            line = await asyncio.wait_for(reader.readline(), HELLO_TIMEOUT_S)
            message = json.loads(line)
            token, need = message["token"], message["bytes"]
            if not isinstance(token, str) or not isinstance(need, int) or need < 0:
                raise ValueError("malformed")
        except (TimeoutError, ValueError, KeyError, TypeError):
            log.warning("frame memory: a malformed request on the sessions' socket")
            return None
        owner = self.find(token)
        if owner is None:
            log.warning("frame memory: a request without a session's token")
            return None
        return _Ask(owner, need, writer)

    def _drop(self, ask: _Ask) -> None:
        if ask.granted:
            with contextlib.suppress(ValueError):
                self.granted.remove(ask)
                self.in_use_bytes -= ask.need_bytes
            ask.granted = False
        elif ask in self.queue:
            self.queue.remove(ask)
            self.n_dropped += 1

    def _pump(self) -> None:
        """Grant the frames at the head of the queue that fit (first come, first served: a small
        frame does not pass a large one that waits), and tell the others their place."""
        while self.queue and self.in_use_bytes + self.queue[0].need_bytes <= self.budget_bytes:
            ask = self.queue.popleft()
            ask.granted = True
            self.granted.append(ask)
            self.in_use_bytes += ask.need_bytes
            self.n_granted += 1
            self.n_waited += ask.ahead >= 0
            self.most_in_use_bytes = max(self.most_in_use_bytes, self.in_use_bytes)
            self.most_at_once = max(self.most_at_once, len(self.granted))
            _send(ask.writer, {"granted": True})
        self.most_waiting = max(self.most_waiting, len(self.queue))
        for place, ask in enumerate(self.queue):
            if ask.ahead != place:
                ask.ahead = place
                _send(ask.writer, {"ahead": place})


def budget_for(budget_bytes: int | None, children: Iterable) -> FrameMemory | None:
    """The launcher's budget of ``budget_bytes`` (None: no budget) for its ``children`` (the
    set of its session processes, each with its private ``token``: kept up to date by the
    launcher, read at each request)."""
    if budget_bytes is None:
        return None

    def find(token: str):
        for child in list(children):
            if child.token and hmac.compare_digest(child.token.encode(), token.encode()):
                return child
        return None

    return FrameMemory(budget_bytes, find)


def _send(writer: asyncio.StreamWriter, message: dict) -> None:
    if not writer.is_closing():
        writer.write(json.dumps(message).encode() + b"\n")


def refusal(need_bytes: int, budget_bytes: int) -> str:
    """The message of a frame that could never fit in the server's budget."""
    return (
        f"this frame would take about {need_bytes / 1e9:.2g} GB of memory, and this server keeps "
        f"{budget_bytes / 1e9:.2g} GB for the frames of all its sessions together: lower the "
        "Pixels, or choose a fidelity preset with fewer sub-rays per pixel"
    )


# -- a session's side -----------------------------------------------------------------------------
class Grant:
    """A frame's place in the budget: held until :meth:`close` (or the process's end)."""

    def __init__(self, sock: socket.socket | None = None):
        self._sock = sock

    def close(self) -> None:
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.close()
            self._sock = None

    def __enter__(self) -> Grant:
        return self

    def __exit__(self, *_) -> None:
        self.close()


def _answer(line: bytes) -> dict:
    """The launcher's answer on one line; ConnectionError if it is none."""
    try:
        message = json.loads(line)
    except ValueError:
        message = None
    if not isinstance(message, dict):
        raise ConnectionError("a malformed answer on the frames' socket")
    return message


class FrameGrants:
    """A session's end of the launcher's budget (see the module); blocking calls, for the frame
    runner's worker thread only.

    path : the launcher's socket; token : this session's private token
    """

    def __init__(self, path: str, token: str, light_bytes: int = LIGHT_FRAME_BYTES):
        self.path = path
        self.token = token
        self.light_bytes = light_bytes
        self._warned = threading.Event()
        self.n_asked = 0
        self.n_waited = 0

    @classmethod
    def from_environment(cls, token: str) -> FrameGrants | None:
        """The grants of a session started by a launcher, or None (no launcher's socket)."""
        path = os.environ.get(ENV, "")
        return cls(path, token) if path else None

    def ask(
        self,
        need_bytes: int,
        overtaken: Callable[[], bool] = lambda: False,
        waiting: Callable[[int | None], None] = lambda ahead: None,
    ) -> Grant:
        """A grant for a frame estimated at ``need_bytes`` (at once, and with no round trip, for a
        light frame); blocks while the frame waits, calling ``waiting(ahead)`` as its place in
        the queue changes and ``waiting(None)`` once the wait is over. Raises StaleRequest if
        ``overtaken()`` while waiting (the place is given up), FrameRefused if the frame could
        never fit. A launcher that cannot be reached lets the frame run (it is bounded by the
        session's own limit) and logs one line."""
        if need_bytes < self.light_bytes:
            return Grant()
        self.n_asked += 1
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        waited = False
        try:
            sock.settimeout(HELLO_TIMEOUT_S)
            sock.connect(self.path)
            sock.sendall(
                json.dumps({"token": self.token, "bytes": int(need_bytes)}).encode() + b"\n"
            )
            sock.settimeout(POLL_S)
            pending = b""
            while True:
                if overtaken():
                    raise StaleRequest
                try:
                    data = sock.recv(LINE_LIMIT)
                except TimeoutError:
                    continue
                if not data:
                    raise ConnectionError("the launcher closed the frames' socket")
                pending += data
                while b"\n" in pending:
                    line, pending = pending.split(b"\n", 1)
                    message = _answer(line)
                    if "refused" in message:
                        raise FrameRefused(str(message["refused"]))
                    if message.get("granted") is True:
                        return Grant(sock)
                    if isinstance(message.get("ahead"), int):
                        waited = True
                        self.n_waited += 1
                        waiting(message["ahead"])
        except OSError as exc:  # no launcher: the session's own limit only
            sock.close()
            if not self._warned.is_set():
                self._warned.set()
                log.warning("frame memory: the launcher's budget cannot be reached (%s)", exc)
            return Grant()
        except BaseException:
            sock.close()
            raise
        finally:
            if waited:
                waiting(None)
