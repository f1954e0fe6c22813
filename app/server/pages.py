"""The launcher's own pages: a short message (an unknown session, a refusal) and the door's
streamed page, which says at once that the tab's session is starting and ends, once the
session listens, by moving the tab to it (or by saying that it could not start)."""

from __future__ import annotations

import html
import json
import math

from aiohttp import web


def message_page(status: int, title: str, text: str, link: str, link_text: str) -> web.Response:
    """A short HTML page (never a trace): a title, a sentence, a link."""
    body = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>lmapd-sim: {html.escape(title)}</title></head>"
        "<body style='font-family: sans-serif; max-width: 40em; margin: 3em auto'>"
        f"<h1 class='launcher-title'>{html.escape(title)}</h1>"
        f"<p class='launcher-message'>{html.escape(text)}</p>"
        f"<p><a class='launcher-link' href='{html.escape(link, quote=True)}'>"
        f"{html.escape(link_text)}</a></p></body></html>"
    )
    return web.Response(
        status=status,
        text=body,
        content_type="text/html",
        headers={"Cache-Control": "no-store"},
    )


def not_a_tab(link: str) -> web.Response:
    """The door's answer to a request that is no tab's navigation (a 403)."""
    return message_page(
        403,
        "Open this address in a browser tab",
        "A session starts only when this address is opened in a tab of its own (not "
        "from another page's image, script or prefetch).",
        link,
        "Open it here",
    )


def not_from_here(link: str) -> web.Response:
    """The door's answer to a navigation from another site's page that carries only the
    token's cookie (a 403): the link, followed from this page, starts a session."""
    return message_page(
        403,
        "Open the address that lmapd app printed",
        "Another page sent this tab here. A session starts from the printed address, or from "
        "a link of this app's own pages.",
        link,
        "Start a session",
    )


def no_session_free(problem: str, caps, link: str, frees_in_s: float | None = None) -> web.Response:
    """The door's answer when the caps leave no room for a session (a 503): ``problem`` says
    which cap; ``caps`` (app.server.caps.Caps) when a session ends (``idle_s`` after its tab
    closed, ``input_idle_s`` after its page's last input); ``frees_in_s`` how long until the
    first open session that would make room ends if nobody uses it again [s], None if unknown."""
    if frees_in_s is None:
        when = (
            "Close a tab of this app that you no longer use (its session ends "
            f"{_duration(caps.idle_s)} after), then try again"
        )
    else:
        when = (
            f"If nobody uses it again, a session frees {_within(frees_in_s)} (a session ends "
            f"after {_duration(caps.input_idle_s)} without input, or {_duration(caps.idle_s)} "
            "after its tab is closed). Close a tab of this app that you no longer use, then try "
            "again"
        )
    return message_page(
        503,
        "No session free",
        f"{problem} {when}; or ask whoever runs the server to start it with a higher "
        "--max-sessions.",
        link,
        "Try again",
    )


def _within(seconds: float) -> str:
    """``seconds`` from now as a student reads it: "within a minute", "within about 4 minutes"."""
    minutes = math.ceil(seconds / 60.0)
    return "within a minute" if minutes <= 1 else f"within about {minutes} minutes"


def _duration(seconds: float) -> str:
    """A cap's duration: "60 s", "30 minutes", "1 minute"."""
    if seconds < 120:
        return f"{seconds:g} s"
    minutes = seconds / 60.0
    return f"{minutes:.3g} minutes"


def no_such_session(link: str) -> web.Response:
    """The answer to an unknown or ended session's address (a 404)."""
    return message_page(
        404,
        "No such session",
        "This page's session has ended (it was closed, left idle, or the server "
        "restarted) or never existed. Each tab has a session of its own: start a new one.",
        link,
        "Start a new session",
    )


def foreign_session() -> web.Response:
    """The answer to a request for a session without its cookie (a 403)."""
    return message_page(
        403,
        "This session is another tab's",
        "Each session belongs to the browser tab that opened it. Open the address "
        "that `lmapd app` printed to start a session of your own.",
        "/",
        "Start a session of your own",
    )


STARTING_HEAD = (
    "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
    "<title>lmapd-sim: starting</title></head>"
    "<body style='font-family: sans-serif; max-width: 40em; margin: 3em auto'>"
)


def starting_page(ahead: int) -> str:
    """The first words a tab gets from the door, before its session's process is ready."""
    queue = f" ({ahead} more starting before it)" if ahead > 0 else ""
    return (
        f"{STARTING_HEAD}<h1 class='launcher-title'>lmapd-sim</h1>"
        f"<p class='launcher-message' role='status'>Starting your session{queue}…</p>\n"
    )


def move_html(location: str, nonce: str = "") -> str:
    """The end of the door's page: moves its tab to ``location`` (in place, so Back does not
    reopen the door). A script's navigation is same-site, so the session's SameSite=Strict
    cookie is sent even when the door was opened from a link on another site (a redirect would
    not send it). ``nonce``: the one the page's Content-Security-Policy allows its script by."""
    target = html.escape(location, quote=True)
    script = json.dumps(location).replace("<", "\\u003c")
    return (
        f"<p><a class='launcher-link' href='{target}'>Open the simulator</a></p>"
        f"<script nonce='{html.escape(nonce, quote=True)}'>window.location.replace({script});"
        "</script></body></html>"
    )


def start_failed_html(link: str) -> str:
    """The end of the door's page when the session's process did not start."""
    return (
        "<h1 class='launcher-title'>The session could not start</h1>"
        "<p class='launcher-message'>The simulator's process for this tab did not start (the "
        "server's log says why). Try again in a moment.</p>"
        f"<p><a class='launcher-link' href='{html.escape(link, quote=True)}'>Try again</a></p>"
        "</body></html>"
    )


async def finish(page: web.StreamResponse, rest: str) -> bool:
    """Send the rest of a streamed page and end it; False if the tab had gone."""
    try:
        await page.write(rest.encode())
        await page.write_eof()
    except (ConnectionError, RuntimeError):
        return False
    return True
