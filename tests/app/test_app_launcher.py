"""The launcher (app.server.launcher: each tab its own session) without a browser.

Most tests run the launcher in this process with stand-in session processes
(tests/support/fake_session.py, which start in well under a second); the last ones start the real
``python -m app`` launcher and its real session processes: a wslink hello and a state change
through the proxy, the token kept off the command lines, and no process left behind after SIGTERM
or SIGKILL. Every wait is bounded and only catches hangs; no test asserts a wall time.
"""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import contextlib
import dataclasses
import json
import logging
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

import aiohttp
import psutil
import pytest
from aiohttp import web
from support.ci import skip_unless_ci
from support.fork import require_fork
from support.hostile_client import Client
from support.launch import app_process

from app.logic import upload_folders
from app.server import connections, proxy
from app.server import launcher as lau

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
async def serving(the_caps: lau.Caps, **options):
    """A launcher with stand-in sessions on a free port, behind its connection guard:
    (launcher, base address, client); ``options``: the Launcher's own (``origins``)."""
    launcher = lau.Launcher(TOKEN, "127.0.0.1", the_caps, command=fake_command, **options)
    async with listening(launcher) as served:
        yield served


@contextlib.asynccontextmanager
async def listening(launcher: lau.Launcher):
    """``launcher`` served on a free port behind its connection guard: (launcher, base address,
    client)."""
    runner = web.AppRunner(launcher.web_app(), access_log=None)
    await runner.setup()
    server, sweeper, port = await connections.listen(runner, launcher.guard, "127.0.0.1", 0)
    try:
        async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as client:
            yield launcher, f"http://127.0.0.1:{port}", client
    finally:
        await connections.stop_listening(server, sweeper)
        await runner.cleanup()


def cookie(base: str) -> dict[str, str]:
    """The launcher's token cookie (what the printed address leaves in the browser)."""
    return {"Cookie": f"lmapd-token-{urllib.parse.urlsplit(base).port}={TOKEN}"}


NAVIGATION = {"Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}


@dataclasses.dataclass(frozen=True)
class Session:
    """A session as its browser holds it: the address the door sends the tab to, and the
    cookies the door set (the session's own, the browser's id)."""

    location: str
    cookies: dict[str, str]

    @property
    def path(self) -> str:  # /s/<id>/
        return self.location.split("?")[0].split("#")[0]

    @property
    def id(self) -> str:
        return self.path.split("/")[2]

    def headers(self, base: str, *names: str) -> dict[str, str]:
        """The Cookie header of this browser: the token's cookie and its own cookies."""
        jar = {**self.cookies}
        jar[f"lmapd-token-{urllib.parse.urlsplit(base).port}"] = TOKEN
        return {"Cookie": "; ".join(f"{k}={v}" for k, v in jar.items())}


async def get(client, url: str, **headers) -> tuple[int, str, dict]:
    async with client.get(url, allow_redirects=False, headers=headers) as answer:
        return answer.status, await answer.text(), dict(answer.headers)


async def open_door(client, base: str, query: str = "", **headers) -> tuple[int, str, dict]:
    """GET the door as a tab's navigation: (status, page, the cookies it set)."""
    url = f"{base}/?token={TOKEN}{query}"
    async with client.get(url, allow_redirects=False, headers={**NAVIGATION, **headers}) as answer:
        cookies = {k: m.value for k, m in answer.cookies.items()}
        return answer.status, await answer.text(), cookies


MOVE = re.compile(r"location\.replace\((\"[^\"]*\")\)")


async def new_session(client, base: str, query: str = "", **headers) -> Session:
    status, page, cookies = await open_door(client, base, query, **headers)
    assert status == 200, status
    location = json.loads(MOVE.search(page)[1])
    assert location.startswith("/s/")
    return Session(location, cookies)


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


def test_the_start_says_whether_a_class_of_30_fits():
    from app.server.process import class_line

    mib = lau.MIB
    small = lau.default_caps(available_bytes=4000 * mib, session_rss_bytes=370 * mib)
    assert small.max_sessions == 8
    line = class_line(small)
    assert "room for 8 tabs, not a class of 30" in line and "about 12 GB" in line
    big = lau.default_caps(available_bytes=64000 * mib, session_rss_bytes=370 * mib)
    assert big.max_sessions == 30 and "room for a class of 30" in class_line(big)


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
def test_the_token_opens_a_session_of_its_own_and_its_page_is_proxied(caplog):
    caplog.set_level(logging.WARNING, logger="app.server.launcher")

    async def body():
        async with serving(caps()) as (launcher, base, client):
            assert (await get(client, f"{base}/"))[0] == 403
            assert (await get(client, f"{base}/?token=wrong"))[0] == 403
            first = await new_session(client, base, "&pitch_deg=30")
            assert first.location.endswith(f"/?pitch_deg=30#token={TOKEN}")  # token after '#'
            assert first.cookies[f"lmapd-session-{first.id}"]
            second = await new_session(client, base)
            assert first.id != second.id and len(launcher.sessions) == 2
            assert len({c.port for c in launcher.sessions.values()}) == 2
            # the session's page: through the launcher, with the session's own token
            status, text, _ = await get(
                client, f"{base}{first.path}?pitch_deg=30", **first.headers(base)
            )
            assert status == 200 and "token ok" in text and "pitch_deg=30" in text
            status, text, _ = await get(client, f"{base}{first.path}x.js", **first.headers(base))
            assert (status, text.split(";")[1]) == (200, " token ok")
            status, _, headers = await get(
                client, f"{base}{first.path[:-1]}", **first.headers(base)
            )
            assert status == 302 and headers["Location"].endswith("/")
            async with client.post(f"{base}{first.path}", data=b"x") as answer:
                assert answer.status == 405
            # trame's page asks a session manager where to connect (wslink's launcher protocol):
            # its session's websocket, at the address its page was loaded from (not logged)
            probe = f"{base}{first.path}paraview/"
            async with client.post(probe, headers=first.headers(base), json={}) as ans:
                assert ans.status == 200 and ans.headers["Cache-Control"] == "no-store"
                answer = await ans.json()
            assert answer == {"id": first.id, "sessionURL": f"ws://USE_HOST{first.path}ws"}
            # trame's client lowercases the address before it connects: the same session
            assert answer["sessionURL"].lower() == f"ws://use_host{first.path}ws"
            for headers in (cookie(base), second.headers(base)):  # not this browser's session
                async with client.post(probe, headers=headers) as ans:
                    assert ans.status == 403 and "sessionURL" not in await ans.text()
            async with client.post(f"{base}/s/nope/paraview/", headers=cookie(base)) as ans:
                assert ans.status == 404 and "No such session" in await ans.text()

    run(body)
    refusals = [r for r in caplog.records if "non-GET" in r.getMessage()]
    assert len(refusals) == 1  # the POST to the page, not the page's own probe


def test_session_ids_are_128_bits_of_lowercase_hex():
    """trame's client lowercases the session address it is given: an id must survive that."""
    from app.server import routes

    ids = {routes.new_session_id() for _ in range(200)}
    assert len(ids) == 200
    for session_id in ids:
        assert re.fullmatch(r"[0-9a-f]{32}", session_id)
        assert routes.SESSION_ID.match(f"/s/{session_id}/ws")["id"] == session_id


def test_a_session_is_bound_to_the_browser_that_opened_it():
    """Whoever reads a session's address (the token and the id, off a projector) but lacks the
    cookie that came with it can neither load its pages nor open its websocket."""

    async def body():
        async with serving(caps()) as (launcher, base, client):
            teacher = await new_session(client, base)
            student = await new_session(client, base)
            for headers in (cookie(base), student.headers(base), {}):
                status, text, _ = await get(client, f"{base}{teacher.path}", **headers)
                assert status == 403 and "token ok" not in text
                status, _, _ = await get(client, f"{base}{teacher.path}?token={TOKEN}", **headers)
                assert status == 403
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await client.ws_connect(
                        f"ws://{base[7:]}{teacher.path}ws?token={TOKEN}",
                        headers={"Origin": base, **headers},
                    )
                assert refused.value.status == 403
            assert launcher.sessions[teacher.id].n_sockets == 0
            status, text, _ = await get(client, f"{base}{teacher.path}", **teacher.headers(base))
            assert status == 200 and "token ok" in text
            ws = await client.ws_connect(
                f"ws://{base[7:]}{teacher.path}ws",
                headers={"Origin": base, **teacher.headers(base)},
            )
            await ws.close()

    run(body)


@pytest.mark.parametrize(
    "headers",
    [
        {"Sec-Fetch-Mode": "no-cors", "Sec-Fetch-Dest": "image"},  # <img src=...>
        {"Sec-Fetch-Mode": "cors", "Sec-Fetch-Dest": "empty"},  # fetch() from another page
        {"Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "iframe"},  # a frame in another page
        {"Sec-Fetch-Mode": "navigate", "Sec-Purpose": "prefetch"},  # a link prefetch
        {"Purpose": "prefetch"},
    ],
)
def test_only_a_tabs_navigation_starts_a_session(headers):
    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            async with client.head(f"{base}/?token={TOKEN}", headers=NAVIGATION) as answer:
                assert answer.status == 200  # a link preview: no session
            url = f"{base}/?token={TOKEN}"
            async with client.get(url, allow_redirects=False, headers=headers) as answer:
                assert answer.status == 403 and "/s/" not in await answer.text()
            assert not launcher.sessions and not launcher._all and launcher.n_not_navigation == 1
            await new_session(client, base)  # the tab's own navigation
            assert len(launcher.sessions) == 1

    run(body)


@pytest.mark.parametrize(
    ("site", "token_in_address", "starts"),
    [
        ("same-site", False, False),  # a page on another port of 127.0.0.1 (cookies ignore ports)
        ("cross-site", False, False),
        ("same-site", True, True),  # whoever holds the printed address may start one
        ("same-origin", False, True),  # a link of the app's own pages
        ("none", False, True),  # the address bar, a bookmark, a reload
        (None, False, True),  # a client that sends no fetch metadata
    ],
)
def test_the_token_cookie_alone_starts_a_session_only_from_the_apps_own_pages(
    site, token_in_address, starts
):
    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            headers = {**NAVIGATION, **({"Sec-Fetch-Site": site} if site else {})}
            if not token_in_address:
                headers.update(cookie(base))
            url = f"{base}/?token={TOKEN}" if token_in_address else f"{base}/?pixels=32"
            async with client.get(url, allow_redirects=False, headers=headers) as answer:
                text = await answer.text()
                status = answer.status
            await until(lambda: launcher.n_starting == 0, "the door to finish")
            return status, text, len(launcher.sessions)

    status, text, n_sessions = run(body)
    if starts:
        assert (status, n_sessions) == (200, 1) and "/s/" in text
    else:
        assert (status, n_sessions) == (403, 0) and "/s/" not in text
        assert "Open the address that lmapd app printed" in text and "href='/?pixels=32'" in text


@pytest.mark.parametrize("behind_tls", [False, True], ids=["http", "https-proxy"])
def test_the_doors_cookies_are_httponly_strict_scoped_and_secure_behind_https(behind_tls):
    """The token's and the browser's cookies at ``/`` (the door's own address), the session's at
    ``/s/<id>/`` only; all HttpOnly and SameSite=Strict, and Secure where the page is served
    over https (here: through a proxy at a configured https address, which passes the Host)."""
    options = {"origins": ("https://lab.example",)} if behind_tls else {}
    host = {"Host": "lab.example", "X-Forwarded-For": "10.0.0.5"} if behind_tls else {}

    async def body():
        async with serving(caps(spare=False), **options) as (launcher, base, client):
            url = f"{base}/?token={TOKEN}"
            headers = {**NAVIGATION, **host}
            async with client.get(url, allow_redirects=False, headers=headers) as answer:
                await answer.text()
                return answer.headers.getall("Set-Cookie")

    set_cookies = run(body)
    by_name = {line.split("=", 1)[0]: line for line in set_cookies}
    assert len(by_name) == 3, set_cookies
    for name, line in by_name.items():
        attributes = {part.strip().split("=")[0].lower() for part in line.split(";")[1:]}
        assert {"httponly", "samesite", "path"} <= attributes, line
        assert "SameSite=Strict" in line
        assert ("secure" in attributes) is behind_tls, line
        session = name.startswith("lmapd-session-")
        want = f"Path=/s/{name.removeprefix('lmapd-session-')}/" if session else "Path=/;"
        assert want in line + ";", line
    assert sum(n.startswith(("lmapd-token-", "lmapd-client-")) for n in by_name) == 2


def test_every_answer_carries_the_security_headers_and_the_doors_script_its_nonce():
    async def body():
        async with serving(caps(spare=False)) as (_, base, client):
            url = f"{base}/?token={TOKEN}"
            async with client.get(url, allow_redirects=False, headers=NAVIGATION) as answer:
                door, page = dict(answer.headers), await answer.text()
            refused = (await get(client, f"{base}/?token=wrong"))[2]
            missing = (await get(client, f"{base}/s/nope/", **cookie(base)))[2]
            return door, page, refused, missing

    door, page, refused, missing = run(body)
    nonce = re.search(r"<script nonce='([^']+)'>window\.location\.replace", page)[1]
    policy = door["Content-Security-Policy"]
    assert f"'nonce-{nonce}'" in policy.split("; ")[1]  # script-src
    assert "frame-ancestors 'none'" in policy and "connect-src 'self' ws://127.0.0.1:" in policy
    assert door["Cache-Control"] == "no-store"
    for headers in (door, refused, missing):
        assert headers["X-Content-Type-Options"] == "nosniff"
        assert headers["Referrer-Policy"] == "no-referrer" and headers["X-Frame-Options"] == "DENY"
        assert "default-src 'self'" in headers["Content-Security-Policy"]
    assert "nonce" not in refused["Content-Security-Policy"]  # a nonce only where it is used


def test_an_unknown_session_or_a_path_out_of_it_gets_a_page_not_a_trace():
    async def body():
        async with serving(caps()) as (_, base, client):
            session = await new_session(client, base)
            status, text, _ = await get(client, f"{base}/s/nope/?pixels=32", **cookie(base))
            assert status == 404 and "No such session" in text
            assert "href='/?pixels=32'" in text and "Traceback" not in text
            for path in ("%2e%2e/%2e%2e/etc/passwd", "a/%2e%2e/%2e%2e/x", "..%5c..%5cx"):
                url = aiohttp.client.URL(f"{base}{session.path}{path}", encoded=True)
                headers = session.headers(base)
                async with client.get(url, allow_redirects=False, headers=headers) as answer:
                    assert answer.status == 404, path
            assert (await get(client, f"{base}/etc/passwd", **cookie(base)))[0] == 404

    run(body)


def test_over_the_caps_a_503_page_says_how_many_sessions_are_open():
    async def body():
        async with serving(caps(max_sessions=2)) as (launcher, base, client):
            await new_session(client, base)
            await new_session(client, base)
            status, text, _ = await open_door(client, base)
            assert status == 503 and "2 sessions are open" in text and "--max-sessions" in text
            assert launcher.spare is None and len(launcher._all) == 2  # the spare counts
        one = caps(memory_cap_bytes=150 * lau.MIB, session_bytes=100 * lau.MIB, spare=False)
        async with serving(one) as (launcher, base, client):
            await new_session(client, base)
            status, text, _ = await open_door(client, base)
            assert status == 503 and "1 session is open and use" in text and "MB" in text

    run(body)


def test_the_503_page_says_when_a_session_frees_if_nobody_uses_it():
    """The soonest an open session ends by the reaper's rules if its page sends nothing more:
    its input-idle time left while its websocket is open, its closed-tab time once it is not."""

    async def body():
        the_caps = caps(max_sessions=1, spare=False, idle_s=150.0, input_idle_s=600.0)
        async with serving(the_caps) as (launcher, base, client):
            session = await new_session(client, base)
            child = launcher.sessions[session.id]
            pages = []
            # no websocket yet: the closed-tab time (150 s, over connect_s) is the soonest
            pages.append((await open_door(client, base))[:2])
            ws = await client.ws_connect(
                f"ws://{base[7:]}{session.path}ws",
                headers={"Origin": base, **session.headers(base)},
            )
            pages.append((await open_door(client, base))[:2])  # 600 s of input idle left
            child.last_input_s -= 330.0  # its page last sent something 5.5 minutes ago
            pages.append((await open_door(client, base))[:2])
            child.last_input_s -= 250.0  # 20 s left
            pages.append((await open_door(client, base))[:2])
            await ws.close()
            return pages

    pages = run(body)
    assert [status for status, _ in pages] == [503] * 4
    texts = [text for _, text in pages]
    assert "a session frees within about 3 minutes" in texts[0]
    assert "a session frees within about 10 minutes" in texts[1]
    assert "a session frees within about 5 minutes" in texts[2]
    assert "a session frees within a minute" in texts[3]
    for text in texts:
        assert "1 session is open" in text and "If nobody uses it again" in text
        assert "after 10 minutes without input, or 2.5 minutes after its tab is closed" in text


def gated(launcher: lau.Launcher) -> asyncio.Event:
    """Hold the launcher's session processes back from starting until the returned event is
    set (a class opening together on a slow machine, a session that takes seconds)."""
    gate = asyncio.Event()
    start = launcher.start_child

    async def held_start():
        await gate.wait()
        return await start()

    launcher.start_child = held_start
    return gate


def test_the_door_says_at_once_that_the_session_is_starting_and_moves_the_tab_when_it_listens():
    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            gate = gated(launcher)
            url = f"{base}/?token={TOKEN}&pixels=32&sessionURL=ws%3A%2F%2Fevil.example%2Fws"
            answering = client.get(url, allow_redirects=False, headers=NAVIGATION)
            async with await asyncio.wait_for(answering, WAIT_S) as answer:
                assert answer.status == 200
                first = await asyncio.wait_for(answer.content.readuntil(b"\n"), WAIT_S)
                assert b"Starting your session" in first and b"location" not in first
                assert launcher.n_starting == 1 and not launcher.sessions  # nothing listens yet
                gate.set()
                rest = (await asyncio.wait_for(answer.content.read(), WAIT_S)).decode()
                cookies = {k: m.value for k, m in answer.cookies.items()}
            location = json.loads(MOVE.search(rest)[1])
            (session_id,) = launcher.sessions
            assert location.startswith(f"/s/{session_id}/?pixels=32")
            assert "evil" not in location  # trame's page would read it as where to connect
            assert cookies[lau.session_cookie(session_id)] == launcher.sessions[session_id].secret
            port = urllib.parse.urlsplit(base).port
            assert cookies[f"lmapd-token-{port}"] == TOKEN  # the address's token, kept

    run(body)


def test_a_tab_closed_while_its_session_starts_leaves_no_session_behind():
    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            gate = gated(launcher)
            answering = client.get(f"{base}/?token={TOKEN}", headers=NAVIGATION)
            answer = await asyncio.wait_for(answering, WAIT_S)
            first = await asyncio.wait_for(answer.content.readuntil(b"\n"), WAIT_S)
            assert b"Starting your session" in first
            answer.close()  # the tab went away (closed, or navigated elsewhere)
            await asyncio.sleep(0.2)
            gate.set()
            await until(lambda: launcher.n_starting == 0, "the start to finish")
            await until(lambda: not launcher.sessions and not launcher._all, "the session to end")

    run(body)


def test_a_session_that_cannot_start_ends_its_page_with_a_message_and_a_link():
    def failing(scene, options=()):
        return [sys.executable, "-c", "raise SystemExit(3)"]

    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            launcher.command = failing
            status, page, _ = await open_door(client, base)
            assert status == 200 and "Starting your session" in page
            assert "could not start" in page and "Try again" in page
            assert "location.replace" not in page and not launcher.sessions

    run(body)


def test_a_burst_of_page_loads_counts_starting_sessions_at_their_size():
    """Five tabs opened at once under a cap that fits two sessions start two: a process that
    is still starting counts at a session's measured size, not at the little it uses yet."""

    async def body():
        two = caps(max_sessions=10, memory_cap_bytes=250 * lau.MIB, session_bytes=100 * lau.MIB)
        async with serving(dataclasses.replace(two, spare=False)) as (launcher, base, client):
            answers = await asyncio.gather(*(open_door(client, base) for _ in range(5)))
            statuses = sorted(a[0] for a in answers)
            assert statuses == [200, 200, 503, 503, 503]
            assert len(launcher.sessions) == 2 and len(launcher._all) == 2

    run(body)


@pytest.mark.parametrize("behind_proxy", [True, False], ids=["proxy", "no-proxy"])
def test_behind_a_configured_proxy_the_address_cap_counts_the_forwarded_address(behind_proxy):
    """Every student arrives from the proxy's loopback address: with --public-url the cap is
    kept per forwarded address; without one the header is not believed (loopback: no cap)."""
    options = {"origins": ("https://lab.example",)} if behind_proxy else {}

    async def body():
        async with serving(caps(per_address=1, spare=False, max_sessions=5), **options) as (
            launcher,
            base,
            client,
        ):
            statuses = []
            for forwarded in ("10.0.0.5", "10.0.0.5", "198.51.100.7, 10.0.0.6", "10.0.0.5"):
                headers = {"X-Forwarded-For": forwarded}
                status, _, _ = await open_door(client, base, "", **headers)
                statuses.append(status)
                await until(lambda: launcher.n_starting == 0, "the door to finish")
            return statuses, sorted(c.address for c in launcher.sessions.values())

    statuses, addresses = run(body)
    if behind_proxy:
        assert statuses == [200, 503, 200, 503] and addresses == ["10.0.0.5", "10.0.0.6"]
    else:
        assert statuses == [200] * 4 and addresses == ["127.0.0.1"] * 4


def test_at_its_own_cap_an_address_is_told_when_one_of_its_own_sessions_frees():
    """Another computer's session ending makes no room under one computer's own cap."""

    async def body():
        the_caps = caps(per_address=1, spare=False, max_sessions=5, idle_s=3000.0)
        async with serving(the_caps, origins=("https://lab.example",)) as (launcher, base, client):
            for forwarded in ("10.0.0.5", "10.0.0.6"):
                await open_door(client, base, "", **{"X-Forwarded-For": forwarded})
                await until(lambda: launcher.n_starting == 0, "the door to finish")
            other = next(c for c in launcher.sessions.values() if c.address == "10.0.0.6")
            other.last_input_s -= the_caps.input_idle_s - 20.0  # ends within a minute
            return await open_door(client, base, "", **{"X-Forwarded-For": "10.0.0.5"})

    status, text, _ = run(body)
    assert status == 503 and "Your computer has 1 session" in text
    assert "a session frees within about 30 minutes" in text


def test_a_browser_holds_at_most_its_share_of_sessions():
    async def body():
        the_caps = caps(max_sessions=6, per_client=2, spare=False)
        async with serving(the_caps) as (launcher, base, client):
            first = await new_session(client, base)
            name = f"lmapd-client-{urllib.parse.urlsplit(base).port}"
            browser = {"Cookie": f"{name}={first.cookies[name]}"}
            opened = [first] + [await new_session(client, base, **browser) for _ in range(3)]
            assert len(launcher.sessions) == 2  # the oldest two ended
            assert set(launcher.sessions) == {s.id for s in opened[-2:]}
            other = await new_session(client, base)  # another browser
            assert len(launcher.sessions) == 3 and other.id in launcher.sessions

    run(body)


def test_the_spare_is_taken_and_replaced():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            await until(lambda: launcher.spare is not None and launcher.spare.done(), "a spare")
            spare = launcher.spare.result()
            session = await new_session(client, base)
            assert launcher.sessions[session.id] is spare
            await until(lambda: launcher.spare is not None, "the next spare")

    run(body)


def test_the_websocket_is_proxied_with_its_origin_checked_and_its_frames_bounded():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            session = await new_session(client, base)
            url = f"ws://{base[7:]}{session.path}ws"
            own = session.headers(base)
            for origin in ("http://evil.example", None):
                headers = {"Origin": origin, **own} if origin else own
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await client.ws_connect(url, headers=headers)
                assert refused.value.status == 403
            child = launcher.sessions[session.id]
            ws = await client.ws_connect(url, headers={"Origin": base, **own}, max_msg_size=0)
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
            held = [
                await client.ws_connect(url, headers={"Origin": base, **own})
                for _ in range(launcher.caps.sockets_per_session)
            ]
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:  # one tab's share
                await client.ws_connect(url, headers={"Origin": base, **own})
            assert refused.value.status == 503
            await held[0].send_bytes(b"again")  # the session goes on
            assert (await asyncio.wait_for(held[0].receive(), WAIT_S)).data == b"again"
            for ws in held:
                await ws.close()

    run(body)


def test_a_page_on_this_machine_gets_its_frames_uncompressed_one_from_the_network_deflated():
    """permessage-deflate only where it saves something: a page on this machine is answered
    without it, a page that a reverse proxy forwards (X-Forwarded-For or Forwarded) with it."""

    async def body():
        async with serving(caps()) as (_launcher, base, client):
            session = await new_session(client, base)
            url = f"ws://{base[7:]}{session.path}ws"
            own = {"Origin": base, **session.headers(base)}
            for forwarded, deflated in (
                ({}, False),
                ({"X-Forwarded-For": "192.0.2.7"}, True),
                ({"Forwarded": "for=192.0.2.7"}, True),
            ):
                ws = await client.ws_connect(url, headers={**own, **forwarded}, compress=15)
                assert bool(ws.compress) is deflated, forwarded
                await ws.send_bytes(b"a" * 10_000)
                answer = await asyncio.wait_for(ws.receive(), WAIT_S)
                assert answer.data == b"a" * 10_000  # the frames pass either way
                await ws.close()

    run(body)


def test_idle_sessions_end_and_dead_ones_are_forgotten_and_close_stops_all():
    async def body():
        async with serving(caps()) as (launcher, base, client):
            idle = await new_session(client, base)
            kept = await new_session(client, base)
            dies = await new_session(client, base)
            ws = await client.ws_connect(
                f"ws://{base[7:]}{kept.path}ws", headers={"Origin": base, **kept.headers(base)}
            )
            victim = launcher.sessions[dies.id]
            idle_child = launcher.sessions[idle.id]
            left = Path(tempfile.gettempdir()) / f"{upload_folders.PREFIX}{victim.pid}-test"
            left.mkdir()  # the dead session's uploads
            (left / "upload-1.glb").write_bytes(b"x")
            other = Path(tempfile.mkdtemp(prefix=f"{upload_folders.PREFIX}{os.getpid()}-"))
            # from now on; the page that never connected is given connect_s
            launcher.caps = dataclasses.replace(launcher.caps, idle_s=0.3, connect_s=0.3)
            os.kill(victim.pid, signal.SIGKILL)
            await until(lambda: len(launcher.sessions) == 1, "the idle and the dead session")
            assert launcher.n_reaped == 1 and idle_child.proc.returncode is not None
            assert not left.exists() and other.is_dir()  # only the dead one's folder removed
            other.rmdir()
            status, text, _ = await get(client, f"{base}{idle.path}", **idle.headers(base))
            assert status == 404 and "No such session" in text
            assert (await get(client, f"{base}{kept.path}", **kept.headers(base)))[0] == 200
            await ws.close()
            await until(lambda: not launcher.sessions, "the closed page's session")
            await until(lambda: launcher.spare is not None and launcher.spare.done(), "a spare")
            pids = [c.pid for c in launcher._all]
        assert pids and not any(psutil.pid_exists(p) and _running(p) for p in pids)

    run(body)


def test_a_stopped_sessions_page_gets_a_504_after_the_read_timeout_not_a_hang(monkeypatch):
    monkeypatch.setattr(proxy, "READ_S", 0.5)

    async def body():
        async with serving(caps(spare=False)) as (launcher, base, client):
            session = await new_session(client, base)
            child = launcher.sessions[session.id]
            assert (await get(client, f"{base}{session.path}", **session.headers(base)))[0] == 200
            os.kill(child.pid, signal.SIGSTOP)
            try:
                stuck = await asyncio.wait_for(
                    get(client, f"{base}{session.path}", **session.headers(base)), WAIT_S
                )
            finally:
                os.kill(child.pid, signal.SIGCONT)
            again = await get(client, f"{base}{session.path}", **session.headers(base))
            return stuck, again

    (status, text, _), again = run(body)
    assert status == 504 and "not answering" in text
    assert again[0] == 200


def test_a_page_still_loading_keeps_its_session_past_the_idle_time_until_connect_s():
    """A new session's page loads its files before it opens its websocket (seconds on a loaded
    machine): the reaper gives it connect_s, not idle_s; once its page has connected and closed,
    idle_s applies."""

    async def body():
        async with serving(caps(idle_s=0.2, connect_s=WAIT_S, spare=False)) as (
            launcher,
            base,
            client,
        ):
            loading = await new_session(client, base)
            child = launcher.sessions[loading.id]
            await asyncio.sleep(1.0)  # five idle times, a few reaper rounds
            assert loading.id in launcher.sessions and not child.connected
            ws = await client.ws_connect(
                f"ws://{base[7:]}{loading.path}ws",
                headers={"Origin": base, **loading.headers(base)},
            )
            await until(lambda: child.connected, "the page's websocket")
            await ws.close()
            await until(lambda: loading.id not in launcher.sessions, "the closed page's session")
            late = await new_session(client, base)
            launcher.caps = dataclasses.replace(launcher.caps, connect_s=0.3)
            await until(lambda: late.id not in launcher.sessions, "the page that never came")

    run(body)


def test_a_pump_whose_other_side_closed_ends_quietly():
    """A page that goes while its session's frames are on their way: the frame's send fails
    (aiohttp's ClientConnectionResetError) and the pump ends without an exception that asyncio
    would log as a traceback ("Task exception was never retrieved")."""

    class Source:
        def __aiter__(self):
            return self

        async def __anext__(self):
            return aiohttp.WSMessage(aiohttp.WSMsgType.BINARY, b"frame", None)

    class ClosingSink:
        async def send_bytes(self, data):
            raise aiohttp.ClientConnectionResetError("Cannot write to closing transport")

    async def body():
        assert await proxy._pump(Source(), ClosingSink()) is None

    run(body)


def test_a_held_socket_does_not_keep_a_session_without_input_alive():
    """A page that holds its websocket open but sends nothing is ended after the input idle
    time (its page is told: close code 4000, "session ended"); one that sends goes on until the
    maximum age."""

    async def body():
        the_caps = caps(input_idle_s=WAIT_S, max_age_s=WAIT_S, spare=False)
        async with serving(the_caps) as (launcher, base, client):
            held = await new_session(client, base)
            busy = await new_session(client, base)
            sockets = [
                await client.ws_connect(
                    f"ws://{base[7:]}{s.path}ws", headers={"Origin": base, **s.headers(base)}
                )
                for s in (held, busy)
            ]
            # the idle time made short once both are connected (starting them may take longer)
            launcher.caps = dataclasses.replace(launcher.caps, input_idle_s=2.0)
            deadline = time.monotonic() + WAIT_S
            while held.id in launcher.sessions:  # the busy page sends input all along
                assert time.monotonic() < deadline, "the held session was not ended"
                await sockets[1].send_bytes(b"input")
                await asyncio.wait_for(sockets[1].receive(), WAIT_S)
                await asyncio.sleep(0.1)
            msg = await asyncio.wait_for(sockets[0].receive(), WAIT_S)
            assert msg.type == aiohttp.WSMsgType.CLOSE and msg.data == lau.SESSION_ENDED
            assert busy.id in launcher.sessions
            launcher.caps = dataclasses.replace(launcher.caps, max_age_s=0.2)
            await until(lambda: busy.id not in launcher.sessions, "the old session to end")
            for ws in sockets:
                await ws.close()

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
@pytest.mark.parametrize("fork", [False, True], ids=["processes", "forked"])
def test_the_real_launcher_proxies_a_session_and_leaves_no_process_after_sigterm(tmp_path, fork):
    """A session through the real launcher: its own process (``python -m app``), or forked from
    the preloaded parent (``--fork-sessions``: the parent and the session)."""
    options = ("--max-sessions", "2", "--no-spare")
    options += ("--fork-sessions",) if fork else ("--process-sessions",)
    with app_process(log_path=tmp_path / "server.log", sessions=True, app_args=options) as running:

        async def body():
            async with aiohttp.ClientSession() as client:
                url = running.url + "&pixels=32"
                async with client.get(url, headers=NAVIGATION, allow_redirects=False) as answer:
                    assert answer.status == 200
                    jar = {k: m.value for k, m in answer.cookies.items()}
                    path = json.loads(MOVE.search(await answer.text())[1]).split("?")[0]
                ws = await client.ws_connect(
                    f"ws://127.0.0.1:{running.port}{path}ws",
                    headers={
                        "Origin": running.origin,
                        "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items()),
                    },
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
        assert len(children) == 1 + fork
        assert not any(running.token in " ".join(c.cmdline()) for c in children)
        os.kill(running.pid, signal.SIGTERM)
        gone, alive = psutil.wait_procs(children, timeout=WAIT_S)
        assert alive == [] and len(gone) == 1 + fork


@pytest.mark.slow
@pytest.mark.parametrize("fork", [False, True], ids=["processes", "forked"])
def test_sessions_stop_when_their_launcher_is_killed(tmp_path, fork):
    cmd = [sys.executable, "-m", "app", "--port", "0", "--max-sessions", "1"]
    cmd += ["--fork-sessions"] if fork else ["--process-sessions"]
    root = Path(__file__).resolve().parents[2]
    with open(tmp_path / "out.log", "w+b") as out:
        proc = subprocess.Popen(cmd, cwd=root, stdout=out, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + WAIT_S
            while len(_descendants(proc.pid)) < 1 + fork:  # the spare (and its parent)
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


# -- connections and logs, the launcher in a process of its own ----------------------------------
FAKE_LAUNCHER = Path(__file__).resolve().parents[1] / "support" / "fake_launcher.py"
OPEN_FILES = 1024  # a common default soft limit


@contextlib.contextmanager
def launcher_process(tmp_path: Path, *args: str, open_files: int = OPEN_FILES):
    """The launcher with stand-in sessions in a process limited to ``open_files`` open files
    (soft and hard): (its address with the token, its log file)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (open_files, open_files))

    log_path = tmp_path / "launcher.log"
    with open(log_path, "wb") as log_file:
        proc = subprocess.Popen(
            [sys.executable, str(FAKE_LAUNCHER), *args],
            stdout=subprocess.PIPE,
            stderr=log_file,
            preexec_fn=limit,
        )
        try:
            line = proc.stdout.readline().decode()
            assert line.startswith("lmapd-sim app: http://"), line
            yield line.split()[-1], log_path
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=WAIT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_a_thousand_half_open_connections_do_not_stop_a_page_load(tmp_path):
    """Under a 1,024 open-file limit, 1,000 connections that never finish their request line do
    not keep a tab from opening its session (idle ones are evicted over the per-address cap),
    and the server closes them all after its idle time."""
    connections.raise_open_file_limit()  # this process holds the client ends
    n_sockets = min(1000, resource.getrlimit(resource.RLIMIT_NOFILE)[0] - 200)
    if n_sockets < 500:
        skip_unless_ci(f"this process may open only {n_sockets + 200} files")
    with launcher_process(tmp_path, "--guard-idle-s", "3") as (url, log_path):
        parts = urllib.parse.urlsplit(url)
        half_open = []
        try:
            for _ in range(n_sockets):
                s = socket.create_connection((parts.hostname, parts.port), timeout=WAIT_S)
                s.sendall(f"GET /?{parts.query} HTTP/1.1\r\nHost: x\r\nX-Slow: ".encode())
                half_open.append(s)

            async def body():
                async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as client:
                    token = urllib.parse.parse_qs(parts.query)["token"][0]
                    door = f"{parts.scheme}://{parts.netloc}/?token={token}"
                    async with client.get(door, headers=NAVIGATION) as answer:
                        assert answer.status == 200
                        jar = {k: m.value for k, m in answer.cookies.items()}
                        location = json.loads(MOVE.search(await answer.text())[1])
                    headers = {"Cookie": "; ".join(f"{k}={v}" for k, v in jar.items())}
                    page = f"{parts.scheme}://{parts.netloc}{location.split('#')[0]}"
                    async with client.get(page, headers=headers) as answer:
                        return answer.status, await answer.text()

            # in a thread of its own: a browser test before it on this worker may hold a loop
            status, text = run(lambda: asyncio.wait_for(body(), WAIT_S))
            assert status == 200 and "token ok" in text
            deadline = time.monotonic() + WAIT_S  # every half-open one is closed by the server
            closed = sum(1 for s in half_open if _closed_by_peer(s, deadline))
            assert closed == n_sockets
        finally:
            for s in half_open:
                s.close()
        log = log_path.read_text()
        assert "Too many open files" not in log and "Traceback" not in log


@pytest.mark.slow
def test_half_open_floods_from_five_addresses_leave_files_for_a_page_load(tmp_path):
    """Five addresses (127.0.0.1 to .5, five computers to the launcher), each under its
    per-address cap, together past the launcher's open-file limit (512 here): the launcher keeps
    its reserve (closing the longest-idle connections), a page load goes through, and no "Too
    many open files" is logged."""
    connections.raise_open_file_limit()  # this process holds the client ends
    open_files, per_address = 512, 110  # 550 in all, each address under PER_ADDRESS
    if resource.getrlimit(resource.RLIMIT_NOFILE)[0] < 5 * per_address + 200:
        skip_unless_ci("this process may not open 750 files")
    launcher = launcher_process(tmp_path, "--guard-idle-s", "30", open_files=open_files)
    with launcher as (url, log_path):
        parts = urllib.parse.urlsplit(url)
        held = []
        try:
            for i in range(1, 6):
                for _ in range(per_address):
                    s = socket.socket()
                    s.bind((f"127.0.0.{i}", 0))
                    s.settimeout(WAIT_S)
                    s.connect((parts.hostname, parts.port))
                    s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nX-Slow: ")
                    held.append(s)

            async def body():
                async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as client:
                    async with client.get(url, headers=NAVIGATION) as answer:
                        return answer.status, await answer.text()

            status, text = run(lambda: asyncio.wait_for(body(), WAIT_S))
            assert status == 200 and "/s/" in text
            closed = sum(1 for s in held if _closed_by_peer(s, time.monotonic() + 0.01))
            assert closed >= 5 * per_address - open_files + connections.FD_RESERVE
        finally:
            for s in held:
                s.close()
    log = log_path.read_text()
    assert "Too many open files" not in log and "Traceback" not in log
    assert "open files near the limit" in log


def test_failed_accepts_log_one_line_a_second_without_a_traceback(caplog):
    now = [0.0]
    accepts = connections._AcceptErrors(
        connections.ShortLog(logging.getLogger("asyncio"), 1, 1.0, clock=lambda: now[0])
    )
    logger = logging.getLogger("asyncio")
    # this filter alone: a launcher served in this process (the tests above) installed the
    # process's own one (on the real clock), which would thin these records again
    installed, logger.filters = logger.filters, []
    logger.addFilter(accepts)
    error = OSError(24, "Too many open files")
    try:
        with caplog.at_level(logging.WARNING, logger="asyncio"):
            for step in range(300):  # 3 s of retries, 100 a second
                now[0] = step / 100
                try:
                    raise error
                except OSError:
                    logger.error("socket.accept() out of system resource", exc_info=True)
            logger.error("another asyncio error")
    finally:
        logger.filters = installed
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0] == "could not accept a connection (Too many open files)"
    assert (
        lines[1:3]
        == ["could not accept a connection (Too many open files) (99 more like it not logged)"] * 2
    )
    assert lines[3:] == ["another asyncio error"]
    assert not any(r.exc_info for r in caplog.records[:3])


def _closed_by_peer(s: socket.socket, deadline: float) -> bool:
    try:
        s.settimeout(max(0.01, deadline - time.monotonic()))
        return s.recv(1024) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def test_a_malformed_request_logs_one_short_line_without_the_token(tmp_path):
    with launcher_process(tmp_path) as (url, log_path):
        parts = urllib.parse.urlsplit(url)
        token = urllib.parse.parse_qs(parts.query)["token"][0]
        requests = [
            f"GET /?token={token} HTTP/1.1\r\nHost: x\r\nContent-Length: nope\r\n\r\n",
            f"GET /?token={token}\x01 HTTP/1.1\r\nHost: x\r\n\r\n",
            f"GET /?token={token} HTTP/1.1\r\nHost: x\r\nBad Header\r\n\r\n",
        ]
        for request in requests:
            with socket.create_connection((parts.hostname, parts.port), timeout=WAIT_S) as s:
                s.sendall(request.encode())
                s.settimeout(WAIT_S)
                assert s.recv(1024).split(b"\r\n")[0].endswith(b" 400 Bad Request")
        with socket.create_connection((parts.hostname, parts.port), timeout=WAIT_S) as s:
            s.sendall(b"GET /?token=wrong HTTP/1.1\r\nHost: x\r\n\r\n")  # refused: one line
            assert s.recv(1024).startswith(b"HTTP/1.1 403")
    lines = log_path.read_text().splitlines()
    assert token not in "\n".join(lines) and "Traceback" not in "\n".join(lines)
    malformed = [line for line in lines if "malformed" in line]
    assert len(malformed) == len(requests), lines
    assert any("without the token" in line for line in lines) and len(lines) <= len(requests) + 1


def test_sessions_are_forked_by_default_on_linux_and_processes_of_their_own_on_request():
    import app.main as app_main

    assert app_main.parse_args([]).fork_sessions == sys.platform.startswith("linux")
    assert app_main.parse_args(["--fork-sessions"]).fork_sessions
    assert not app_main.parse_args(["--process-sessions"]).fork_sessions
    with pytest.raises(SystemExit):  # one or the other
        app_main.parse_args(["--fork-sessions", "--process-sessions"])


def test_lmapd_app_passes_the_session_and_proxy_options_on(monkeypatch):
    import app.main as app_main
    from simcore import cli

    seen = []
    monkeypatch.setattr(app_main, "main", lambda argv: seen.append(argv) or 0)
    argv = ["app", "--input-idle-min", "5", "--max-age-h", "2", "--frame-memory-mb", "800"]
    argv += ["--frames-in-flight-mb", "3000"]
    argv += ["--public-url", "https://a.example", "--public-url", "https://b.example:8443"]
    assert cli.main([*argv, "--fork-sessions"]) == 0
    given = app_main.parse_args(seen[0])
    assert given.fork_sessions
    assert (given.input_idle_min, given.max_age_h, given.frame_memory_mb) == (5, 2, 800)
    assert given.frames_in_flight_mb == 3000
    assert given.public_url == ["https://a.example", "https://b.example:8443"]


def _options(parser) -> set[str]:
    return {
        flag
        for action in parser._actions  # argparse keeps no public list of its options
        if action.help != argparse.SUPPRESS
        for flag in action.option_strings
        if flag.startswith("--")
    }


def test_lmapd_app_python_m_app_and_the_serving_docs_name_the_same_flags():
    import app.main as app_main
    from simcore.cli import app as cli_app

    sub = argparse.ArgumentParser().add_subparsers()
    lmapd_app = _options(cli_app.add_parser(sub))
    python_m_app = set()
    original = argparse.ArgumentParser.parse_args
    try:  # the parser app.main builds, read as it parses
        argparse.ArgumentParser.parse_args = lambda self, argv=None: (
            python_m_app.update(_options(self)) or original(self, [])
        )
        app_main.parse_args([])
    finally:
        argparse.ArgumentParser.parse_args = original
    assert lmapd_app == python_m_app, lmapd_app ^ python_m_app
    root = Path(__file__).resolve().parents[2]
    text = " ".join((root / "docs" / name).read_text() for name in ("serving.md", "app.md"))
    named = set(re.findall(r"`(?:lmapd app [^`]*?)?(--[a-z][a-z-]+)", text))
    others = {"--set", "--moved", "--no-browser-settle", "--vs-no-preview"}  # other commands'
    assert named - others <= lmapd_app, (named - others) - lmapd_app


def test_refusals_are_logged_a_few_a_window_and_the_held_back_ones_counted(caplog):
    import logging

    now = [0.0]
    short = connections.ShortLog(
        logging.getLogger("lmapd.test"), per_window=3, window_s=10, clock=lambda: now[0]
    )
    with caplog.at_level(logging.WARNING, logger="lmapd.test"):
        logged = [short.warning("token", "refused %d", i) for i in range(100)]
        assert logged == [True] * 3 + [False] * 97
        assert short.warning("origin", "another kind") is True  # each kind its own window
        now[0] = 10.0
        assert short.warning("token", "refused %d", 100) is True
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 5 and lines[-1] == "refused 100 (97 more like it not logged)"


# Processes sharing one unbuffered stdout pipe print many long lines at once, as the zygote and
# the sessions it forks do at a class's start (they print how each can be reached).
SHARED_PIPE_WRITERS = """
import os, sys
from app.server.children import say
n_procs, n_lines = int(sys.argv[1]), int(sys.argv[2])
for k in range(n_procs):
    if os.fork() == 0:
        for i in range(n_lines):
            say(f"writer {k} line {i} " + "x" * 200 + " end")
        os._exit(0)
for _ in range(n_procs):
    os.wait()
"""


def test_processes_sharing_a_pipe_print_whole_lines():
    """app.server.children.say writes a line and its newline at once: ``print`` under
    PYTHONUNBUFFERED (as the launcher runs the zygote) writes them apart, so lines of processes
    printing together merged and the launcher, missing a session's line, waited 120 s for it."""
    require_fork()
    n_procs, n_lines = 6, 400
    done = subprocess.run(
        [sys.executable, "-c", SHARED_PIPE_WRITERS, str(n_procs), str(n_lines)],
        cwd=Path(__file__).resolve().parents[2],
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    lines = done.stdout.splitlines()
    whole = re.compile(r"^writer (\d+) line (\d+) x{200} end$")
    broken = [line for line in lines if not whole.match(line)]
    assert not broken, broken[:3]
    assert len(lines) == n_procs * n_lines


MALFORMED = [  # each sent alone on a fresh connection, the launcher's token in its request line
    "GET /?token={t} HTTP/1.1\r\nHost: x\r\nContent-Length: nope\r\n\r\n",
    "GET /?token={t}\x01 HTTP/1.1\r\nHost: x\r\n\r\n",
    "GET /?token={t} HTTP/1.1\r\nHost: x\r\nBad Header\r\n\r\n",
    "G@T /?token={t} HTTP/1.1\r\nHost: x\r\n\r\n",
    "GET /?token={t} HTTP/9.9\r\nHost: x\r\n\r\n",
    "GET /?token={t} HTTP/1.1\r\nHost: x\r\nX-Long: " + "a" * 70_000 + "\r\n\r\n",
    "POST /?token={t} HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
    "POST /?token={t} HTTP/1.1\r\nHost: x\r\nContent-Length: 3\r\nContent-Length: 4\r\n\r\nabc",
    "GET /?token={t} HTTP/1.1\r\nHost: x\r\nX-Nul: a\x00b\r\n\r\n",
    "GET /?token={t}%ff%fe HTTP/1.1\r\nHost: x\r\n\r\n",
    "GET /ws?token={t} HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: short\r\n\r\n",
    "GET /?token={t} HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: gzip, chunked, x\r\n\r\n",
]


def _listening_port(pid: int) -> int:
    ports = [
        c.laddr.port for c in psutil.Process(pid).net_connections("tcp") if c.status == "LISTEN"
    ]
    assert len(ports) == 1, ports
    return ports[0]


@pytest.mark.slow
def test_a_sessions_own_port_refuses_malformed_requests_and_sockets_in_one_line_each(tmp_path):
    """The 12 malformed requests, and a websocket and a page without the session's secret,
    straight to a forked session's loopback port: each refused, one short line each at most,
    never a traceback or the launcher's token."""
    require_fork()
    options = ("--max-sessions", "1", "--no-spare")
    log_path = tmp_path / "server.log"
    with app_process(log_path=log_path, sessions=True, app_args=options) as running:

        async def body():
            async with aiohttp.ClientSession() as client:
                url = running.url + "&pixels=32"
                async with client.get(url, headers=NAVIGATION, allow_redirects=False) as answer:
                    assert answer.status == 200
                    await answer.text()
                session = max(_descendants(running.pid), key=lambda p: p.create_time())
                port = _listening_port(session.pid)
                base = f"http://127.0.0.1:{port}"
                page = (await get(client, f"{base}/?token={running.token}"))[0]
                try:
                    await client.ws_connect(f"ws://127.0.0.1:{port}/ws", headers={"Origin": base})
                    socket_status = 101
                except aiohttp.WSServerHandshakeError as exc:
                    socket_status = exc.status
                return port, page, socket_status

        n_lines_before = len(log_path.read_text().splitlines())
        port, page_status, socket_status = run(body)
        assert (page_status, socket_status) == (403, 403)
        for request in MALFORMED:
            with socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) as s:
                s.sendall(request.format(t=running.token).encode("latin-1"))
                s.settimeout(WAIT_S)
                with contextlib.suppress(ConnectionResetError):
                    assert s.recv(1024).split(b" ")[1] in (b"400", b"403", b"404", b"405", b"413")
        time.sleep(0.5)  # the last lines reach the log
    lines = log_path.read_text().splitlines()[n_lines_before:]
    text = "\n".join(lines)
    assert running.token not in text and "Traceback" not in text, text[-3000:]
    assert len(lines) <= len(MALFORMED) + 2, text[-3000:]


@pytest.mark.slow
def test_a_session_whose_input_changes_nothing_ends_at_its_input_idle_time(tmp_path):
    """Two forked sessions whose pages send something every half second, with a 6 s input idle
    time: one sends only what changes nothing (its pitch again, a trigger with no effect, a
    state read), and ends; the other moves its pitch, and stays."""
    require_fork()
    options = ("--max-sessions", "2", "--no-spare", "--input-idle-min", "0.1")
    log_path = tmp_path / "server.log"
    with app_process(log_path=log_path, sessions=True, app_args=options) as running:

        async def open_page(client) -> Client:
            url = running.url + "&pixels=32"
            async with client.get(url, headers=NAVIGATION, allow_redirects=False) as answer:
                jar = {k: m.value for k, m in answer.cookies.items()}
                path = json.loads(MOVE.search(await answer.text())[1]).split("?")[0]
            ws = await client.ws_connect(
                f"ws://127.0.0.1:{running.port}{path}ws",
                headers={
                    "Origin": running.origin,
                    "Cookie": "; ".join(f"{k}={v}" for k, v in jar.items()),
                },
                max_msg_size=0,
            )
            page = Client(ws)
            assert "result" in await page.hello()
            return page

        async def body():
            async with aiohttp.ClientSession() as client:
                started = time.monotonic()  # before the session starts
                idle, busy = await open_page(client), await open_page(client)
                opened = time.monotonic()  # starting them took what the machine's load says
                for step in range(int(WAIT_S * 2)):
                    await asyncio.sleep(0.5)
                    try:
                        await idle.set_state(pitch_deg=0)  # the value it holds
                        await idle.call("trame.trigger", ["unpin_frame", [], {}])  # none pinned
                        await idle.call("trame.state.get")
                    except ConnectionError as exc:
                        ended_s, why = time.monotonic() - started, str(exc)
                        after_open_s = time.monotonic() - opened
                        break
                    await busy.set_state(pitch_deg=1 + step % 2)
                else:
                    raise AssertionError("the unused session did not end")
                alive = "result" in await busy.call("trame.state.get")
                await busy.ws.close()
                return ended_s, after_open_s, why, alive

        ended_s, after_open_s, why, alive = run(body)
        # not before its idle time (counted from before it started), and within the idle time, the
        # reaper's round and a margin of its page's opening (the sessions' start is not timed)
        assert ended_s >= 6 and after_open_s < 6 + 10, (ended_s, after_open_s)
        assert str(lau.SESSION_ENDED) in why and alive
