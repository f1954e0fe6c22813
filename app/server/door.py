"""The HTTP side of the door (an aiohttp middleware, aiohttp 3.14): the per-launch access token
(from the tokenised address's cookie, or ``?token=``), the allowed ``Origin`` of a websocket and
the connection cap, checked before a websocket is upgraded; pages and files are served only with
the token (or its cookie) too.

Browsers always send ``Origin`` on websockets, so a websocket without one is refused: a
non-browser client (the tests) must send the served address as its ``Origin``, as a page would.
"""

from __future__ import annotations

import hmac
import logging
from urllib.parse import urlsplit

from aiohttp import web

from app.server import connections
from app.server.budget import Limits
from app.state import echo

log = logging.getLogger("app.server.security")  # the door's lines keep their logger's name

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
WILDCARD_HOSTS = ("0.0.0.0", "::", "")
WS_PATH = "/ws"
AUTHORISED = "lmapd_authorised"  # set on a websocket request the middleware let in


class Door:
    """The HTTP side: the access token, the allowed origins and the connection count."""

    def __init__(self, token: str, host: str, limits: Limits, origins: tuple[str, ...] = ()):
        self.token = token
        self.host = host.strip("[]").lower()
        self.limits = limits
        # the addresses a reverse proxy serves the app at (https://name[:port]): their pages
        # are the app's own too
        self.origins = {o for o in (normal_origin(u) for u in origins) if o}
        self.n_connections = 0
        self.n_refused = 0
        self.log = connections.ShortLog(log)  # one line per refusal, a few a second at most

    def cookie_name(self, request: web.Request) -> str:
        return f"lmapd-token-{_local_port(request)}"

    def served_securely(self, request: web.Request) -> bool:
        """Whether the browser reached this server over https: directly, or through a reverse
        proxy at one of its configured ``https://`` addresses (the request's ``Host`` names it:
        the documented proxy passes the browser's own)."""
        if request.secure:
            return True
        host = request.headers.get("Host", "")
        return bool(host) and normal_origin(f"https://{host}") in self.origins

    def cookie_attributes(self, request: web.Request, path: str = "/") -> dict:
        """The attributes of a cookie set in the answer to ``request``: HttpOnly (no script
        reads it), SameSite=Strict (no other site's page sends it), ``path`` (the token's: ``/``,
        the door's own address, which every other path of the server is under) and, where the
        page is served over https, Secure (never sent over plain http, such as a first
        ``http://`` visit before the proxy's redirect)."""
        return {
            "httponly": True,
            "samesite": "Strict",
            "path": path,
            "secure": self.served_securely(request),
        }

    def token_ok(self, request: web.Request) -> tuple[bool, bool]:
        """(authorised, from the address): the token is in the query or in our cookie."""
        query = request.query.get("token", "")
        if query and hmac.compare_digest(query.encode(), self.token.encode()):
            return True, True
        cookie = request.cookies.get(self.cookie_name(request), "")
        return bool(cookie) and hmac.compare_digest(cookie.encode(), self.token.encode()), False

    def origin_problem(self, request: web.Request) -> str | None:
        """None if the request's Origin is the served page, else why not."""
        origin = request.headers.get("Origin")
        if not origin:
            return "no Origin header"
        try:
            parts = urlsplit(origin)
            port = parts.port or {"http": 80, "https": 443}.get(parts.scheme, 0)
        except ValueError:
            return f"a malformed Origin {echo(origin)}"
        name = (parts.hostname or "").lower()
        if normal_origin(origin) in self.origins:
            return None
        if parts.scheme not in ("http", "https") or port != _local_port(request):
            return f"a foreign Origin {echo(origin)}"
        if self.host in WILDCARD_HOSTS:  # any name may reach us: the page's own (same origin)
            allowed = {(request.url.host or "").strip("[]").lower()}
        elif self.host in LOOPBACK_NAMES:
            allowed = set(LOOPBACK_NAMES)
        else:
            allowed = {self.host}
        return None if name in allowed else f"a foreign Origin {echo(origin)}"

    @web.middleware
    async def middleware(self, request: web.Request, handler):
        authorised, from_address = self.token_ok(request)
        if request.path == WS_PATH or request.headers.get("Upgrade", "").lower() == "websocket":
            return await self._websocket(request, handler, authorised)
        if not authorised:
            self.n_refused += 1
            self.log.warning("token", "refused a request without the token from %s", request.remote)
            return web.Response(
                status=403,
                text="Forbidden: open the address that `lmapd app` printed (it carries the "
                "access token).\n",
            )
        response = await handler(request)
        if from_address:
            response.set_cookie(
                self.cookie_name(request), self.token, **self.cookie_attributes(request)
            )
        return response

    async def _websocket(self, request: web.Request, handler, authorised: bool):
        problem = self.origin_problem(request)
        if problem is None and not authorised:
            problem = "no valid access token"
        if problem is None and self.n_connections >= self.limits.max_connections:
            self.log.warning(
                "cap", "refused a websocket: %d connections already", self.n_connections
            )
            self.n_refused += 1
            return web.Response(status=503, text="Too many connections\n")
        if problem is not None:
            self.log.warning(
                "websocket", "refused a websocket from %s: %s", request.remote, problem
            )
            self.n_refused += 1
            return web.Response(status=403, text="Forbidden\n")
        request[AUTHORISED] = True
        self.n_connections += 1
        try:
            return await handler(request)
        finally:
            self.n_connections -= 1


def normal_origin(url: str) -> str | None:
    """``scheme://host:port`` of an http(s) address (the port written out), or None."""
    try:
        parts = urlsplit(url.strip())
        port = parts.port or {"http": 80, "https": 443}.get(parts.scheme, 0)
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return None
    return f"{parts.scheme}://{parts.hostname.lower()}:{port}"


def _local_port(request: web.Request) -> int:
    sockname = request.transport.get_extra_info("sockname") if request.transport else None
    return int(sockname[1]) if sockname else 0
