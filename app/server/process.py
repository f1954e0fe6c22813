"""The serving processes: a session's (its token on stdin, stopped when stdin closes, its address
space limited), the launcher's (``lmapd app`` without ``--shared``: app.server.launcher until
Ctrl+C or SIGTERM, and what it prints about its capacity), and the exit status of serving."""

from __future__ import annotations

import argparse
import os
import secrets
import signal
import sys
import threading
from collections.abc import Callable

import simcore
from app.server.addresses import public_lines, start_message
from app.server.children import say


def read_token_and_watch_stdin() -> str:
    """A session process's token (the first line of stdin); then stop the process (as Ctrl+C
    would) when stdin closes, so that no process outlives its launcher."""
    token = sys.stdin.readline().strip()
    if not token:
        raise ValueError("no token on stdin")

    def watch() -> None:
        while sys.stdin.readline():
            pass
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=watch, name="lmapd-stdin-watch", daemon=True).start()
    return token


HEADROOM_BYTES = 2**30  # a session's address space beyond its size at start and its frame budget


def limit_address_space(extra_bytes: int) -> int | None:
    """Limit this process's address space (``RLIMIT_AS``) to its size now plus ``extra_bytes``:
    an allocation beyond fails (MemoryError) in this process only. The limit [bytes], or None
    where it cannot be set."""
    import resource  # noqa: PLC0415  (sessions only)

    import psutil  # noqa: PLC0415

    try:
        limit = int(psutil.Process().memory_info().vms) + int(extra_bytes)
        hard = resource.getrlimit(resource.RLIMIT_AS)[1]
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (ValueError, OSError, psutil.Error):
        return None
    return limit


def interrupt(*_) -> None:
    """A signal handler that stops serving as Ctrl+C does (a session on the launcher's SIGTERM)."""
    raise KeyboardInterrupt


def run_launcher(args: argparse.Namespace) -> int:
    """Each tab its own session: the launcher (app.server.launcher) until Ctrl+C or SIGTERM."""
    import asyncio  # noqa: PLC0415  (the launcher's loop: only without --shared)

    from app.server import launcher  # noqa: PLC0415

    mib = launcher.MIB
    frames_mb = args.frames_in_flight_mb
    caps = launcher.default_caps(
        session_rss_bytes=launcher.FORKED_SESSION_BYTES
        if args.fork_sessions
        else launcher.SESSION_RSS_BYTES,
        max_sessions=args.max_sessions,
        memory_cap_bytes=None if args.memory_cap_mb is None else int(args.memory_cap_mb * mib),
        idle_s=max(0.0, args.idle_s),
        spare=not args.no_spare,
        input_idle_s=max(1.0, 60.0 * args.input_idle_min),
        max_age_s=max(1.0, 3600.0 * args.max_age_h),
        frame_limit_bytes=int(max(1.0, args.frame_memory_mb) * mib),
        frames_bytes=None if frames_mb is None else int(max(0.0, frames_mb) * mib),
    )
    try:
        scene = simcore.load_scene(args.scene)  # the sessions' scene, checked once here
        del scene
    except (simcore.SceneError, simcore.TargetError, OSError) as exc:
        print(f"lmapd app: {exc}", file=sys.stderr)
        return 2
    token = secrets.token_urlsafe(32)
    options = ("--no-preview",) if args.no_preview else ()
    options += ("--frame-memory-mb", f"{args.frame_memory_mb:g}")
    # a session ends itself after this long without input that changes its scene (the
    # launcher's own count takes any frame its page sends: a ping, the same value again)
    options += ("--input-idle-min", f"{args.input_idle_min:g}")
    if args.studies:
        options += ("--studies", os.path.abspath(args.studies))
    origins = tuple(args.public_url)
    door = launcher.Launcher(
        token,
        args.host,
        caps,
        scene=args.scene,
        options=options,
        origins=origins,
        zygote=launcher.zygote_command if args.fork_sessions else None,
    )

    def announce(port: int) -> None:
        say(
            *start_message(args.host, port, token),
            *public_lines(origins, token),
            f"lmapd-sim app: each tab its own session: at most {caps.max_sessions} at once, "
            f"{caps.memory_cap_bytes / mib:,.0f} MB for their processes, a closed page's session "
            f"ends after {caps.idle_s:g} s, one without input after "
            f"{caps.input_idle_s / 60:g} min (--shared: one scene for every tab)",
            f"lmapd-sim app: heavy frames in flight across the sessions may take "
            f"{caps.frames_bytes / mib:,.0f} MB together, by their estimates; more wait their turn "
            "(--frames-in-flight-mb)",
            class_line(caps),
        )

    return serve_until_stopped(
        lambda: asyncio.run(launcher.serve(door, args.host, args.port, announce)), args
    )


def class_line(caps) -> str:
    """What the session cap means for a class of 30."""
    from app.server import launcher  # noqa: PLC0415  (launcher mode only)

    need_gb = launcher.MAX_DEFAULT_SESSIONS * caps.session_bytes / 1e9
    if caps.max_sessions >= launcher.MAX_DEFAULT_SESSIONS:
        return f"lmapd-sim app: room for a class of {launcher.MAX_DEFAULT_SESSIONS} tabs"
    return (
        f"lmapd-sim app: room for {caps.max_sessions} tabs, not a class of "
        f"{launcher.MAX_DEFAULT_SESSIONS} (that needs about {need_gb:.0f} GB for the sessions: "
        "--memory-cap-mb and --max-sessions set it)"
    )


def serve_until_stopped(serve: Callable[[], object], args: argparse.Namespace) -> int:
    """Run ``serve()`` until Ctrl+C; the exit status (2, with one line, if it cannot listen)."""
    try:
        serve()
    except OSError as exc:  # port in use, bad host
        print(f"lmapd app: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        pass
    return 0
