"""What the launcher reads off a request, and the addresses and cookie names it makes: which
session a path names (``SESSION_ID``; the ids it makes, ``new_session_id``) and whether the rest
of it stays inside (``safe_rest``), whether it is trame's question to a session manager
(``is_session_manager_probe``),
whether a request to the door is a tab's navigation (``navigation_problem``), the names of a
session's and a browser's cookies, and the launcher's root with a request's settings."""

from __future__ import annotations

import ipaddress
import re
import secrets
from urllib.parse import quote

from aiohttp import web

from app.server import index_page, security

CLIENT_ID = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
# any id-like segment is read as a session's (an unknown one gets the "No such session" page);
# the ids the launcher makes are lowercase hex (new_session_id)
SESSION_ID = re.compile(r"^/s/(?P<id>[A-Za-z0-9_-]{1,64})(?P<rest>/.*)?$")
SESSION_ID_BYTES = 16  # 128 bits of entropy


def new_session_id() -> str:
    """A new session's id: ``SESSION_ID_BYTES`` random bytes as lowercase hex. Lowercase because
    trame's client lowercases the whole ``sessionURL`` it is given (``/s/<id>/ws``) before it
    connects: a mixed-case id would send the websocket to a session that does not exist."""
    return secrets.token_hex(SESSION_ID_BYTES)


def is_session_manager_probe(method: str, rest: str | None) -> bool:
    """Whether a request inside a session (``rest``, the path after ``/s/<id>``) is trame's
    question to a session manager: a POST to the ``paraview/`` beside its page."""
    return method == "POST" and rest == index_page.SESSION_MANAGER_PATH


def session_manager_answer(session_id: str) -> dict[str, str]:
    """The answer to a session page's question (wslink's launcher protocol): the session's id
    and its websocket, ``/s/<id>/ws`` of the address the page was loaded from."""
    return index_page.session_manager_answer(f"/s/{session_id}", session_id)


def navigation_problem(headers) -> str | None:
    """None if a request to the door is a browser's navigation of a tab (or comes from a client
    that sends no fetch metadata, such as an older browser or a script), else why not: a
    subresource (``<img>``, ``fetch``), a frame, or a prefetch."""
    mode = headers.get("Sec-Fetch-Mode", "").lower()
    if mode and mode != "navigate":
        return f"a {security.echo(mode)} request, not a navigation"
    dest = headers.get("Sec-Fetch-Dest", "").lower()
    if dest and dest != "document":
        return f"a request for a {security.echo(dest)}, not a page"
    purpose = " ".join(headers.get(k, "") for k in ("Sec-Purpose", "Purpose", "X-Moz")).lower()
    if "prefetch" in purpose or "prerender" in purpose or "preview" in purpose:
        return "a prefetch"
    return None


def foreign_navigation(headers) -> str | None:
    """None if a navigation to the door that carries the token only in its cookie comes from
    the app's own pages or from the browser itself (``Sec-Fetch-Site: same-origin`` or
    ``none``: the address bar, a bookmark; or no fetch metadata at all), else why not. A page on
    another port of this machine is same-site: its navigation carries the cookie (cookies ignore
    ports), and must not start a session."""
    site = headers.get("Sec-Fetch-Site", "").lower()
    if site and site not in ("same-origin", "none"):
        return f"a navigation from a {security.echo(site)} page without the token in its address"
    return None


def client_address(request: web.Request, behind_proxy: bool) -> str:
    """The address a request comes from: with a reverse proxy configured (``--public-url``),
    a request from loopback (the proxy) is the client the proxy names last in
    ``X-Forwarded-For`` (the address it appended: nginx's ``$proxy_add_x_forwarded_for``), if
    that is an IP address; otherwise the connection's own address."""
    remote = request.remote or ""
    if behind_proxy and remote in security.LOOPBACK_NAMES:
        forwarded = request.headers.get("X-Forwarded-For", "").split(",")[-1].strip()
        try:
            return str(ipaddress.ip_address(forwarded))
        except ValueError:
            pass
    return remote


def session_cookie(session_id: str) -> str:
    """The name of the cookie that binds a session to its browser."""
    return f"lmapd-session-{session_id}"


def client_cookie(request: web.Request) -> str:
    """The name of the cookie that names a browser to the launcher at the request's port."""
    return f"lmapd-client-{security._local_port(request)}"


def safe_rest(rest: str) -> bool:
    """A path inside a session that stays inside it: no dot segments, no backslashes, no
    empty segments, no control characters."""
    if not rest.startswith("/") or "\\" in rest or "//" in rest:
        return False
    if any(ord(c) < 32 or ord(c) == 127 for c in rest):
        return False
    return not any(seg in (".", "..") for seg in rest.split("/"))


def page_settings(request: web.Request) -> list[tuple[str, str]]:
    """The request's query settings a page may be given: not the token (it stays in the cookie
    or the address's fragment), nor the framework's (``index_page.FRAMEWORK_KEYS``)."""
    framework = index_page.FRAMEWORK_KEYS
    return [(k, v) for k, v in request.query.items() if k != "token" and k.lower() not in framework]


def root_link(request: web.Request) -> str:
    """The launcher's root with the request's settings (its token stays in the cookie)."""
    query = page_settings(request)
    return "/" + ("?" + query_string(query) if query else "")


def query_string(pairs) -> str:
    return "&".join(f"{quoted(k)}={quoted(v)}" for k, v in pairs)


def quoted(text: str) -> str:
    return quote(text, safe="")


def redirect(location: str) -> web.Response:
    return web.Response(status=302, headers={"Location": location, "Cache-Control": "no-store"})
