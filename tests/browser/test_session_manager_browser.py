"""trame's question to a session manager in a real Chromium: at every load trame's page POSTs to
the ``paraview/`` beside it (wslink's launcher protocol) and connects to the ``sessionURL`` it is
told, lowercased (app.server.index_page, app.server.routes). Behind the launcher and in
``--shared`` mode the question is answered (no 405 in the console), the page's one websocket goes
where the answer says (its own session's, behind the launcher), and the page draws its first
frame."""

from __future__ import annotations

import urllib.parse

import pytest
from support.launch import app_server, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

SMALL = "&pixels=32"
SESSION_START_S = 120.0


def watched(page) -> dict[str, list]:
    """What the page does from now on: its console messages, its questions to a session manager
    (method, status) and the addresses of its websockets."""
    seen: dict[str, list] = {"console": [], "probes": [], "sockets": []}
    page.on("console", lambda m: seen["console"].append(f"{m.type}: {m.text}"))

    def answered(response) -> None:
        if urllib.parse.urlsplit(response.url).path.endswith("/paraview/"):
            seen["probes"].append((response.request.method, response.status))

    page.on("response", answered)
    page.on("websocket", lambda ws: seen["sockets"].append(ws.url))
    return seen


def loaded_path(page) -> str:
    """The path of the page's address as it was loaded (the address bar shows less later)."""
    loaded = page.evaluate("() => performance.getEntriesByType('navigation')[0].name")
    return urllib.parse.urlsplit(loaded).path


def assert_answered_and_connected(page, seen: dict[str, list], websocket: str) -> None:
    wait_first_frame(page)
    wait_settled(page)
    assert seen["probes"] == [("POST", 200)], seen
    assert seen["sockets"] == [websocket], seen
    errors = [m for m in seen["console"] if m.startswith("error")]
    assert not [m for m in errors if "405" in m or "paraview" in m], errors
    assert page.evaluate("() => window.trame.client.isConnected()")
    assert page.evaluate("() => window.lmapdErrors || []") == []


def test_behind_the_launcher_the_page_connects_where_the_launcher_says(page, artifacts_dir):
    log_path = artifacts_dir / "app-server-session-manager.log"
    with app_server(log_path=log_path, sessions=True, app_args=("--max-sessions", "2")) as url:
        seen = watched(page)
        page.goto(url + SMALL, wait_until="commit")  # the door's page moves the tab
        page.wait_for_url(lambda u: "token" not in u, timeout=SESSION_START_S * 1000)
        parts = urllib.parse.urlsplit(url)
        path = loaded_path(page)
        assert path.startswith("/s/") and path == path.lower(), path
        assert_answered_and_connected(page, seen, f"ws://{parts.netloc}{path}ws")


def test_in_shared_mode_the_page_connects_where_its_server_says(page, app_url):
    seen = watched(page)
    page.goto(app_url + SMALL)
    parts = urllib.parse.urlsplit(app_url)
    assert_answered_and_connected(page, seen, f"ws://{parts.netloc}/ws")
