"""The launcher's limits (``Caps``) and the memory figures its default session cap is derived from:
what one session process holds, started afresh or forked from the preloaded parent."""

from __future__ import annotations

import dataclasses

import psutil

MIB = 2**20
# One session process's resident memory after its first frame with the paper scene at 256 x 256
# (354-370 MB, median 357 MB, with its preview's stages, scripts/bench_sessions.py, 2026-11-25);
# the default session cap is derived from it.
SESSION_RSS_BYTES = 370 * MIB
# A session forked from the zygote (the default on Linux): 30 such sessions and their parent held
# 2,309 MB of proportional set size after each computed a 256 x 256 frame of its own (77 MB a
# session, the parent's share included; 7,112 MB as processes of their own; they share the
# parent's app, target stage and first frame: scripts/bench_session_memory.py --moved,
# 2026-11-26); counted at 128 MB, room for a larger frame's caches.
FORKED_SESSION_BYTES = 128 * MIB
MAX_DEFAULT_SESSIONS = 30  # a class
MEMORY_SHARE = 0.75  # of the memory available at start, for the children together


@dataclasses.dataclass(frozen=True)
class Caps:
    """The launcher's limits.

    max_sessions : sessions open at once; the warm spare counts too (at most this many processes)
    memory_cap_bytes : the children's total memory that no new session may take beyond [bytes]
    idle_s : a session whose websocket has been closed this long is stopped [s]
    connect_s : a new session whose page has not opened its websocket yet is given at least this
        long (its page loads its files first: seconds on a loaded machine; a 1 s idle_s had
        ended sessions whose pages were still loading) [s]
    spare : keep one process started ahead
    start_timeout_s : a process that has not listened after this long is given up [s]
    input_idle_s : a session whose page has sent nothing this long is stopped, socket or not [s]
    max_age_s : a session this old is stopped [s]
    per_client : sessions of one browser (its client cookie); a new one ends its oldest
    per_address : sessions of one client address [0: no limit]: loopback is not capped while
        the launcher listens on loopback only; behind a configured reverse proxy the address is
        the one the proxy forwards (``app.server.routes.client_address``)
    sockets_per_session : websockets open at once on one session
    session_bytes : what a session is counted at in the memory cap until it measures more [bytes]
    frames_bytes : what the heavy frames in flight across the sessions may take together, by
        their estimates (app.server.frame_memory) [bytes; None: no such budget]
    """

    max_sessions: int
    memory_cap_bytes: int
    idle_s: float = 60.0
    spare: bool = True
    connect_s: float = 30.0
    start_timeout_s: float = 120.0
    input_idle_s: float = 1800.0
    max_age_s: float = 8 * 3600.0
    per_client: int = 3
    per_address: int = 6
    sockets_per_session: int = 4
    session_bytes: int = SESSION_RSS_BYTES
    frames_bytes: int | None = None


def default_caps(
    available_bytes: int | None = None,
    session_rss_bytes: int = SESSION_RSS_BYTES,
    max_sessions: int | None = None,
    memory_cap_bytes: int | None = None,
    idle_s: float = 60.0,
    spare: bool = True,
    frame_limit_bytes: int | None = None,
    **more,
) -> Caps:
    """The caps for this machine: the children may use ``MEMORY_SHARE`` of the memory available
    now [bytes], and as many sessions as fit in it at ``session_rss_bytes`` each (at least 1, at
    most ``MAX_DEFAULT_SESSIONS``); explicit values win; ``more``: the other fields of Caps.
    With ``frame_limit_bytes`` (one session's largest frame) and no ``frames_bytes`` in
    ``more``, the frames in flight get what the memory cap leaves beside the sessions at rest
    (default_budget_bytes)."""
    if available_bytes is None:
        available_bytes = int(psutil.virtual_memory().available)
    if memory_cap_bytes is None:
        memory_cap_bytes = int(MEMORY_SHARE * available_bytes)
    if max_sessions is None:
        fits = memory_cap_bytes // max(1, session_rss_bytes)
        max_sessions = int(min(MAX_DEFAULT_SESSIONS, max(1, fits)))
    if frame_limit_bytes is not None and more.get("frames_bytes") is None:
        baseline = max(1, max_sessions) * session_rss_bytes
        more["frames_bytes"] = default_budget_bytes(memory_cap_bytes, baseline, frame_limit_bytes)
    return Caps(
        max(1, max_sessions),
        max(0, memory_cap_bytes),
        idle_s,
        spare,
        session_bytes=session_rss_bytes,
        **more,
    )


def default_budget_bytes(memory_cap_bytes: int, baseline_bytes: int, frame_bytes: int) -> int:
    """The default budget of the frames in flight across sessions (app.server.frame_memory): the
    sessions' memory cap less their resting size (``baseline_bytes``: the most sessions at what
    the cap counts each), and at least one frame at the per-session limit ``frame_bytes`` (one
    heaviest frame at a time, as a single session always could run)."""
    return int(max(frame_bytes, memory_cap_bytes - baseline_bytes))
