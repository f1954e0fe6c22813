"""The sessions' processes, seen from the launcher: ``Child`` (one app process, its port, its
private token and, once it serves a session, that session's owner), the commands that start one
(``child_command``) or the preloaded parent that forks them (``zygote_command``), starting one and
waiting until it listens (``start_process``), stopping one, and ``Zygote``, the launcher's end of
app.server.zygote: the lines it prints (``ZYGOTE_READY``, ``token_digest``) are defined here, in a
module that imports no framework, so that the zygote can read them before its version check.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import hashlib
import os
import re
import secrets
import signal
import sys
import time
from collections.abc import Callable
from typing import Protocol

import psutil

from app.server.caps import Caps

FORKED_LINE = re.compile(r"^lmapd-sim zygote: forked (?P<pid>\d+) for (?P<digest>[0-9a-f]{16})$")
SESSION_LINE = re.compile(
    r"^lmapd-sim app: http://127\.0\.0\.1:(?P<port>\d+)/\?token=(?P<token>[A-Za-z0-9_-]+)"
)
ADDRESS_LINE = re.compile(r"^lmapd-sim app: http://127\.0\.0\.1:(?P<port>\d+)/")
CHILD_HOST = "127.0.0.1"
ZYGOTE_READY = "lmapd-sim zygote: ready"  # what app.server.zygote prints once it can fork


def say(*lines: str) -> None:
    """Print each line to stdout in one write. The zygote and the sessions it forks share one
    pipe to the launcher, and ``print`` writes a line and its newline apart when stdout is
    unbuffered (``PYTHONUNBUFFERED``, as the launcher starts the zygote): two processes printing
    at once then merged their lines, and the launcher, missing a line, waited ``start_timeout_s``
    (120 s) for a session that was listening. A write of a line to a pipe is never split
    (up to ``PIPE_BUF``, 4 KB on Linux)."""
    for line in lines:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def token_digest(token: str) -> str:
    """How app.server.zygote names a session's token in its output (never the token itself)."""
    return hashlib.sha256(token.encode()).hexdigest()[:16]


class StartFailed(Exception):
    """A child process exited or did not listen in time."""


@dataclasses.dataclass(eq=False)
class Child:
    """One app process: its port on 127.0.0.1, its private token and its open websockets; once
    it serves a session, that session's cookie secret, its browser and its client address."""

    proc: asyncio.subprocess.Process
    port: int
    token: str
    started_s: float
    n_sockets: int = 0
    connected: bool = False  # its page has opened a websocket (the reaper's idle time applies)
    idle_since_s: float = 0.0
    drain: asyncio.Task | None = None
    secret: str = ""
    client: str = ""
    address: str = ""
    opened_s: float = 0.0
    last_input_s: float = 0.0
    pages: set = dataclasses.field(default_factory=set)  # the open page websockets

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def alive(self) -> bool:
        return self.proc.returncode is None

    def rss_bytes(self) -> int:
        """Resident memory [bytes] (0 once the process is gone); of a process forked from the
        zygote, its proportional share (PSS: the pages it shares with its parent and siblings
        split between them), which the kernel sums cheaply in ``smaps_rollup``."""
        if isinstance(self.proc, ForkedProcess):
            pss = _pss_bytes(self.pid)
            if pss is not None:
                return pss
        try:
            return int(psutil.Process(self.pid).memory_info().rss)
        except (psutil.Error, OSError):
            return 0

    @property
    def cookie(self) -> str:
        return f"lmapd-token-{self.port}={self.token}"

    @property
    def origin(self) -> str:
        return f"http://{CHILD_HOST}:{self.port}"

    async def stop(self, wait_s: float = 10.0) -> None:
        """Stop the process (SIGTERM, then SIGKILL after ``wait_s``), close its stdin and stop
        reading its output."""
        proc = self.proc
        await stop_process(proc, wait_s)
        if proc.stdin is not None:
            proc.stdin.close()
        if self.drain is not None:
            self.drain.cancel()


def child_command(scene: str | None, options: tuple[str, ...] = ()) -> list[str]:
    """The command of one session's process: the one-scene app on loopback, any free port, its
    token read from stdin (never on the command line, where other users could read it), and the
    launcher's own app ``options`` (``--no-preview``)."""
    cmd = [sys.executable, "-m", "app", "--shared", "--host", CHILD_HOST, "--port", "0"]
    cmd.append("--token-stdin")
    if scene:
        cmd += ["--scene", scene]
    return cmd + list(options)


def zygote_command(scene: str | None, options: tuple[str, ...] = ()) -> list[str]:
    """The command of the sessions' preloaded parent (app.server.zygote)."""
    return [
        sys.executable,
        "-m",
        "app.server.zygote",
        *(["--scene", scene] if scene else []),
        *options,
    ]


class Parent(Protocol):
    """What starting a child needs of the launcher (app.server.launcher.Launcher): its caps, its
    set of children not yet stopped, its way to stop one and its count of failed starts."""

    caps: Caps
    command: Callable[..., list[str]]
    scene: str | None
    options: tuple[str, ...]
    n_start_failures: int
    child_env: dict[str, str]
    _all: set[Child]

    async def stop_child(self, child: Child, wait_s: float = 10.0) -> None: ...


async def start_process(launcher: Parent) -> Child:
    """Start one app process with the launcher's command and wait until it listens (the
    launcher's ``start_child`` without a zygote). Raises StartFailed."""
    token = secrets.token_urlsafe(32)
    # two malloc arenas: each thread's own (64 MB of address space apiece) would eat the
    # session's address-space limit (app.server.process.limit_address_space) without using
    # memory
    env = {**os.environ, **launcher.child_env, "PYTHONUNBUFFERED": "1", "MALLOC_ARENA_MAX": "2"}
    proc = await asyncio.create_subprocess_exec(
        *launcher.command(launcher.scene, launcher.options),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        env=env,
        start_new_session=True,  # a Ctrl+C in the terminal reaches the launcher only
    )
    child = Child(proc, 0, token, time.monotonic())
    launcher._all.add(child)
    proc.stdin.write(token.encode() + b"\n")
    try:
        await proc.stdin.drain()
        port = await asyncio.wait_for(_read_port(proc), launcher.caps.start_timeout_s)
    except (TimeoutError, StartFailed, ConnectionError) as exc:
        await launcher.stop_child(child)
        launcher.n_start_failures += 1
        raise StartFailed(str(exc) or type(exc).__name__) from None
    child.port = port
    child.drain = asyncio.create_task(_drain(proc.stdout))
    return child


async def _read_port(proc: asyncio.subprocess.Process) -> int:
    while True:
        line = await proc.stdout.readline()
        if not line:
            await proc.wait()
            raise StartFailed(f"the process exited with {proc.returncode} before listening")
        found = ADDRESS_LINE.match(line.decode(errors="replace"))
        if found:
            return int(found["port"])


async def stop_process(proc, wait_s: float = 10.0) -> None:
    """Stop a process (an ``asyncio.subprocess.Process`` or a ForkedProcess): SIGTERM, then
    SIGKILL after ``wait_s``."""
    if proc.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        try:
            await asyncio.wait_for(proc.wait(), wait_s)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()


def _pss_bytes(pid: int) -> int | None:
    """A process's proportional set size from /proc/PID/smaps_rollup [bytes] (Linux 4.14+), or
    None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as f:
            for line in f:
                if line.startswith(b"Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


class ForkedProcess:
    """A session process forked by the zygote (not this process's child), seen through the
    parts of ``asyncio.subprocess.Process`` the launcher uses; its exit status is unknown (-1)
    once it is gone."""

    stdin = None

    def __init__(self, pid: int):
        self.pid = pid
        self._returncode: int | None = None

    @property
    def returncode(self) -> int | None:
        if self._returncode is None:
            try:
                gone = psutil.Process(self.pid).status() == psutil.STATUS_ZOMBIE
            except psutil.NoSuchProcess:
                gone = True
            if gone:
                self._returncode = -1
        return self._returncode

    def _signal(self, sig: int) -> None:
        if self.returncode is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self._signal(signal.SIGTERM)

    def kill(self) -> None:
        self._signal(signal.SIGKILL)

    async def wait(self) -> int:
        while self.returncode is None:
            await asyncio.sleep(0.05)
        return self._returncode


class Zygote:
    """The launcher's end of app.server.zygote: started on the first spawn, asked for one session
    per ``spawn TOKEN`` line; its output tells each token's process and, once it listens, its
    port."""

    def __init__(self, command: list[str], env: dict[str, str] | None = None):
        self.command = command
        self.proc: asyncio.subprocess.Process | None = None
        self.reader: asyncio.Task | None = None
        self.ready: asyncio.Future | None = None
        self.pids: dict[str, asyncio.Future] = {}  # token digest -> pid
        self.ports: dict[str, asyncio.Future] = {}  # token -> port
        self.env = {} if env is None else env  # what its environment adds (the launcher's)
        self._lock = asyncio.Lock()

    async def _start(self, timeout_s: float) -> None:
        loop = asyncio.get_running_loop()
        self.ready = loop.create_future()
        self.proc = await asyncio.create_subprocess_exec(
            *self.command,
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            env={
                **os.environ,
                **self.env,
                "PYTHONUNBUFFERED": "1",
                "MALLOC_ARENA_MAX": "2",
                "NUMBA_THREADING_LAYER": "workqueue",  # GNU OpenMP's aborts forked processes
            },
            start_new_session=True,
        )
        self.reader = asyncio.create_task(self._read())
        await asyncio.wait_for(asyncio.shield(self.ready), timeout_s)

    async def _read(self) -> None:
        while line := await self.proc.stdout.readline():
            text = line.decode(errors="replace").strip()
            if text == ZYGOTE_READY and not self.ready.done():
                self.ready.set_result(True)
            elif found := FORKED_LINE.match(text):
                future = self.pids.get(found["digest"])
                if future is not None and not future.done():
                    future.set_result(int(found["pid"]))
            elif found := SESSION_LINE.match(text):
                future = self.ports.get(found["token"])
                if future is not None and not future.done():
                    future.set_result(int(found["port"]))
        problem = StartFailed(f"the sessions' parent exited with {await self.proc.wait()}")
        for future in (self.ready, *self.pids.values(), *self.ports.values()):
            if future is not None and not future.done():
                future.set_exception(problem)

    async def spawn(self, launcher: Parent) -> Child:
        """Fork one session and wait until it listens. Raises StartFailed."""
        timeout_s = launcher.caps.start_timeout_s
        token = secrets.token_urlsafe(32)
        loop = asyncio.get_running_loop()
        pid_future = self.pids[token_digest(token)] = loop.create_future()
        port_future = self.ports[token] = loop.create_future()
        child = None
        try:
            async with self._lock:
                if self.proc is None or self.proc.returncode is not None:
                    await self._start(timeout_s)
                self.proc.stdin.write(f"spawn {token}\n".encode())
                await self.proc.stdin.drain()
            pid = await asyncio.wait_for(pid_future, timeout_s)
            child = Child(ForkedProcess(pid), 0, token, time.monotonic())  # type: ignore[arg-type]
            launcher._all.add(child)
            child.port = await asyncio.wait_for(port_future, timeout_s)
            return child
        except (TimeoutError, StartFailed, ConnectionError, OSError) as exc:
            if child is not None:
                await launcher.stop_child(child)
            launcher.n_start_failures += 1
            raise StartFailed(str(exc) or type(exc).__name__) from None
        finally:
            self.pids.pop(token_digest(token), None)
            self.ports.pop(token, None)
            for future in (pid_future, port_future):
                if future.done() and not future.cancelled():
                    future.exception()  # read: never "never retrieved"

    async def close(self) -> None:
        proc = self.proc
        if proc is None:
            return
        await stop_process(proc, 10)
        if self.reader is not None:
            self.reader.cancel()


async def _drain(stream: asyncio.StreamReader) -> None:
    """Read a child's stdout to its end (its pipe must not fill up)."""
    while await stream.readline():
        pass
