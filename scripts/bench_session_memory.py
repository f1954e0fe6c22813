"""Benchmark of a class's sessions without a browser: the memory that N open sessions hold and
the time a new session takes to its first frame while they are open, with each session its own
process (``lmapd app``) and with sessions forked from the preloaded parent (``--fork-sessions``).

    .venv/bin/python scripts/bench_session_memory.py [--sessions 10]

For each mode it starts the launcher (no spare), opens N sessions one after the other as a page
would (the door, then the session's websocket: the wslink hello, a state change, its frame), then
sums the proportional set size (PSS: shared pages split between the processes that share them)
of every process under the launcher (the sessions, and the parent when forking), and times one
more session from the door's request to its first frame (the server's frame of the paper scene
at 256 x 256 pixels; a browser would also draw it).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

import aiohttp
import psutil
from support.hostile_client import Client
from support.launch import app_process

NAVIGATION = {"Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}


async def open_session(running) -> tuple[aiohttp.ClientSession, Client, float]:
    """A session as a tab opens it, up to its first frame: (its client, its page, seconds)."""
    started = time.perf_counter()
    client = aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar())
    async with client.get(running.url, headers=NAVIGATION) as answer:
        assert answer.status == 200, answer.status
        jar = {k: m.value for k, m in answer.cookies.items()}
        text = await answer.text()
    location = json.loads(text.split("location.replace(")[1].split(");")[0])
    path = location.split("#")[0].split("?")[0]
    ws = await client.ws_connect(
        f"ws://127.0.0.1:{running.port}{path}ws",
        headers={
            "Origin": running.origin,
            "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items()),
        },
        max_msg_size=0,
    )
    page = Client(ws)
    await page.hello()
    state = (await page.call("trame.state.get"))["result"]["state"]
    if not state.get("frame_generation"):  # the session's first frame: still computing
        await page.wait_state(lambda s: s.get("frame_generation", 0) > 0)
    return client, page, time.perf_counter() - started


def pss_mb(pid: int) -> float:
    total = 0
    for proc in psutil.Process(pid).children(recursive=True):
        try:
            total += proc.memory_full_info().pss
        except psutil.Error:
            pass
    return total / 2**20


async def one_mode(fork: bool, n: int) -> dict:
    mode = "--fork-sessions" if fork else "--process-sessions"
    args = ("--no-spare", "--max-sessions", str(n + 2), mode)
    with app_process(sessions=True, app_args=args) as running:
        opened, times = [], []
        for _ in range(n):
            client, page, seconds = await open_session(running)
            opened.append(client)
            times.append(seconds)
        await asyncio.sleep(2.0)
        held = pss_mb(running.pid)
        client, _, new_s = await open_session(running)
        opened.append(client)
        for c in opened:
            await c.close()
    return {"fork": fork, "pss_mb": held, "new_s": new_s, "open_s": times}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=int, default=10)
    parser.add_argument(
        "--modes",
        nargs="+",
        choices=("process", "fork"),
        default=["process", "fork"],
        help="a process per session, forked sessions, or both (the default)",
    )
    args = parser.parse_args(argv)
    for fork in [mode == "fork" for mode in args.modes]:
        r = asyncio.run(one_mode(fork, args.sessions))
        mode = "forked from the parent" if fork else "a process each     "
        print(
            f"{mode}: {args.sessions} sessions hold {r['pss_mb']:,.0f} MB PSS "
            f"({r['pss_mb'] / args.sessions:,.0f} MB each, the parent included); "
            f"a new one to its first frame {r['new_s']:.1f} s with them open; "
            f"opening them: median {statistics.median(r['open_s']):.1f} s",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
