"""A websocket client that speaks wslink's protocol as trame's page does (msgpack messages in
chunks with a 12-byte header; the hello carries a secret), for tests that act as a hostile page.

Every wait has a generous limit that only catches hangs.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable
from typing import Any

import aiohttp
import msgpack
from wslink.chunking import UnChunker, _encode_header, generate_chunks

from support.launch import RunningApp

WAIT_S = 60.0
CHUNK = 4 * 2**20


class Client:
    """One connection: calls (answered by id) and the state pushes seen meanwhile."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse):
        self.ws = ws
        self._unchunker = UnChunker()
        self._unchunker.set_max_message_size(2**31)
        self._ids = itertools.count(1)
        self.states: list[dict] = []  # every trame.state.topic push received, in order
        self.messages: list[dict] = []  # every message received

    async def send(self, message: dict) -> None:
        for chunk in generate_chunks(msgpack.packb(message), CHUNK):
            await self.ws.send_bytes(chunk)

    async def call(self, method: str, args: Any = None, kwargs: Any = None, **fields) -> dict:
        """Send one call and return its answer (``result`` or ``error``)."""
        rpcid = fields.pop("id", f"rpc:c0:{next(self._ids)}")
        message = {"wslink": "1.0", "id": rpcid, "method": method, "args": args or []}
        message["kwargs"] = {} if kwargs is None else kwargs
        message.update(fields)
        await self.send(message)
        return await self.receive_until(lambda m: m.get("id") == rpcid)

    async def hello(self, secret: str = "wslink-secret") -> dict:
        return await self.call("wslink.hello", [{"secret": secret}], id="system:c0:0")

    async def set_state(self, **values) -> dict:
        changes = [{"key": k, "value": v} for k, v in values.items()]
        return await self.call("trame.state.update", [changes])

    async def receive_until(self, done: Callable[[dict], bool], wait_s: float = WAIT_S) -> dict:
        """Read messages until one satisfies ``done``; raises ConnectionError if it closes."""
        while True:
            msg = await asyncio.wait_for(self.ws.receive(), wait_s)
            if msg.type != aiohttp.WSMsgType.BINARY:
                raise ConnectionError(f"connection ended: {msg.type.name} {msg.data!r}")
            full = self._unchunker.process_chunk(msg.data)
            if full is None:
                continue
            self.messages.append(full)
            if str(full.get("id", "")).startswith("publish:trame.state.topic"):
                self.states.append(full["result"])
            if done(full):
                return full

    async def wait_state(self, predicate: Callable[[dict], bool]) -> dict:
        """Read until a state push satisfies ``predicate``; return that push."""
        found: list[dict] = []

        def done(message: dict) -> bool:
            if str(message.get("id", "")).startswith("publish:trame.state.topic"):
                if predicate(message["result"]):
                    found.append(message["result"])
                    return True
            return False

        await self.receive_until(done)
        return found[0]

    def seen(self, key: str) -> list:
        """The values of ``key`` in the state pushes received so far."""
        return [s[key] for s in self.states if key in s]

    async def send_raw_chunk(self, msg_id: int, offset: int, total: int, content: bytes) -> None:
        await self.ws.send_bytes(_encode_header(msg_id, offset, total) + content)


RIGHT = "the server's own"  # connect()'s default origin and token: the app's


def ws_url(app: RunningApp, token: str | None = RIGHT) -> str:
    token = app.token if token == RIGHT else token
    query = f"?token={token}" if token is not None else ""
    return f"ws://127.0.0.1:{app.port}/ws{query}"


async def connect(
    session: aiohttp.ClientSession,
    app: RunningApp,
    *,
    origin: str | None = RIGHT,
    token: str | None = RIGHT,
    hello: bool = True,
) -> Client:
    """A connection as the app's own page makes it (unless told otherwise); raises
    aiohttp.WSServerHandshakeError when the server refuses the upgrade."""
    headers = {"Origin": app.origin if origin == RIGHT else origin} if origin is not None else {}
    ws = await session.ws_connect(ws_url(app, token), headers=headers, max_msg_size=0)
    client = Client(ws)
    if hello:
        answer = await client.hello()
        assert "result" in answer, answer
    return client
