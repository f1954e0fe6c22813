"""Benchmark of a class's sessions without a browser: the memory that N open sessions hold and
the time a new session takes to its first frame while they are open, with each session its own
process (``lmapd app``) and with sessions forked from the preloaded parent (``--fork-sessions``).

    .venv/bin/python scripts/bench_session_memory.py [--sessions 10] [--moved]

For each mode it starts the launcher (no spare), opens N sessions one after the other as a page
would (the door, then the session's websocket: the wslink hello, its state, its first frame; with
``--moved`` then a frame of its own, the pitch moved: a forked session's first frame is its
parent's, shared until it computes another), then
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


async def open_session(running, moved: bool = False) -> tuple[aiohttp.ClientSession, Client, float]:
    """A session as a tab opens it, up to its first frame: (its client, its page, seconds).
    ``moved``: then the pitch moves to 10 deg and the session's own frame of it is waited for
    (a forked session's first frame is its parent's: a student who moves a slider holds frames
    of their own; the seconds are still to the first frame)."""
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
        state = await page.wait_state(lambda s: s.get("frame_generation", 0) > 0)
    seconds = time.perf_counter() - started
    if moved:
        await own_frame(page, state)
    return client, page, seconds


async def own_frame(page: Client, state: dict) -> None:
    """Move the pitch and wait for the session's frame of it, each frame reported shown as a page
    does (the server paces its frames by those reports)."""
    first = generation = state["frame_generation"]
    await page.call("trame.trigger", ["frame_shown", [state["frame_key"]], {}])
    seen = len(page.states)
    await page.set_state(pitch_deg=10.0)
    while True:
        if len(page.states) == seen:  # nothing new among the messages read so far
            await page.wait_state(lambda s: True)
        pushed, seen = page.states[seen], seen + 1
        generation = pushed.get("frame_generation", generation)  # sent when it changes
        if "frame_key" not in pushed:
            continue
        await page.call("trame.trigger", ["frame_shown", [pushed["frame_key"]], {}])
        if generation > first and pushed.get("frame_kind") == "preset":
            return


def pss_mb(pid: int) -> float:
    total = 0
    for proc in psutil.Process(pid).children(recursive=True):
        try:
            total += proc.memory_full_info().pss
        except psutil.Error:
            pass
    return total / 2**20


async def one_mode(fork: bool, n: int, moved: bool = False) -> dict:
    mode = "--fork-sessions" if fork else "--process-sessions"
    args = ("--no-spare", "--max-sessions", str(n + 2), mode)
    with app_process(sessions=True, app_args=args) as running:
        opened, times = [], []
        for _ in range(n):
            client, page, seconds = await open_session(running, moved)
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
    parser.add_argument(
        "--moved",
        action="store_true",
        help="each session then computes a frame of its own (the pitch moved) before the count",
    )
    args = parser.parse_args(argv)
    for fork in [mode == "fork" for mode in args.modes]:
        r = asyncio.run(one_mode(fork, args.sessions, args.moved))
        mode = "forked from the parent" if fork else "a process each     "
        own = ", each with a frame of its own" if args.moved else ""
        print(
            f"{mode}: {args.sessions} sessions{own} hold {r['pss_mb']:,.0f} MB PSS "
            f"({r['pss_mb'] / args.sessions:,.0f} MB each, the parent included); "
            f"a new one to its first frame {r['new_s']:.1f} s with them open; "
            f"opening them: median {statistics.median(r['open_s']):.1f} s",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
