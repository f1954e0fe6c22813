"""A piece of work in a forked child process, its answer read back: for tests of what survives
a fork (the app's sessions are forked from a preloaded parent, app.server.zygote)."""

from __future__ import annotations

import json
import os
import select
import signal
from collections.abc import Callable
from typing import Any

from support.ci import skip_unless_ci


def require_fork() -> None:
    """Skip where the system cannot fork (not POSIX: the sessions are not forked there either);
    a failure in CI."""
    if not hasattr(os, "fork"):
        skip_unless_ci("fork is POSIX's: this system starts processes afresh")


def in_forked_child(work: Callable[[], Any], wait_s: float = 60.0) -> Any:
    """Fork, run ``work()`` in the child and return its answer (JSON-able); None if the child
    gave none within ``wait_s`` (it hung: it is killed) or failed. The child never returns into
    the caller (it leaves with ``os._exit``, never through pytest). Skipped where the system
    cannot fork (:func:`require_fork`)."""
    require_fork()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child
        try:
            os.close(read)
            os.write(write, json.dumps(work()).encode())
        finally:
            os._exit(0)
    os.close(write)
    with os.fdopen(read) as pipe:
        ready = select.select([pipe], [], [], wait_s)[0]  # a hung child writes nothing
        text = pipe.read() if ready else ""
    if not text:
        os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return json.loads(text) if text else None
