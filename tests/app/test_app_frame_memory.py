"""The launcher's memory budget for heavy frames across sessions (app.server.frame_memory).

The first tests run the launcher's budget on an event loop of its own and sessions' ends of it in
threads (and one in a process of its own, killed while it holds a grant): first come first served,
the places in the queue told as they change, a frame over the whole budget refused at once, a
frame overtaken while it waits giving up its place, light frames asking nothing. The last ones
run the launcher in this process with real sessions forked from the preloaded parent: two heavy
frames under a small budget run one after the other with their pages told that they wait, and
the sessions' processes together stay under the budget beside what they held before; a frame
that could never fit is refused with its message on the page. Every wait is bounded and only
catches hangs; no test asserts a wall time.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from support.fork import require_fork
from support.frame_sessions import PeakSampler, heavy_frame, open_page, tree_pss_bytes
from support.hostile_client import Client
from test_app_launcher import listening

import simcore
from app.engine import FrameRefused, frame_bytes
from app.logic.controller import memory_wait_text
from app.runner import StaleRequest
from app.server import frame_memory as fm
from app.server import launcher as lau

MIB = 2**20
WAIT_S = 60.0
REPO = Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def budget(budget_bytes: int, owners: dict[str, object]):
    """The launcher's budget on an event loop in a thread: (its FrameMemory, a function that runs
    a callable on that loop and returns its result)."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    memory = fm.FrameMemory(budget_bytes, owners.get)

    def on_loop(call):
        async def run():
            return call()

        return asyncio.run_coroutine_threadsafe(run(), loop).result(WAIT_S)

    asyncio.run_coroutine_threadsafe(memory.start(), loop).result(WAIT_S)
    try:
        yield memory, on_loop
    finally:
        asyncio.run_coroutine_threadsafe(memory.close(), loop).result(WAIT_S)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(WAIT_S)
        loop.close()


def until(condition, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"waited {WAIT_S:g} s for {what}"
        time.sleep(0.01)


class Waiter:
    """A session's frame asking in a thread of its own: the places it was told, its grant or
    what it raised."""

    def __init__(self, path: str, token: str, need: int, overtaken=lambda: False):
        self.told: list[int | None] = []
        self.grant: fm.Grant | None = None
        self.error: BaseException | None = None
        grants = fm.FrameGrants(path, token)

        def run():
            try:
                self.grant = grants.ask(need, overtaken, self.told.append)
            except BaseException as exc:
                self.error = exc

        self.thread = threading.Thread(target=run, daemon=True)
        self.thread.start()

    def done(self) -> bool:
        return not self.thread.is_alive()


def test_heavy_frames_wait_first_come_first_served_and_are_told_their_place():
    owners = {name: object() for name in "abc"}
    with budget(100 * MIB, owners) as (memory, on_loop):
        first = fm.FrameGrants(memory.path, "a").ask(80 * MIB)
        assert on_loop(lambda: memory.in_use_bytes) == 80 * MIB
        b = Waiter(memory.path, "b", 80 * MIB)
        until(lambda: on_loop(lambda: memory.waiting) == 1, "b in the queue")
        c = Waiter(memory.path, "c", 10 * MIB + fm.LIGHT_FRAME_BYTES)  # fits, but comes after b
        until(lambda: on_loop(lambda: memory.waiting) == 2, "c in the queue")
        until(lambda: b.told == [0] and c.told == [1], "the places told")
        assert not b.done() and not c.done()
        first.close()  # a's frame is done: b's turn, and c is next
        until(b.done, "b's grant")
        until(lambda: c.told == [1, 0], "c told it is next")
        assert b.grant is not None and b.told == [0, None] and not c.done()
        b.grant.close()
        until(c.done, "c's grant")
        assert c.told == [1, 0, None]
        c.grant.close()
        until(lambda: on_loop(lambda: memory.in_use_bytes) == 0, "every grant back")
        stats = on_loop(lambda: (memory.n_granted, memory.n_waited, memory.most_at_once))
        assert stats == (3, 2, 1)
        assert memory.most_in_use_bytes <= memory.budget_bytes
    assert memory_wait_text(2) == "Waiting for memory: 2 frames ahead"
    assert memory_wait_text(1) == "Waiting for memory: 1 frame ahead"
    assert memory_wait_text(0).startswith("Waiting for memory: this frame is next")


def test_a_frame_that_could_never_fit_is_refused_at_once_and_a_light_one_asks_nothing():
    with budget(100 * MIB, {"a": object()}) as (memory, on_loop):
        grants = fm.FrameGrants(memory.path, "a")
        with pytest.raises(FrameRefused) as refused:
            grants.ask(2000 * MIB)
        message = str(refused.value)
        assert "about 2.1 GB of memory" in message and "keeps 0.1 GB" in message
        assert "lower the Pixels" in message
        light = grants.ask(fm.LIGHT_FRAME_BYTES - 1)
        light.close()
        assert on_loop(lambda: (memory.n_asked, memory.n_refused, memory.waiting)) == (1, 1, 0)
        assert grants.n_asked == 1  # the light frame made no connection


def test_a_frame_overtaken_while_it_waits_gives_up_its_place():
    owners = {name: object() for name in "abc"}
    with budget(100 * MIB, owners) as (memory, on_loop):
        held = fm.FrameGrants(memory.path, "a").ask(90 * MIB)
        moved = threading.Event()
        b = Waiter(memory.path, "b", 90 * MIB, overtaken=moved.is_set)
        until(lambda: b.told == [0], "b waiting")
        c = Waiter(memory.path, "c", 90 * MIB)
        until(lambda: c.told == [1], "c waiting behind b")
        moved.set()  # b's slider moved again: its frame is stale
        until(b.done, "b gone")
        assert isinstance(b.error, StaleRequest) and b.told == [0, None]
        until(lambda: c.told == [1, 0], "c moved up")
        assert on_loop(lambda: (memory.waiting, memory.n_dropped)) == (1, 1)
        held.close()
        until(c.done, "c's grant")
        c.grant.close()


def test_the_owner_of_a_grant_stopped_or_killed_gives_it_back():
    owners = {name: object() for name in "abc"}
    with budget(100 * MIB, owners) as (memory, on_loop):
        # a session the launcher stops: its grant goes back with it
        held = fm.FrameGrants(memory.path, "a").ask(90 * MIB)
        b = Waiter(memory.path, "b", 90 * MIB)
        until(lambda: b.told == [0], "b waiting")
        assert on_loop(lambda: memory.release_owner(owners["a"])) == 1
        until(b.done, "b's grant after a stopped")
        held.close()
        # a session killed (SIGKILL: nothing of it runs) while it holds a grant
        script = (
            "import sys, time\n"
            "from app.server.frame_memory import FrameGrants\n"
            "grant = FrameGrants(sys.argv[1], 'c').ask(90 * 2**20)\n"
            "print('granted', flush=True)\n"
            "time.sleep(600)\n"
        )
        b.grant.close()
        child = subprocess.Popen(
            [sys.executable, "-c", script, memory.path],
            cwd=REPO,
            stdout=subprocess.PIPE,
            text=True,
            env={**_env(), "PYTHONUNBUFFERED": "1"},
        )
        try:
            assert child.stdout.readline().strip() == "granted"
            a = Waiter(memory.path, "a", 90 * MIB)
            until(lambda: a.told == [0], "a waiting behind the process")
            child.send_signal(signal.SIGKILL)
            child.wait(WAIT_S)
            until(a.done, "a's grant after the process was killed")
            assert a.grant is not None and on_loop(lambda: memory.in_use_bytes) == 90 * MIB
            a.grant.close()
        finally:
            if child.poll() is None:
                child.kill()
                child.wait(WAIT_S)
        assert on_loop(lambda: memory.most_at_once) == 1


def test_a_request_without_a_sessions_token_or_malformed_gets_nothing(caplog):
    with budget(100 * MIB, {"a": object()}) as (memory, on_loop):
        import socket

        for line in (b'{"token": "nobody", "bytes": 99}\n', b"garbage\n", b'{"bytes": -1}\n'):
            with socket.socket(socket.AF_UNIX) as sock:
                sock.settimeout(WAIT_S)
                sock.connect(memory.path)
                sock.sendall(line)
                assert sock.recv(100) == b""  # closed with no answer
        assert on_loop(lambda: (memory.n_asked, memory.in_use_bytes)) == (0, 0)
        assert Path(memory.folder).stat().st_mode & 0o077 == 0  # this user's only


def test_the_default_budget_is_the_memory_cap_less_the_sessions_and_at_least_one_frame():
    big = lau.default_caps(
        available_bytes=24000 * MIB, session_rss_bytes=128 * MIB, frame_limit_bytes=1536 * MIB
    )
    assert big.max_sessions == 30
    assert big.frames_bytes == big.memory_cap_bytes - 30 * 128 * MIB
    small = lau.default_caps(
        available_bytes=4000 * MIB, session_rss_bytes=128 * MIB, frame_limit_bytes=1536 * MIB
    )
    assert small.frames_bytes == 1536 * MIB  # 3000 MB less 23 sessions: one frame at a time
    given = lau.default_caps(
        available_bytes=4000 * MIB, frame_limit_bytes=1536 * MIB, frames_bytes=500 * MIB
    )
    assert given.frames_bytes == 500 * MIB
    assert lau.default_caps(available_bytes=4000 * MIB).frames_bytes is None


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO)}


# -- the real launcher and its forked sessions -----------------------------------------------------
TOKEN = "frame-memory-test-token"


def heavy(pixels: int) -> dict:
    """The controls of a heavy frame: the reference preset (64 sub-rays a pixel) at ``pixels``."""
    return {"preset": "reference", "pixels": pixels}


def estimate(pixels: int) -> int:
    scene = simcore.load_scene()
    return frame_bytes(simcore.with_overrides(scene, simcore.PRESETS["reference"], pixels=pixels))


@contextlib.asynccontextmanager
async def real_launcher(frames_bytes: int):
    """The launcher in this process with real sessions forked from the preloaded parent, on a
    free port: (launcher, base address, client)."""
    caps = lau.Caps(max_sessions=4, memory_cap_bytes=2**40, spare=False, frames_bytes=frames_bytes)
    launcher = lau.Launcher(TOKEN, "127.0.0.1", caps, zygote=lau.zygote_command)
    async with listening(launcher) as served:
        yield served


async def _bounded(condition, what: str) -> None:
    deadline = time.monotonic() + 120.0
    while not condition():
        assert time.monotonic() < deadline, f"waited 120 s for {what}"
        await asyncio.sleep(0.05)


async def _classroom() -> None:
    need = estimate(128)  # 339 MiB: one such frame fits the budget, two do not
    async with real_launcher(need + 16 * MIB) as (launcher, base, client):
        memory = launcher.frames
        (a, state_a, id_a), (b, state_b, id_b) = [
            await open_page(client, base, TOKEN) for _ in range(2)
        ]
        zygote = launcher.zygote.proc.pid
        # 1. two sessions' heavy frames at once: they run one after the other, each page told
        # that its frame waits. The budget is held first (as a third tab's frame would hold it)
        # so that both frames wait, whatever the machine's speed
        holder = fm.FrameGrants(memory.path, launcher.sessions[id_b].token)
        held = await asyncio.to_thread(holder.ask, need)
        baseline = tree_pss_bytes(zygote)
        with PeakSampler(zygote) as peak:
            tasks = [
                asyncio.create_task(heavy_frame(page, state, **heavy(128)))
                for page, state in ((a, state_a), (b, state_b))
            ]
            await _bounded(lambda: memory.waiting == 2, "both frames in the queue")
            held.close()
            outcomes = await asyncio.gather(*tasks)
        assert [o["frame"] for o in outcomes] == [True, True], outcomes
        for outcome in outcomes:  # the queue's message reached each page's state
            assert outcome["waits"] and outcome["waits"][0].startswith("Waiting for memory: ")
        assert (memory.most_at_once, memory.n_granted, memory.n_waited) == (1, 3, 2)
        assert memory.most_in_use_bytes <= memory.budget_bytes
        assert peak.n_samples >= 2
        assert peak.peak_bytes <= baseline + memory.budget_bytes, (peak.peak_bytes, baseline)
        # 2. a session killed while a grant is held in its name: the launcher notices its exit
        # and gives the grant back, and the other session's waiting frame runs
        victim = launcher.sessions[id_a]
        holder = fm.FrameGrants(memory.path, victim.token)
        held = await asyncio.to_thread(holder.ask, need)
        task = asyncio.create_task(heavy_frame(b, b_state(b, state_b), **heavy(96)))
        await _bounded(lambda: memory.waiting == 1, "b's frame in the queue")
        os.kill(victim.pid, signal.SIGKILL)
        outcome = await task
        assert outcome["frame"] and outcome["waits"], outcome
        await _bounded(lambda: memory.in_use_bytes == 0, "b's grant back after its frame")
        assert id_a not in launcher.sessions
        held.close()
        # 3. a frame that could never fit the server's budget is refused before it runs, with
        # the message on its page (it fits the session's own limit)
        memory.budget_bytes = 100 * MIB
        n_asked = memory.n_asked
        outcome = await heavy_frame(b, b_state(b, state_b), **heavy(112))
        assert not outcome["frame"] and memory.n_refused == 1 and memory.n_asked == n_asked + 1
        assert outcome["error"].startswith("Refused: this frame would take about 0.27 GB")
        assert "this server keeps 0.1 GB for the frames of all its sessions" in outcome["error"]


def b_state(page: Client, state: dict) -> dict:
    """The page's state: what it started with and every push since."""
    for pushed in page.states:
        state = {**state, **pushed}
    return state


def test_heavy_frames_of_real_sessions_wait_their_turn_and_a_killed_session_frees_its_grant():
    require_fork()
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        pool.submit(asyncio.run, _classroom()).result()
