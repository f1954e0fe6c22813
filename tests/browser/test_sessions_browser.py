"""Each tab its own scene (``lmapd app`` without ``--shared``: app.server.launcher) in a real
Chromium: two tabs keep their own scenes and a reload opens a new one, the address bar shows neither
the token nor the session, a link made in one tab opens a new session with the same scene, a bad
session id gets the message page, and over the cap the 503 page says how many are open and when
one frees."""

from __future__ import annotations

import re
import urllib.parse

import pytest
from support.launch import JS_STATE, app_server, set_field, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

SMALL = "&pixels=64"  # a small array: the tests are about sessions, not frames


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def point_count(page) -> int:
    return int(page.locator(".point-count").inner_text().split()[0].replace(",", ""))


def session_of(page) -> str:
    """The session id of the page's address as it was loaded (``/s/<id>/...``); the address bar
    shows only the launcher's root once the page has read its settings."""
    loaded = page.evaluate("() => performance.getEntriesByType('navigation')[0].name")
    parts = urllib.parse.urlsplit(loaded).path.split("/")
    assert parts[1] == "s", loaded
    return parts[2]


def moved(url: str) -> bool:
    """The tab has left the door (``/?token=...``) for its session."""
    return "/s/" in url or "token" not in url


# The door's page streams: it says at once that the session is starting and ends when the
# session listens (seconds on a loaded machine, and over Playwright's 30 s for a navigation's
# "load" once in CI). Navigations to it wait for the answer to begin ("commit"); the move to the
# session is then waited for with its own limit (SESSION_START_S).
DOOR = "commit"
SESSION_START_S = 120.0


def open_tab(page, url: str, pixels: int = 64) -> None:
    page.goto(url, wait_until=DOOR)  # the door's page moves the tab to its session
    page.wait_for_url(moved, timeout=SESSION_START_S * 1000)
    wait_first_frame(page)
    page.wait_for_function("(p) => window.trame.state.get('pixels') === p", arg=pixels)
    wait_settled(page)


@pytest.fixture(scope="module")
def launcher_url(artifacts_dir):
    """A launcher (each page load its own session) with room for the sessions below (those of a
    finished test end a minute after its tabs closed)."""
    log_path = artifacts_dir / "app-server-sessions.log"
    with app_server(log_path=log_path, sessions=True, app_args=("--max-sessions", "8")) as url:
        yield url


def test_two_tabs_keep_their_own_scenes(page, launcher_url):
    other = page.context.new_page()
    try:
        open_tab(page, launcher_url + SMALL)
        open_tab(other, launcher_url + SMALL)
        assert session_of(page) != session_of(other)
        shown = urllib.parse.urlsplit(page.url)  # neither the token nor the session
        assert (shown.path, shown.query, shown.fragment) == ("/", "", ""), page.url
        before = point_count(other)
        assert state(page, "pitch_deg") == state(other, "pitch_deg") == 0
        set_field(page, "pitch_deg", 30)
        page.wait_for_function("() => window.trame.state.get('pitch_deg') === 30")
        wait_settled(page)
        wait_settled(other)
        assert state(page, "pitch_deg") == 30
        assert state(other, "pitch_deg") == 0 and point_count(other) == before
        first = session_of(other)
        other.reload(wait_until=DOOR)  # the address shown is the launcher's: a new session
        other.wait_for_url(moved, timeout=SESSION_START_S * 1000)
        wait_first_frame(other)
        wait_settled(other)
        assert session_of(other) != first and state(other, "pitch_deg") == 0
        set_field(other, "azimuth_deg", -20)
        other.wait_for_function("() => window.trame.state.get('azimuth_deg') === -20")
        wait_settled(other)
        assert state(page, "azimuth_deg") == 0 and state(page, "pitch_deg") == 30
    finally:
        other.close()


def test_a_link_made_in_one_tab_opens_a_new_session_with_the_same_scene(page, launcher_url):
    open_tab(page, launcher_url + SMALL + "&pitch_deg=25&seed=5")
    page.get_by_role("button", name="Share this scene (link)").click()
    link = page.locator(".share-link input").input_value()
    parts = urllib.parse.urlsplit(link)
    shared = dict(urllib.parse.parse_qsl(parts.query))
    assert parts.path == "/" and shared["token"] and shared["pitch_deg"] == "25"
    student = page.context.new_page()
    try:
        open_tab(student, link)
        assert session_of(student) != session_of(page)
        assert state(student, "pitch_deg") == 25 and state(student, "seed") == 5
        assert point_count(student) == point_count(page)
    finally:
        student.close()


def test_a_bad_session_id_gets_a_message_page(page, launcher_url):
    parts = urllib.parse.urlsplit(launcher_url)
    open_tab(page, launcher_url + SMALL)  # the token is then in the browser's cookie
    answer = page.goto(f"{parts.scheme}://{parts.netloc}/s/no-such-session/?pixels=32")
    assert answer.status == 404
    assert page.locator(".launcher-title").inner_text() == "No such session"
    link = page.locator(".launcher-link")
    assert link.get_attribute("href") == "/?pixels=32"
    link.click()  # a new session, with the settings of the address
    wait_first_frame(page)
    page.wait_for_function("() => window.trame.state.get('pixels') === 32")
    assert session_of(page)


def test_over_the_cap_a_503_page_says_how_many_are_open(page, artifacts_dir):
    log_path = artifacts_dir / "app-server-sessions-cap.log"
    options = ("--max-sessions", "1", "--idle-s", "1")
    with app_server(log_path=log_path, sessions=True, app_args=options) as url:
        open_tab(page, url + SMALL)
        second = page.context.new_page()
        try:
            answer = second.goto(url + SMALL, wait_until=DOOR)
            assert answer.status == 503
            message = second.locator(".launcher-message").inner_text()
            assert "1 session is open" in message and "--max-sessions" in message
            # the open tab's session ends 30 minutes (the default) after its last input
            frees = re.search(
                r"If nobody uses it again, a session frees within about (\d+) min", message
            )
            assert frees and 20 <= int(frees[1]) <= 30, message
            page.close()  # its session ends 1 s after its websocket closed: room for the next
            for _ in range(60):  # bounded; each try is a page load
                answer = second.goto(url + SMALL, wait_until=DOOR)
                if answer.status != 503:
                    break
                second.wait_for_timeout(500)
            second.wait_for_url(moved, timeout=SESSION_START_S * 1000)
            wait_first_frame(second)
            assert session_of(second)
        finally:
            second.close()


def test_a_session_ended_for_want_of_input_says_so_on_its_page(page, artifacts_dir):
    """A page left without input past --input-idle-min keeps its socket but loses its session
    (a held socket cannot keep a session alive); the page says so."""
    log_path = artifacts_dir / "app-server-sessions-idle.log"
    options = ("--max-sessions", "2", "--no-spare", "--input-idle-min", "0.1")  # 6 s
    with app_server(log_path=log_path, sessions=True, app_args=options) as url:
        page.goto(url + SMALL, wait_until=DOOR)
        page.wait_for_url(moved, timeout=SESSION_START_S * 1000)
        note = page.locator(".session-ended")
        note.wait_for(timeout=120_000)
        assert note.inner_text() == "Session ended: reload for a new one."
