"""Sessions of a real launcher driven as tabs drive them, for the frame-memory test and benchmark
(tests/app/test_app_frame_memory.py, scripts/bench_frame_memory.py): a page opened through the
door up to its first frame, a heavy frame asked for and waited for (every frame reported shown,
as a page does), and the launcher tree's memory sampled while they run."""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time

import aiohttp
import psutil

from support.hostile_client import Client

NAVIGATION = {"Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}
WAIT_S = 600.0  # a frame may wait for many others: only catches hangs


async def open_page(
    client: aiohttp.ClientSession, base: str, token: str
) -> tuple[Client, dict, str]:
    """A tab: the door with the token, the session's websocket, its first frame. (The page, its
    state, its session id.) From then on a task reads the page's messages (its state pushes go
    to ``page.states``; the launcher's pings are answered while the page waits)."""
    async with client.get(f"{base}/?token={token}", headers=NAVIGATION) as answer:
        assert answer.status == 200, answer.status
        jar = {k: m.value for k, m in answer.cookies.items()}
        text = await answer.text()
    location = json.loads(text.split("location.replace(")[1].split(");")[0])
    path = location.split("#")[0].split("?")[0]
    ws = await client.ws_connect(
        base.replace("http://", "ws://") + f"{path}ws",
        headers={"Origin": base, "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items())},
        max_msg_size=0,
    )
    page = Client(ws)
    await page.hello()
    state = (await page.call("trame.state.get"))["result"]["state"]
    if not state.get("frame_generation"):
        state = {**state, **await page.wait_state(lambda s: s.get("frame_generation", 0) > 0)}
    page.reader = asyncio.create_task(_read_forever(page))
    return page, state, path.split("/")[2]


async def _read_forever(page: Client) -> None:
    with contextlib.suppress(ConnectionError, asyncio.CancelledError):
        await page.receive_until(lambda m: False, wait_s=WAIT_S)


async def _send_call(page: Client, method: str, args: list) -> None:
    """A call whose answer is not waited for (the page's reader takes it)."""
    await page.send(
        {"wslink": "1.0", "id": "rpc:c0:0", "method": method, "args": args, "kwargs": {}}
    )


async def close_page(page: Client) -> None:
    page.reader.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await page.reader
    await page.ws.close()


async def heavy_frame(page: Client, state: dict, **values) -> dict:
    """Set ``values`` and wait for the session's answer: its new frame at the preset (every frame
    pushed reported shown, as a page does) or its error message. What came: ``frame`` (True when
    the frame came), ``error`` (the message, or ""), ``waits`` (the "Waiting for memory" messages
    the page was sent)."""
    first = generation = state.get("frame_generation", 0)
    key = state.get("frame_key")
    if key:
        await _send_call(page, "trame.trigger", ["frame_shown", [key], {}])
    seen = len(page.states)
    await _send_call(
        page, "trame.state.update", [[{"key": k, "value": v} for k, v in values.items()]]
    )
    deadline = time.monotonic() + WAIT_S
    while True:
        while len(page.states) == seen:
            if page.reader.done():
                return _outcome(page, False, "")  # the connection ended: no answer
            assert time.monotonic() < deadline, f"no answer in {WAIT_S:g} s"
            await asyncio.sleep(0.02)
        pushed, seen = page.states[seen], seen + 1
        generation = pushed.get("frame_generation", generation)
        if pushed.get("error_message"):
            return _outcome(page, False, pushed["error_message"])
        if "frame_key" in pushed:
            await _send_call(page, "trame.trigger", ["frame_shown", [pushed["frame_key"]], {}])
            if generation > first and pushed.get("frame_kind") == "preset":
                return _outcome(page, True, "")


def _outcome(page: Client, frame: bool, error: str) -> dict:
    waits = [m for m in page.seen("memory_message") if m]
    return {"frame": frame, "error": error, "waits": waits}


def tree_pss_bytes(pid: int, include_self: bool = True) -> int:
    """The proportional set size of process ``pid`` and every process under it [bytes]."""
    try:
        root = psutil.Process(pid)
        procs = [*([root] if include_self else []), *root.children(recursive=True)]
    except psutil.Error:
        return 0
    return sum(_pss(proc.pid) for proc in procs)


def _pss(pid: int) -> int:
    """One process's PSS from /proc/PID/smaps_rollup (cheap: psutil's full map is not) [bytes]."""
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as f:
            for line in f:
                if line.startswith(b"Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return 0
    return 0


class PeakSampler:
    """The largest :func:`tree_pss_bytes` of ``pid`` seen while it runs, sampled every
    ``period_s`` in a thread of its own."""

    def __init__(self, pid: int, period_s: float = 0.05, include_self: bool = True):
        self.pid = pid
        self.period_s = period_s
        self.include_self = include_self
        self.peak_bytes = 0
        self.n_samples = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak_bytes = max(self.peak_bytes, tree_pss_bytes(self.pid, self.include_self))
            self.n_samples += 1
            time.sleep(self.period_s)

    def __enter__(self) -> PeakSampler:
        self._thread.start()
        return self

    def __exit__(self, *_) -> None:
        self._stop.set()
        self._thread.join(10)
