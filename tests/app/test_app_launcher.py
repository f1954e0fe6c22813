"""The launcher (app.launcher: each tab its own session) without a browser.

Most tests run the launcher in this process with stand-in session processes
(tests/support/fake_session.py, which start in well under a second); the last ones start the real
``python -m app`` launcher and its real session processes: a wslink hello and a state change
through the proxy, the token kept off the command lines, and no process left behind after SIGTERM
or SIGKILL. Every wait is bounded and only catches hangs; no test asserts a wall time.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import dataclasses
import os
import signal
import subprocess
import sys
import time
import urllib.parse
from pathlib import Path

import aiohttp
import psutil
import pytest
from aiohttp import web
from support.hostile_client import Client
from support.launch import app_process

from app import launcher as lau

TOKEN = "launcher-test-token"
FAKE = Path(__file__).resolve().parents[1] / "support" / "fake_session.py"
WAIT_S = 60.0


def fake_command(scene: str | None, options: tuple[str, ...] = ()) -> list[str]:
    return [sys.executable, str(FAKE)]


def caps(**given) -> lau.Caps:
    return lau.Caps(**{"max_sessions": 3, "memory_cap_bytes": 2**40, "idle_s": 60.0, **given})


def run(coroutine_fn, *args):
    """Run ``coroutine_fn(*args)`` in a thread with its own event loop."""
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(asyncio.run, coroutine_fn(*args)).result()


@contextlib.asynccontextmanager
async def serving(the_caps: lau.Caps):
    """A launcher with stand-in sessions on a free port: (launcher, base address, client)."""
    launcher = lau.Launcher(TOKEN, "127.0.0.1", the_caps, command=fake_command)
    runner = web.AppRunner(launcher.web_app(), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    port = site._server.sockets[0].getsockname()[1]
    try:
        async with aiohttp.ClientSession() as client:
            yield launcher, f"http://127.0.0.1:{port}", client
    finally:
        await runner.cleanup()


def cookie(base: str) -> dict[str, str]:
    return {"Cookie": f"lmapd-token-{urllib.parse.urlsplit(base).port}={TOKEN}"}


async def get(client, url: str, **headers) -> tuple[int, str, dict]:
    async with client.get(url, allow_redirects=False, headers=headers) as answer:
        return answer.status, await answer.text(), dict(answer.headers)


async def new_session(client, base: str, query: str = "") -> str:
    status, _, headers = await get(client, f"{base}/?token={TOKEN}{query}")
    assert status == 302, status
    location = headers["Location"]
    assert location.startswith("/s/")
    return location


async def until(predicate, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.05)


# -- pure functions ------------------------------------------------------------------------------
def test_the_default_caps_fit_the_sessions_in_the_memory_share_between_one_and_eight():
    mib = lau.MIB
    c = lau.default_caps(available_bytes=8000 * mib, session_rss_bytes=1000 * mib)
    assert c.memory_cap_bytes == int(lau.MEMORY_SHARE * 8000 * mib)
    assert c.max_sessions == int(lau.MEMORY_SHARE * 8000) // 1000  # 6
    small = lau.default_caps(available_bytes=500 * mib, session_rss_bytes=1000 * mib)
    assert small.max_sessions == 1
    many = lau.default_caps(available_bytes=10**6 * mib, session_rss_bytes=mib)
    assert many.max_sessions == lau.MAX_DEFAULT_SESSIONS
    given = lau.default_caps(available_bytes=mib, max_sessions=3, memory_cap_bytes=5, idle_s=2)
    assert (given.max_sessions, given.memory_cap_bytes, given.idle_s) == (3, 5, 2)


@pytest.mark.parametrize(
    ("rest", "ok"),
    [
        ("/", True),
        ("/index.html", True),
        ("/assets/index-1.js", True),
        ("/../x", False),
        ("/a/../../x", False),
        ("/./x", False),
        ("//evil.example/x", False),
        ("/a\\..\\x", False),
        ("/a\x00b", False),
        ("x", False),
    ],
)
def test_a_path_inside_a_session_cannot_leave_it(rest, ok):
    assert lau.safe_rest(rest) is ok


def test_the_message_page_escapes_what_it_shows():
    page = lau.message_page(404, "<b>", "a 'quote' <script>", "/?a='x'", "<i>")
    assert "<script>" not in page.text and "&lt;script&gt;" in page.text
    assert "href='/?a=&#x27;x&#x27;'" in page.text and page.status == 404


def test_a_sessions_token_is_never_on_its_command_line():
    cmd = lau.child_command("paper", ("--no-preview",))
    assert cmd[-1] == "--no-preview" and "--token-stdin" in cmd
    assert "--shared" in cmd and "127.0.0.1" in cmd
    assert not any("token=" in part for part in cmd)


# -- the launcher with stand-in sessions --------------------------------------------------------
def test_the_token_opens_a_session_of_its_own_and_its_page_is_proxied():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            assert (await get(client, f"{base}/"))[0] == 403
            assert (await get(client, f"{base}/?token=wrong"))[0] == 403
            status, _, headers = await get(client, f"{base}/?token={TOKEN}&pitch_deg=30")
            assert status == 302 and "HttpOnly" in headers["Set-Cookie"]
            first = headers["Location"]
            assert first.endswith(f"/?token={TOKEN}&pitch_deg=30")
            second = await new_session(client, base)
            assert first.split("/")[2] != second.split("/")[2] and len(launcher.sessions) == 2
            assert len({c.port for c in launcher.sessions.values()}) == 2
            # the session's page: through the launcher, with the session's own token
            status, text, _ = await get(client, f"{base}{first}")
            assert status == 200 and "token ok" in text and "pitch_deg=30" in text
            status, text, _ = await get(client, f"{base}{first.split('?')[0]}x.js", **cookie(base))
            assert (status, text.split(";")[1]) == (200, " token ok")
            assert (await get(client, base + first.split("?")[0]))[0] == 403  # no token
            status, _, headers = await get(client, f"{base}{first.split('/?')[0]}", **cookie(base))
            assert status == 302 and headers["Location"].endswith("/")
            async with client.post(f"{base}{first}", data=b"x") as answer:
                assert answer.status == 405

    run(body)


def test_an_unknown_session_or_a_path_out_of_it_gets_a_page_not_a_trace():
    async def body():
        async with serving(caps()) as (_, base, client):
            session = (await new_session(client, base)).split("?")[0]
            status, text, _ = await get(client, f"{base}/s/nope/?pixels=32", **cookie(base))
            assert status == 404 and "No such session" in text
            assert "href='/?pixels=32'" in text and "Traceback" not in text
            for path in ("%2e%2e/%2e%2e/etc/passwd", "a/%2e%2e/%2e%2e/x", "..%5c..%5cx"):
                url = aiohttp.client.URL(f"{base}{session}{path}", encoded=True)
                async with client.get(url, allow_redirects=False, headers=cookie(base)) as answer:
                    assert answer.status == 404, path
            assert (await get(client, f"{base}/etc/passwd", **cookie(base)))[0] == 404

    run(body)


def test_over_the_caps_a_503_page_says_how_many_sessions_are_open():
    async def body():
        async with serving(caps(max_sessions=2)) as (launcher, base, client):
            await new_session(client, base)
            await new_session(client, base)
            status, text, _ = await get(client, f"{base}/?token={TOKEN}")
            assert status == 503 and "2 sessions are open" in text and "--max-sessions" in text
            assert launcher.spare is None and len(launcher._all) == 2  # the spare counts
        async with serving(caps(memory_cap_bytes=1, spare=False)) as (launcher, base, client):
            await new_session(client, base)
            status, text, _ = await get(client, f"{base}/?token={TOKEN}")
            assert status == 503 and "1 session is open and use" in text and "MB" in text

    run(body)


def test_the_spare_is_taken_and_replaced():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            await until(lambda: launcher.spare is not None and launcher.spare.done(), "a spare")
            spare = launcher.spare.result()
            location = await new_session(client, base)
            assert launcher.sessions[location.split("/")[2]] is spare
            await until(lambda: launcher.spare is not None, "the next spare")

    run(body)


def test_the_websocket_is_proxied_with_its_origin_checked_and_its_frames_bounded():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            path = (await new_session(client, base)).split("?")[0]
            url = f"ws://{base[7:]}{path}ws?token={TOKEN}"
            for origin in ("http://evil.example", None):
                headers = {"Origin": origin} if origin else {}
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await client.ws_connect(url, headers=headers)
                assert refused.value.status == 403
            child = launcher.sessions[path.split("/")[2]]
            ws = await client.ws_connect(url, headers={"Origin": base}, max_msg_size=0)
            await ws.send_bytes(b"hello")
            assert (await asyncio.wait_for(ws.receive(), WAIT_S)).data == b"hello"
            assert child.n_sockets == 1
            with contextlib.suppress(ConnectionError):  # closed while it is being sent
                await ws.send_bytes(bytes(lau.FRAME_BYTES + 1))  # over one frame: closed
            msg = await asyncio.wait_for(ws.receive(), WAIT_S)
            closed = (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR)
            assert msg.type in closed
            await ws.close()
            await until(lambda: child.n_sockets == 0, "the proxy to close")
            ws = await client.ws_connect(url, headers={"Origin": base})  # the session goes on
            await ws.send_bytes(b"again")
            assert (await asyncio.wait_for(ws.receive(), WAIT_S)).data == b"again"
            await ws.close()

    run(body)


def test_idle_sessions_end_and_dead_ones_are_forgotten_and_close_stops_all():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            idle = (await new_session(client, base)).split("?")[0]
            kept = (await new_session(client, base)).split("?")[0]
            dies = (await new_session(client, base)).split("?")[0]
            ws = await client.ws_connect(
                f"ws://{base[7:]}{kept}ws?token={TOKEN}", headers={"Origin": base}
            )
            victim = launcher.sessions[dies.split("/")[2]]
            idle_child = launcher.sessions[idle.split("/")[2]]
            launcher.caps = dataclasses.replace(launcher.caps, idle_s=0.3)  # from now on
            os.kill(victim.pid, signal.SIGKILL)
            await until(lambda: len(launcher.sessions) == 1, "the idle and the dead session")
            assert launcher.n_reaped == 1 and idle_child.proc.returncode is not None
            status, text, _ = await get(client, f"{base}{idle}", **cookie(base))
            assert status == 404 and "No such session" in text
            assert (await get(client, f"{base}{kept}", **cookie(base)))[0] == 200
            await ws.close()
            await until(lambda: not launcher.sessions, "the closed page's session")
            await until(lambda: launcher.spare is not None and launcher.spare.done(), "a spare")
            pids = [c.pid for c in launcher._all]
        assert pids and not any(psutil.pid_exists(p) and _running(p) for p in pids)

    run(body)


def _running(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


# -- the real launcher and its real sessions -------------------------------------------------------
def _descendants(pid: int) -> list[psutil.Process]:
    return psutil.Process(pid).children(recursive=True)


@pytest.mark.slow
def test_the_real_launcher_proxies_a_session_and_leaves_no_process_after_sigterm(tmp_path):
    options = ("--max-sessions", "2", "--no-spare")
    with app_process(log_path=tmp_path / "server.log", sessions=True, app_args=options) as running:

        async def body():
            async with aiohttp.ClientSession() as client:
                status, _, headers = await get(client, running.url + "&pixels=32")
                assert status == 302
                path = headers["Location"].split("?")[0]
                ws = await client.ws_connect(
                    f"ws://127.0.0.1:{running.port}{path}ws?token={running.token}",
                    headers={"Origin": running.origin},
                    max_msg_size=0,
                )
                page = Client(ws)
                assert "result" in await page.hello()
                state = (await page.call("trame.state.get"))["result"]["state"]
                await page.set_state(pitch_deg=12)
                generation = state["frame_generation"]
                frame = await page.wait_state(
                    lambda s: s.get("frame_generation", 0) > generation and "n_points" in s
                )
                await ws.close()
                return state, frame

        state, frame = run(body)
        assert state["pitch_deg"] == 0 and frame["n_points"] > 0
        children = _descendants(running.pid)
        assert len(children) == 1
        assert not any(running.token in " ".join(c.cmdline()) for c in children)
        os.kill(running.pid, signal.SIGTERM)
        gone, alive = psutil.wait_procs(children, timeout=WAIT_S)
        assert alive == [] and len(gone) == 1


@pytest.mark.slow
def test_sessions_stop_when_their_launcher_is_killed(tmp_path):
    cmd = [sys.executable, "-m", "app", "--port", "0", "--max-sessions", "1"]
    root = Path(__file__).resolve().parents[2]
    with open(tmp_path / "out.log", "w+b") as out:
        proc = subprocess.Popen(cmd, cwd=root, stdout=out, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + WAIT_S
            while not _descendants(proc.pid):  # the spare
                assert proc.poll() is None and time.monotonic() < deadline
                time.sleep(0.1)
            children = _descendants(proc.pid)
            proc.kill()  # no chance to stop them: they stop when their stdin closes
            proc.wait(timeout=WAIT_S)
            gone, alive = psutil.wait_procs(children, timeout=WAIT_S)
            assert alive == []
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
