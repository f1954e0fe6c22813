"""A hostile client against the real app server, speaking wslink's protocol directly: foreign
origins and missing tokens are refused before the upgrade; injected state keys are dropped and
never reach another page; life-cycle and exit calls are refused and the simulation goes on;
chunk floods close their connection with the server's memory bounded; malformed calls get one
short message. The work of each test is bounded; waits have generous limits only to catch hangs.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import json
import re
import time
import urllib.error
import urllib.request
from pathlib import Path

import aiohttp
import msgpack
import psutil
import pytest
from support.hostile_client import Client, connect
from support.hostile_meshes import bufferless_glb, ply_claiming, shared_accessor_glb, stl_claiming
from support.launch import app_process
from support.soak import rss_mb

from app.server.security import MAX_MESSAGE_BYTES, Door, Limits

pytestmark = pytest.mark.slow

INJECTED = {
    "trame__template_main": '<img src=x onerror="window.pwned=1">',
    "trame__inline_script_1": "window.pwned = 2",
    "trame__scripts": ["http://evil.example/x.js"],
    "not_a_key_of_the_app": "x",
}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    log_path = tmp_path_factory.mktemp("hostile") / "server.log"
    with app_process(log_path=log_path) as running:
        yield running


def run(coroutine_fn, *args):
    """Run ``coroutine_fn(session, *args)`` with a fresh aiohttp session, in a thread of its own
    (its own event loop: the browser tests' Playwright keeps one running in this thread)."""

    async def main():
        async with aiohttp.ClientSession() as session:
            return await coroutine_fn(session, *args)

    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(asyncio.run, main()).result()


def http_get(url: str, headers: dict | None = None) -> tuple[int, dict]:
    request = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, dict(response.headers)
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers)


async def refused_status(session, app, **how) -> int | None:
    try:
        client = await connect(session, app, hello=False, **how)
    except aiohttp.WSServerHandshakeError as exc:
        return exc.status
    await client.ws.close()
    return None


# -- 1. the door -----------------------------------------------------------------------------------
def test_foreign_or_missing_origins_are_refused_before_the_upgrade(app):
    other_port = f"http://127.0.0.1:{app.port + 1}"
    origins = ["http://evil.example", other_port, "null", "file://", f"https://{app.origin[7:]}x"]

    async def attempt(session):
        statuses = [await refused_status(session, app, origin=o) for o in origins]
        statuses.append(await refused_status(session, app, origin=None))  # no Origin at all
        statuses.append(await refused_status(session, app))  # the page's own origin
        return statuses

    assert run(attempt) == [403] * (len(origins) + 1) + [None]


def test_a_missing_or_wrong_token_is_refused(app):
    async def attempt(session):
        statuses = [await refused_status(session, app, token=t) for t in (None, "", "x" * 43)]
        wrong = app.token[:-1] + ("A" if app.token[-1] != "A" else "B")
        statuses.append(await refused_status(session, app, token=wrong))
        return statuses

    assert run(attempt) == [403, 403, 403, 403]


def test_the_page_needs_the_token_and_the_address_sets_its_cookie(app):
    base = app.origin + "/index.html"
    assert http_get(base)[0] == 403
    assert http_get(base + "?token=wrong")[0] == 403
    status, headers = http_get(app.url)
    assert status == 200
    status, headers = http_get(base + f"?token={app.token}")
    cookie = headers.get("Set-Cookie", "")
    assert status == 200 and "HttpOnly" in cookie and "SameSite=Strict" in cookie
    # every path of the server needs it (the page, its files, its websocket); plain http here
    assert "Path=/;" in cookie + ";" and "secure" not in cookie.lower()
    name_value = cookie.split(";")[0]
    assert http_get(base, {"Cookie": name_value})[0] == 200

    async def with_cookie(session):  # the page's websocket carries the cookie, not the query
        headers = {"Origin": app.origin, "Cookie": name_value}
        ws = await session.ws_connect(f"ws://127.0.0.1:{app.port}/ws", headers=headers)
        answer = await Client(ws).hello("any secret: the token was checked at the upgrade")
        await ws.close()
        return answer

    assert "result" in run(with_cookie)


# -- 2. what a client may write --------------------------------------------------------------------
def test_injected_keys_are_dropped_and_never_reach_another_page(app):
    async def attack(session):
        victim = await connect(session, app)
        before = (await victim.call("trame.state.get"))["result"]["state"]
        attacker = await connect(session, app)
        answer = await attacker.set_state(**INJECTED, pitch_deg=7)
        await victim.wait_state(lambda s: s.get("pitch_deg") == 7)
        late = await connect(session, app)  # a page opened afterwards
        after = (await late.call("trame.state.get"))["result"]["state"]
        for c in (victim, attacker, late):
            await c.ws.close()
        return answer, victim, before, after

    answer, victim, before, after = run(attack)
    assert "result" in answer  # the page's other keys went through (no retry loop)
    for key in INJECTED:
        assert victim.seen(key) == [], key
        assert after.get(key) == before.get(key), key
    assert "window.pwned" not in str(after)
    assert after["pitch_deg"] == 7


def test_life_cycle_and_exit_calls_are_refused_and_the_simulation_goes_on(app):
    calls = [
        ("trame.lifecycle.update", ["server_exited"]),
        ("trame.lifecycle.update", ["server_ready"]),
        ("trame.lifecycle.update", ["exception"]),
        ("application.exit", []),
        ("application.exit.later", [0]),
        ("trame.force.push", ["trame__template_main"]),
        ("no.such.method", []),
    ]

    async def attack(session):
        client = await connect(session, app)
        state = (await client.call("trame.state.get"))["result"]["state"]
        answers = [await client.call(m, a) for m, a in calls]
        ok = await client.call("trame.lifecycle.update", ["client_connected"])
        target = 12 if state["pitch_deg"] != 12 else 13
        await client.set_state(pitch_deg=target)
        generation = state["frame_generation"]
        frame = await client.wait_state(
            lambda s: s.get("frame_generation", 0) > generation and "n_points" in s
        )
        await client.ws.close()
        return answers, ok, frame

    answers, ok, frame = run(attack)
    for (method, _), answer in zip(calls, answers, strict=True):
        assert "error" in answer and "result" not in answer, method
        assert "data" not in answer["error"] and len(answer["error"]["message"]) < 60
    assert "result" in ok  # what the trame page itself reports is accepted
    assert frame["n_points"] > 0


def test_malformed_calls_get_one_short_message_and_no_trace(app):
    malformed = [
        ("trame.state.update", [[1]]),
        ("trame.state.update", [{"key": 1}]),
        ("trame.state.update", ["x"]),
        ("trame.state.update", None),
        ("trame.trigger", None),
        ("trame.trigger", ["pixel_click", "x", {}]),
        ("trame.trigger", [["pixel_click"], [], {}]),
        ("trame.trigger", ["no_such_trigger", [], {}]),
        ("trame.trigger", ["pixel_click", [], {"x": 1}, 4]),
        ("trame.state.get", [1]),
        ("trame.error.client", []),
    ]

    async def attack(session):
        client = await connect(session, app)
        answers = [await client.call(m, a) for m, a in malformed]
        answers.append(await client.call("trame.trigger", ["pixel_click", [], {}], kwargs=[1]))
        answers.append(await client.call(["not", "a", "name"], []))
        still = await client.call("trame.state.get")
        await client.ws.close()
        return answers, still

    answers, still = run(attack)
    for answer in answers:
        assert set(answer) == {"wslink", "id", "error"}, answer
        text = str(answer["error"])
        assert len(answer["error"]["message"]) < 60 and "data" not in answer["error"]
        assert "Traceback" not in text and ".py" not in text and "/" not in text
    assert "result" in still


# -- 3. memory -------------------------------------------------------------------------------------
def test_a_chunk_flood_closes_its_connection_with_bounded_server_memory(app):
    """The issue's attack: 40 chunks of 13 bytes, each opening a new message that claims 48 MiB
    (1.7 GB of server memory before)."""
    claim = 48 * 2**20

    async def flood(session):
        client = await connect(session, app)
        rss_before = rss_mb(app.pid)
        closed_after = None
        for i in range(40):
            try:
                await client.send_raw_chunk(1000 + i, 0, claim, b"x" * 13)
                await asyncio.sleep(0)
            except (ConnectionError, aiohttp.ClientConnectionError):
                closed_after = i
                break
        try:
            await client.receive_until(lambda m: False, wait_s=30)
        except ConnectionError:
            closed_after = closed_after if closed_after is not None else -1
        healthy = await connect(session, app)  # the server still serves
        answer = await healthy.call("trame.state.get")
        await healthy.ws.close()
        return rss_before, rss_mb(app.pid), closed_after, answer

    rss_before, rss_after, closed_after, answer = run(flood)
    assert closed_after is not None  # the connection was closed
    assert rss_after - rss_before < 64, (rss_before, rss_after)
    assert "result" in answer


def test_partial_messages_of_all_connections_share_one_total_budget(app):
    limits = Limits()
    claim = 40 * 2**20  # fits one connection's budget (48 MiB) ...
    n_fit = limits.total_budget_bytes // claim  # ... and 4 of them the server's (192 MiB)
    assert claim <= limits.connection_budget_bytes == MAX_MESSAGE_BYTES

    async def claims(session):
        clients = [await connect(session, app) for _ in range(n_fit + 1)]
        for client in clients:
            await client.send_raw_chunk(7, 0, claim, b"y" * 10)
        closed = []
        for client in clients:
            probe = await asyncio.wait_for(_answers(client), 60)
            closed.append(not probe)
        for client in clients:
            await client.ws.close()
        fresh = await connect(session, app)  # the budget was released with the connections
        await fresh.send_raw_chunk(7, 0, claim, b"z" * 10)
        alive = await _answers(fresh)
        await fresh.ws.close()
        return closed, alive

    closed, alive = run(claims)
    assert closed == [False] * n_fit + [True]
    assert alive


async def _answers(client: Client) -> bool:
    """The connection still answers a call (False: the server closed it)."""
    try:
        answer = await client.call("trame.state.get")
    except (ConnectionError, aiohttp.ClientConnectionError):
        return False
    return "result" in answer


def test_connections_are_capped(app):
    limit = Limits().max_connections

    async def crowd(session):
        clients = [await connect(session, app, hello=False) for _ in range(limit)]
        status = await refused_status(session, app)
        for client in clients:
            await client.ws.close()
        await asyncio.sleep(0.5)
        after = await refused_status(session, app)
        return status, after

    assert run(crowd) == (503, None)


# -- 5. per-page data and the last write -----------------------------------------------------------
def test_an_upload_is_not_sent_to_other_pages(app):
    content = b"solid box\nendsolid box\n" + b"#" * 200_000

    async def upload(session):
        uploader = await connect(session, app)
        watcher = await connect(session, app)
        upload = {"name": "box.stl", "size": len(content), "content": content}
        await uploader.set_state(upload_file=upload, pitch_deg=3)
        await watcher.wait_state(lambda s: s.get("pitch_deg") == 3)
        await watcher.wait_state(lambda s: "Upload refused" in str(s.get("upload_error")))
        for c in (uploader, watcher):
            await c.ws.close()
        return watcher

    watcher = run(upload)
    assert all(v is None for v in watcher.seen("upload_file"))
    assert not any(b"#" * 1000 in msgpack.packb(s) for s in watcher.states)


def test_the_last_write_wins_on_every_page(app):
    """Page B's unsent change is overwritten by A's value (trame's page does that), and B then
    sends A's value back after A moved on: B's echo must not win over A's newer value."""

    async def race(session):
        a, b, c = [await connect(session, app) for _ in range(3)]
        await a.set_state(azimuth_deg=10)
        await b.wait_state(lambda s: s.get("azimuth_deg") == 10)
        await a.set_state(azimuth_deg=11)  # A's last write
        await b.set_state(azimuth_deg=10)  # B's flush of the value it was sent: an echo
        await c.wait_state(lambda s: s.get("azimuth_deg") == 11)
        await b.set_state(pitch_deg=-5)  # B's own later write wins
        await a.wait_state(lambda s: s.get("pitch_deg") == -5)
        await c.wait_state(lambda s: s.get("pitch_deg") == -5)
        final = (await c.call("trame.state.get"))["result"]["state"]
        for p in (a, b, c):
            await p.ws.close()
        return final, a, c

    final, a, c = run(race)
    assert (final["azimuth_deg"], final["pitch_deg"]) == (11, -5)
    assert c.seen("azimuth_deg")[-1] == 11 and 10 not in c.seen("azimuth_deg")[1:]
    assert a.seen("azimuth_deg") in ([], [11])  # A is never sent its own values


def test_a_call_is_answered_after_the_state_it_caused(app):
    """The page reads a call's answer as "the server has it": the values a state update or a
    trigger caused for that page (a correction, the reset controls, ``busy`` for the new frame)
    must reach it before the answer, else a page waiting for its calls to be answered and for an
    idle server takes the old state for the final one (wslink sends a publish after an answer)."""

    async def calls(session):
        page = await connect(session, app)
        update = await page.set_state(distance_m=1e9)  # clamped: the correction comes back
        corrected = page.seen("distance_m")
        trigger = await page.call("trame.trigger", ["reset_controls", [], {}])
        reset = page.seen("distance_m")
        await page.ws.close()
        return update, corrected, trigger, reset

    update, corrected, trigger, reset = run(calls)
    assert "result" in update and corrected == [5000], (update, corrected)
    assert "result" in trigger and reset == [5000, 500], (trigger, reset)


# -- 4. connections ----------------------------------------------------------------------------
def test_half_open_connections_are_evicted_and_a_page_still_loads(app):
    """Connections that never finish their request line are capped per address (the longest
    idle closed first, app.server.connections), so a page load goes through a crowd of them."""
    import socket

    from app.server.connections import PER_ADDRESS

    crowd = []
    try:
        for _ in range(PER_ADDRESS + 40):
            s = socket.create_connection(("127.0.0.1", app.port), timeout=30)
            s.sendall(b"GET /index.html HTTP/1.1\r\nHost: x\r\nX-Slow: ")
            crowd.append(s)
        assert http_get(app.url)[0] == 200
        closed, deadline = 0, time.monotonic() + 30
        for s in crowd[:60]:  # the oldest: evicted by the newer ones
            s.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                closed += s.recv(1024) == b""
            except ConnectionResetError:
                closed += 1
            except TimeoutError:
                pass  # still open
        assert closed >= 40
    finally:
        for s in crowd:
            s.close()


# -- 6. uploads that would expand, and upload calls of the wrong shape ---------------------------
def peak_rss_mb(pid: int) -> float:
    """The highest resident set size ``pid`` has had, in MB (VmHWM)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmHWM for pid {pid}")


async def refusal_of(client: Client, **values) -> str:
    """Send ``values`` and return the upload message the page is then shown."""
    await client.set_state(upload_error="")
    start = len(client.states)
    await client.set_state(**values)  # the message may come before the answer
    if not any(s.get("upload_error") for s in client.states[start:]):
        await client.wait_state(lambda s: bool(s.get("upload_error")))
    return next(s["upload_error"] for s in client.states[start:] if s.get("upload_error"))


HOSTILE_UPLOADS = [
    ({"name": "fleet.glb", "content": bufferless_glb()}, "accessor 0 declares 900,000 elements"),
    ({"name": "fleet.glb", "content": shared_accessor_glb(400, 3000)}, "1,200,000 triangles"),
    ({"name": "big.ply", "content": ply_claiming(10**9, 10**9)}, "25,000,000,000 bytes of data"),
    ({"name": "big.stl", "content": stl_claiming(2**31)}, "does not match the triangle count"),
]
WRONG_SHAPES = [
    ({"upload_scale": [1, 2]}, "scale a list of 2 items is not a number; kept the previous"),
    ({"upload_file": [{"name": "a.stl", "content": b"x"}] * 2}, "one mesh file at a time"),
    ({"upload_file": {"name": "a.stl", "content": "solid a"}}, "came as text, not as the file"),
    ({"upload_file": "box.stl"}, "not a file upload ('box.stl')"),
    ({"upload_file": {"name": "a.stl"}}, "could not read the file"),
]


async def upload_attack(open_page, pid: int) -> tuple[list[str], float, dict]:
    """Every hostile upload and wrong-shaped call through one page (``open_page()``: a new
    connected Client): (the messages, the growth of the peak memory of process ``pid`` in MB,
    the state a new page then reads)."""
    page = await open_page()
    before = peak_rss_mb(pid)
    messages = []
    for upload, _ in HOSTILE_UPLOADS:
        messages.append(await refusal_of(page, upload_file={**upload, "size": 1}))
    for values, _ in WRONG_SHAPES:
        messages.append(await refusal_of(page, **values))
    growth = peak_rss_mb(pid) - before
    await page.ws.close()
    fresh = await open_page()  # the server still serves
    state = (await fresh.call("trame.state.get"))["result"]["state"]
    await fresh.ws.close()
    return messages, growth, state


def assert_refused_one_line_each(messages: list[str]) -> None:
    expected = [text for _, text in HOSTILE_UPLOADS + WRONG_SHAPES]
    for message, text in zip(messages, expected, strict=True):
        assert text in message and "\n" not in message, (text, message)
    assert all(m.startswith("Upload refused: ") for m in messages[: len(HOSTILE_UPLOADS)])


def test_hostile_uploads_and_wrong_shaped_calls_are_refused_in_one_line_the_server_alive(app):
    """--shared: one process for every page, so an upload that expanded would take them all."""
    messages, growth, state = run(
        lambda session: upload_attack(lambda: connect(session, app), app.pid)
    )
    assert_refused_one_line_each(messages)
    assert growth < 100, growth  # the 400-mesh file alone: 5.6 GB once expanded
    assert state["upload_scale"] == 1.0 and not state["upload_busy"]


def test_hostile_uploads_are_refused_in_a_launchers_session_which_stays_alive(tmp_path):
    """Launcher mode: the same uploads and calls through a session's page (the session forked
    from the launcher's preloaded parent, as by default)."""
    options = ("--max-sessions", "1", "--no-spare")
    with app_process(log_path=tmp_path / "server.log", sessions=True, app_args=options) as running:

        async def attack(session: aiohttp.ClientSession):
            navigation = {"Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}
            url = running.url + "&pixels=32"
            async with session.get(url, headers=navigation, allow_redirects=False) as answer:
                assert answer.status == 200
                jar = {k: m.value for k, m in answer.cookies.items()}
                page = await answer.text()
            path = json.loads(re.search(r"location\.replace\((\"[^\"]*\")\)", page)[1])
            headers = {
                "Origin": running.origin,
                "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items()),
            }
            ws_address = f"ws://127.0.0.1:{running.port}{path.split('?')[0]}ws"

            async def open_page() -> Client:
                ws = await session.ws_connect(ws_address, headers=headers, max_msg_size=0)
                client = Client(ws)
                assert "result" in await client.hello()
                return client

            probe = await open_page()  # the session listens: find its process
            await probe.ws.close()
            newest = max(psutil.Process(running.pid).children(recursive=True), key=_started)
            return await upload_attack(open_page, newest.pid), newest.pid

        (messages, growth, state), session_pid = run(attack)
        assert_refused_one_line_each(messages)
        assert growth < 100, growth
        assert state["upload_scale"] == 1.0 and not state["upload_busy"]
        assert psutil.pid_exists(running.pid) and psutil.Process(session_pid).is_running()


def _started(process: psutil.Process) -> float:
    return process.create_time()


def test_the_doors_cookies_are_secure_only_where_the_page_is_served_over_https():
    from aiohttp.test_utils import make_mocked_request

    def attributes(door, host: str) -> dict:
        return door.cookie_attributes(make_mocked_request("GET", "/", headers={"Host": host}))

    proxied = Door("t", "127.0.0.1", Limits(), ("https://lab.example",))
    assert attributes(proxied, "lab.example") == {
        "httponly": True,
        "samesite": "Strict",
        "path": "/",
        "secure": True,
    }
    assert attributes(proxied, "lab.example:443")["secure"]
    assert not attributes(proxied, "127.0.0.1:8080")["secure"]  # the server's own address
    assert not attributes(Door("t", "127.0.0.1", Limits()), "lab.example")[
        "secure"
    ]  # no proxy configured: a Host header alone proves nothing
