"""A stand-in for one session's app process, for the launcher's tests (app.server.launcher): it
reads its token from stdin as ``python -m app --token-stdin`` does, listens on a free 127.0.0.1
port, prints the line the app prints, serves one page that says whether the request carried its
token, and echoes websocket frames to a caller with its token and its own origin. It stops when
stdin closes.
Run as ``python tests/support/fake_session.py``; it starts in well under a second, so the tests
can start many.
"""

from __future__ import annotations

import asyncio
import sys

from aiohttp import WSMsgType, web


async def main() -> None:
    token = sys.stdin.readline().strip()

    def own(request: web.Request) -> bool:
        port = request.transport.get_extra_info("sockname")[1]
        return request.cookies.get(f"lmapd-token-{port}") == token

    async def page(request: web.Request) -> web.Response:
        verdict = "token ok" if own(request) else "no token"
        return web.Response(text=f"session page; {verdict}; query {request.query_string}")

    async def socket(request: web.Request) -> web.StreamResponse:
        port = request.transport.get_extra_info("sockname")[1]
        if not own(request) or request.headers.get("Origin") != f"http://127.0.0.1:{port}":
            return web.Response(status=403, text="Forbidden\n")
        ws = web.WebSocketResponse(max_msg_size=0)
        await ws.prepare(request)
        async for msg in ws:
            if msg.type == WSMsgType.BINARY:
                await ws.send_bytes(msg.data)
        return ws

    app = web.Application()
    app.router.add_get("/ws", socket)
    app.router.add_get("/{tail:.*}", page)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    port = site._server.sockets[0].getsockname()[1]
    print(f"lmapd-sim app: http://127.0.0.1:{port}/?token=not-shown", flush=True)
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, sys.stdin.read)  # until the launcher closes stdin
    await runner.cleanup()


if __name__ == "__main__":
    asyncio.run(main())
