"""The app's websocket door: who may connect, what they may send, how much memory they may hold.

Checked against trame-server 4.1.0, wslink 2.6.0 and aiohttp 3.14; every hook into those libraries
is in this module's parts (and the state synchronisation in ``app.server.sync``), by concern:

* :mod:`app.server.door`: an aiohttp middleware (added through trame's ``on_server_bind`` hook,
  before the server starts) refuses, before the websocket is upgraded: a foreign or missing
  ``Origin`` (browsers always send one on websockets), a missing or wrong per-launch access token
  (from the cookie that the tokenised address sets, or ``?token=`` on ``/ws``), and connections
  over the cap. Pages and files are served only with the token (or its cookie) too;
* :mod:`app.server.guard`: a wslink ``LinkProtocol`` (registered through
  ``Server.add_protocol_to_configure``) decides the wslink hello (``validateToken``: only
  connections let in by the middleware), gives each connection a :class:`BoundedUnChunker` and
  wraps four methods of wslink's handler instance: text messages and refused chunks close the
  connection; each call is checked against an allow-list before wslink dispatches it; errors sent
  to a client are one short line (the trace stays in the server log); answers wait for the state
  pushes (next);
* :mod:`app.server.budget`: the caps (:class:`Limits`) and the reassembly of chunked messages
  within them (one memory budget per connection and one in total, a time-out for partial
  messages);
* :mod:`app.server.client_values`: the screens of the values a page may write;
* the state pushes (``app.server.sync``) are sent at once, in order, and the answer to a page's
  state update or trigger waits for the pushes to that page made before it, the state the call
  caused (wslink's publish would send that on a later turn of the event loop, after the answer:
  :meth:`Guard.send_state`).

Here: :func:`install`, which puts them on a trame server, and the names of those parts, re-exported
(``security.Door``, ``security.Limits``, ``security.scalar``, ...).
"""

from __future__ import annotations

from collections.abc import Mapping

from app.server import connections, headers, index_page
from app.server.budget import (
    MAX_MESSAGE_BYTES,
    MIB,
    WS_CHUNK_BYTES,
    BoundedUnChunker,
    Limits,
    PendingBudget,
    Refused,
)
from app.server.client_values import (
    MAX_SCALAR_CHARS,
    Screen,
    boolean,
    cleared,
    file_upload,
    mapping_of_names,
    scalar,
)
from app.server.door import (
    AUTHORISED,
    LOOPBACK_NAMES,
    WILDCARD_HOSTS,
    WS_PATH,
    Door,
    normal_origin,
)
from app.server.door import _local_port as _local_port  # the launcher names its sessions by it
from app.server.guard import (
    ANSWERED_AFTER_PUSHES,
    MAX_CHANGES,
    MAX_TEXT,
    MAX_TRIGGER_NAME,
    REFUSED,
    SHORT_ERRORS,
    STATE_PUSH_ID,
    Guard,
)
from app.server.sync import ClientStateSync
from app.state import echo as echo  # the launcher's refusals quote a client's values by it

__all__ = [
    "ANSWERED_AFTER_PUSHES",
    "AUTHORISED",
    "LOOPBACK_NAMES",
    "MAX_CHANGES",
    "MAX_MESSAGE_BYTES",
    "MAX_SCALAR_CHARS",
    "MAX_TEXT",
    "MAX_TRIGGER_NAME",
    "MIB",
    "REFUSED",
    "SHORT_ERRORS",
    "STATE_PUSH_ID",
    "WILDCARD_HOSTS",
    "WS_CHUNK_BYTES",
    "WS_PATH",
    "BoundedUnChunker",
    "Door",
    "Guard",
    "Limits",
    "PendingBudget",
    "Refused",
    "Screen",
    "boolean",
    "cleared",
    "file_upload",
    "install",
    "mapping_of_names",
    "normal_origin",
    "scalar",
]


def install(
    server,
    *,
    token: str,
    host: str,
    client_keys: Mapping[str, Screen],
    limits: Limits | None = None,
    origins: tuple[str, ...] = (),
):
    """Lock ``server`` (a trame Server, before it starts) to its own page (and the pages of
    ``origins``, a reverse proxy's addresses): returns the guard and the door (their counters
    are read by tests)."""
    limits = limits or Limits()
    sync = ClientStateSync(server.state, client_keys)
    guard = Guard(server, sync, limits)
    door = Door(token, host, limits, origins)

    def configure(core_protocol) -> None:
        core_protocol.registerLinkProtocol(guard)
        sync.attach(core_protocol)

    def bind(web_app) -> None:
        connections.guard_app(web_app.app)  # idle and partial connections closed
        headers.install(web_app.app)  # CSP, nosniff, no referrer, no-store pages
        web_app.app.middlewares.append(door.middleware)
        # after the door: the page itself needs the token too
        web_app.app.middlewares.append(index_page.middleware_for(server.state))

    connections.guard_wslink_sites()
    server.add_protocol_to_configure(configure)
    server.controller.on_server_bind.add(bind)
    server.options["ws_max_msg_size"] = WS_CHUNK_BYTES
    return guard, door
