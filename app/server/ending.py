"""When the launcher ends a session (its reaper's rules, app.server.launcher): its page closed for
``idle_s`` (a page that never connected is given ``connect_s`` at least), no input from its page
for ``input_idle_s`` even with a socket held open, or open for ``max_age_s``; and those rules run
forward: how long until a session ends if nobody uses it again (the "No session free" page tells
a student when one frees)."""

from __future__ import annotations

from collections.abc import Iterable

from app.server.caps import Caps
from app.server.children import Child


def closed_wait_s(caps: Caps, child: Child) -> float:
    """How long a session whose page has no websocket open is kept [s]."""
    return caps.idle_s if child.connected else max(caps.idle_s, caps.connect_s)


def why_end(caps: Caps, child: Child, now: float) -> str | None:
    """Why a live session should end at ``now`` (``time.monotonic()``), or None."""
    if child.n_sockets == 0:
        wait_s = closed_wait_s(caps, child)
        if now - child.idle_since_s >= wait_s:
            if child.connected:
                return f"its page closed for {wait_s:g} s"
            return f"its page did not connect within {wait_s:g} s"
    if now - child.last_input_s >= caps.input_idle_s:
        return f"no input from its page for {caps.input_idle_s:g} s"
    if now - child.opened_s >= caps.max_age_s:
        return f"open for {caps.max_age_s:g} s, the most allowed"
    return None


def ends_in_s(caps: Caps, child: Child, now: float) -> float:
    """How long after ``now`` :func:`why_end` ends a live session if its page sends nothing more
    and its websockets stay as they are [s] (0 or less: at once). An upper bound: any input puts
    it off, and a session ends itself sooner when its input changes nothing (app.main)."""
    left = [
        caps.input_idle_s - (now - child.last_input_s),
        caps.max_age_s - (now - child.opened_s),
    ]
    if child.n_sockets == 0:
        left.append(closed_wait_s(caps, child) - (now - child.idle_since_s))
    return min(left)


def frees_in_s(caps: Caps, sessions: Iterable[Child], now: float) -> float | None:
    """How long after ``now`` the first of ``sessions`` ends if none is used again [s]; None if
    there is none."""
    return min((ends_in_s(caps, child, now) for child in sessions), default=None)
