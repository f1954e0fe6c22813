"""The launcher's proxy to a session's process: its pages (GET and HEAD, with the process's own
private token, passing back only ``PASSED_HEADERS``) and its websocket (frames passed both ways,
at most ``FRAME_BYTES`` each; the page's frames are its session's input). The checks come first,
in app.server.launcher: the session's cookie, the path, the websocket's origin and count."""

from __future__ import annotations

import asyncio
import logging
import time
from urllib.parse import quote

import aiohttp
from aiohttp import web

from app.server import connections, security
from app.server.children import Child

log = logging.getLogger("app.server.launcher")  # the proxy's lines keep their logger's name

# a session's process that has not sent a byte of its answer this long is taken as stuck (a
# stopped or swapping process): the page gets a 504 instead of waiting for ever [s]
READ_S = 30.0
SESSION_ENDED = 4000  # the websocket close code of an ended session (the page says so)
FRAME_BYTES = security.WS_CHUNK_BYTES + 4096  # one websocket frame: a wslink chunk and its header
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


def client_session() -> aiohttp.ClientSession:
    """The launcher's client of its sessions' processes (made on the launcher's loop)."""
    return aiohttp.ClientSession(
        auto_decompress=False,
        timeout=aiohttp.ClientTimeout(total=None, sock_connect=10),
        # closed by this side before a session's guard closes an idle one (its 10 s)
        connector=aiohttp.TCPConnector(keepalive_timeout=connections.IDLE_S / 2),
    )


async def http(
    client: aiohttp.ClientSession,
    request: web.Request,
    child: Child,
    rest: str,
    read_s: float | None = None,
) -> web.Response:
    """Pass a page's GET or HEAD of ``rest`` to its session's process (its token left out); a
    504 if the process sends nothing for ``read_s`` (default ``READ_S``)."""
    read_s = READ_S if read_s is None else read_s
    query = [(k, v) for k, v in request.query.items() if k != "token"]
    url = f"{child.origin}{_path(rest)}"
    headers = {"Cookie": child.cookie}
    if "Accept-Encoding" in request.headers:
        headers["Accept-Encoding"] = request.headers["Accept-Encoding"]
    try:
        async with client.request(
            request.method,
            url,
            params=query,
            headers=headers,
            allow_redirects=False,
            timeout=aiohttp.ClientTimeout(total=None, sock_connect=10, sock_read=read_s),
        ) as answer:
            body = await answer.read()
            passed = {k: answer.headers[k] for k in PASSED_HEADERS if k in answer.headers}
            return web.Response(status=answer.status, body=body, headers=passed)
    except TimeoutError:
        log.warning("session process %d sent nothing for %g s", child.pid, read_s)
        return web.Response(status=504, text="The session's process is not answering\n")
    except (aiohttp.ClientError, OSError) as exc:
        log.warning("session process %d did not answer: %s", child.pid, exc)
        return web.Response(status=502, text="The session's process did not answer\n")


async def websocket(
    client: aiohttp.ClientSession, request: web.Request, child: Child
) -> web.StreamResponse:
    """Join a page's websocket to its session's process until either closes (counted in the
    session's ``n_sockets``; its page's frames are the session's input)."""
    child.n_sockets += 1
    page = web.WebSocketResponse(
        max_msg_size=FRAME_BYTES, heartbeat=30.0, compress=deflates(request)
    )
    upstream = None
    try:
        try:
            upstream = await client.ws_connect(
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
        child.connected = True
        child.pages.add(page)
        tasks = [
            asyncio.create_task(_pump(page, upstream, child)),
            asyncio.create_task(_pump(upstream, page)),
        ]
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)  # each one's end read, none logged
        if upstream.closed and upstream.close_code == SESSION_ENDED and not page.closed:
            # the session ended itself (unused): the page says "session ended"
            await page.close(code=SESSION_ENDED, message=b"session ended")
    finally:
        child.n_sockets -= 1
        child.pages.discard(page)
        child.idle_since_s = time.monotonic()
        if upstream is not None:
            await upstream.close()
        if page.prepared:
            await page.close()
    return page


def deflates(request: web.Request) -> bool:
    """Whether a page's websocket is compressed (permessage-deflate, if its browser offers it):
    only for a page on another machine. On this one, deflating a first state of 3.8 MB (the
    paper scene at 256 x 256 pixels) to 1.5 MB cost the launcher 0.21 s of CPU at zlib's default
    level and saved nothing; over a network it sends 2.5 times fewer bytes. A reverse proxy on
    this machine passes other machines' pages on (it says so in ``X-Forwarded-For`` or
    ``Forwarded``): those are compressed."""
    headers = request.headers
    if "X-Forwarded-For" in headers or "Forwarded" in headers:
        return True
    return (request.remote or "") not in security.LOOPBACK_NAMES


async def _pump(source, sink, child: Child | None = None) -> None:
    """Pass one websocket's frames to another until either closes; frames from a page
    (``child`` given) are its session's input."""
    try:
        async for msg in source:
            if child is not None:
                child.last_input_s = time.monotonic()
            if msg.type == aiohttp.WSMsgType.BINARY:
                await sink.send_bytes(msg.data)
            elif msg.type == aiohttp.WSMsgType.TEXT:
                await sink.send_str(msg.data)  # refused by the process's guard (closes)
            else:
                break
    except (aiohttp.ClientError, ConnectionError):  # the other side closed meanwhile: done
        return


def _path(rest: str) -> str:
    return quote(rest, safe="/-_.~")
