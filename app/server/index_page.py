"""The page's first answer: trame's ``index.html`` with the page's style sheets and scripts named
in its head (``<link rel="preload">``), so the browser fetches them while the page connects and
waits for its state. Without the hints trame's client learns their names from the state, loads
the style sheets and only then the scripts: two more round trips after the state before the page
can mount (from the state to the mount done, 0.92 s before the hints and 0.69 s with them on this
project's 2-core machine: docs/serving.md). The hints change no behaviour: the client still loads
each file itself, from the browser's cache.

The page's other first request is trame's question to a session manager (wslink's launcher
protocol): at every load, before it connects, trame's client POSTs to the ``paraview/`` beside the
page and connects to the ``sessionURL`` of a JSON answer (after a refusal it falls back to the
``ws`` beside the page, and the browser's console shows the refusal).
:func:`session_manager_answer` is that answer, here and behind the launcher (``/s/<id>/``)."""

from __future__ import annotations

import html
from pathlib import Path
from urllib.parse import urlencode

from aiohttp import web
from trame_client.module import vue3

from app.server.door import WS_PATH

INDEX_HTML = Path(vue3.www) / "index.html"
PAGE_PATHS = ("/", "/index.html")
SESSION_MANAGER_PATH = "/paraview/"  # where trame's page asks where to connect (POST)


# trame's page reads its connection settings from its own address's query too (trame-client's
# config takes every query key): a link that names one could point a student's page elsewhere or
# break it (the CSP's connect-src already refuses another host), so no page is served with them
FRAMEWORK_KEYS = frozenset(
    ("sessionurl", "sessionmanagerurl", "secret", "wsproxy", "retry", "application", "usehost")
)


def file_names(entries) -> list[str]:
    """The file names of a ``trame__styles`` or ``trame__scripts`` list (an entry may be a name
    or ``[name, options]``)."""
    return [e[0] if isinstance(e, (list, tuple)) else e for e in entries or ()]


def preload_links(state) -> list[str]:
    """One ``<link rel="preload">`` per style sheet and script of the page (``state``: the trame
    state with ``trame__styles`` and ``trame__scripts``), in the order the client loads them."""
    kinds = (("style", "trame__styles"), ("script", "trame__scripts"))
    return [
        f'<link rel="preload" as="{kind}" href="{html.escape(name)}">'
        for kind, key in kinds
        for name in file_names(state[key])
    ]


def page_html(state, index_html: Path = INDEX_HTML) -> str:
    """trame's index.html with the page's preload links at the end of its head."""
    text = index_html.read_text(encoding="utf-8")
    links = "".join(f"    {link}\n" for link in preload_links(state))
    head_end = text.index("</head>")
    return text[:head_end] + links.lstrip() + "  " + text[head_end:]


def session_manager_answer(prefix: str = "", session_id: str | None = None) -> dict[str, str]:
    """What trame's page is told when it asks where to connect (wslink's launcher protocol: the
    session's ``id`` where there is one, and its ``sessionURL``): the websocket at ``prefix`` +
    ``/ws`` of the address the page was loaded from. ``USE_HOST`` is trame's client's own word for
    that address (``window.location.host``), and it sets ``ws:`` or ``wss:`` by the page's own
    scheme, so the answer holds behind a TLS proxy too. The client lowercases the whole address
    before it connects: ``prefix`` must be lowercase (a session id is lowercase hex)."""
    if prefix != prefix.lower():
        raise ValueError(f"a websocket path trame's client would lowercase: {prefix!r}")
    answer = {"sessionURL": f"ws://USE_HOST{prefix}{WS_PATH}"}
    return answer if session_id is None else {"id": session_id, **answer}


def session_manager_response(answer: dict[str, str]) -> web.Response:
    return web.json_response(answer, headers={"Cache-Control": "no-store"})


def middleware_for(state):
    """An aiohttp middleware that answers the page (``/`` and ``/index.html``) with
    :func:`page_html`, made once, at the first request (the page's modules are all enabled by
    then), and trame's question to a session manager with :func:`session_manager_answer`.
    Installed after the door: the page needs the access token like every other file."""
    made: list[str] = []

    @web.middleware
    async def middleware(request: web.Request, handler):
        if request.method == "GET" and request.path in PAGE_PATHS:
            if any(k.lower() in FRAMEWORK_KEYS for k in request.query):  # read by the page
                kept = [(k, v) for k, v in request.query.items() if k.lower() not in FRAMEWORK_KEYS]
                location = request.path + ("?" + urlencode(kept) if kept else "")
                return web.Response(
                    status=302, headers={"Location": location, "Cache-Control": "no-store"}
                )
            if not made:
                made.append(page_html(state))
            return web.Response(text=made[0], content_type="text/html")
        if request.method == "POST" and request.path == SESSION_MANAGER_PATH:
            return session_manager_response(session_manager_answer())
        return await handler(request)

    return middleware
