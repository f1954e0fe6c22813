"""The headers every answer of the app's servers carries (the launcher's and a ``--shared``
server's), added as each response is prepared (``install``: aiohttp's ``on_response_prepare``,
so a streamed page and a proxied one get them too):

* ``Content-Security-Policy``: scripts only from the app's own origin, the inline script of
  trame's page by its hash and the door's by a nonce of its response; ``'unsafe-eval'`` because
  trame's client compiles the layout's Vue template in the browser (Vue's runtime compiler makes
  functions of it); styles from the app's origin and inline (trame's Vuetify writes its theme as
  a ``<style>`` element and its loader's style arrives through ``innerHTML``: neither can carry a
  nonce, and a style runs no script); images and workers from the app and ``data:``/``blob:``
  (the built-in targets' thumbnails, the point cloud's canvas); connections only to the app's
  own origin and its websocket (``ws://`` or ``wss://`` of the address the page was loaded from);
  ``frame-ancestors 'none'`` (no other page may frame the app), no plugins, no ``<base>`` or
  form target elsewhere;
* ``X-Frame-Options: DENY`` (the same for browsers without ``frame-ancestors``),
  ``X-Content-Type-Options: nosniff``, ``Referrer-Policy: no-referrer`` (the address carries the
  token until the page moves it after ``#``);
* ``Cache-Control: no-store`` on every HTML page (they hold or are reached with the token) unless
  the page set its own.
"""

from __future__ import annotations

import base64
import hashlib
import re
import secrets
from pathlib import Path

from aiohttp import web
from trame_client.module import vue3

NONCE = web.RequestKey("lmapd_csp_nonce", str)  # the nonce of the door's inline script, if any
_INLINE_SCRIPT = re.compile(r"<script>(.*?)</script>", re.DOTALL)


def script_hashes(html: str) -> list[str]:
    """The CSP source (``'sha256-...'``) of each inline ``<script>`` (no attributes) of a page."""
    return [
        "'sha256-" + base64.b64encode(hashlib.sha256(body.encode()).digest()).decode() + "'"
        for body in _INLINE_SCRIPT.findall(html)
    ]


TRAME_PAGE_HASHES = tuple(script_hashes((Path(vue3.www) / "index.html").read_text("utf-8")))


def new_nonce(request: web.Request) -> str:
    """A nonce for one inline script of the response to ``request`` (put in its CSP)."""
    nonce = secrets.token_urlsafe(18)
    request[NONCE] = nonce
    return nonce


def content_security_policy(host: str, nonce: str | None = None) -> str:
    """The policy of a response to a request for ``host`` (its ``Host`` header: the page's
    websocket goes to the same address)."""
    scripts = ["'self'", *TRAME_PAGE_HASHES, "'unsafe-eval'"]
    if nonce:
        scripts.append(f"'nonce-{nonce}'")
    connect = ["'self'"]
    if host and re.fullmatch(r"[A-Za-z0-9.\-\[\]:]+", host):
        connect += [f"ws://{host}", f"wss://{host}"]
    directives = {
        "default-src": ["'self'"],
        "script-src": scripts,
        "style-src": ["'self'", "'unsafe-inline'"],
        "img-src": ["'self'", "data:", "blob:"],
        "font-src": ["'self'", "data:"],
        "worker-src": ["'self'", "blob:"],
        "connect-src": connect,
        "object-src": ["'none'"],
        "base-uri": ["'self'"],
        "form-action": ["'self'"],
        "frame-ancestors": ["'none'"],
    }
    return "; ".join(f"{name} {' '.join(sources)}" for name, sources in directives.items())


async def add_headers(request: web.Request, response: web.StreamResponse) -> None:
    """aiohttp's ``on_response_prepare`` handler: the headers above on ``response``."""
    headers = response.headers
    headers["Content-Security-Policy"] = content_security_policy(
        request.headers.get("Host", ""), request.get(NONCE)
    )
    headers["X-Frame-Options"] = "DENY"
    headers["X-Content-Type-Options"] = "nosniff"
    headers["Referrer-Policy"] = "no-referrer"
    if response.content_type == "text/html" and "Cache-Control" not in headers:
        headers["Cache-Control"] = "no-store"


def install(web_app: web.Application) -> None:
    """Add the headers to every response of ``web_app``."""
    web_app.on_response_prepare.append(add_headers)
