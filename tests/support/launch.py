"""Run the real app server in a subprocess and drive it with Debian's headless Chromium: shared by
the browser tests (tests/browser) and the benchmark (scripts/bench_app.py)."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path

REPO_DIR = Path(__file__).resolve().parents[2]
CHROMIUM_PATH = os.environ.get("LMAPD_CHROMIUM", "/usr/bin/chromium")
# Debian's Chromium, headless, WebGL on SwiftShader (docs: STACK.md); never `playwright install`.
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
]


def chromium_missing_message() -> str | None:
    """None if Chromium is installed, else what to do about it."""
    if Path(CHROMIUM_PATH).is_file() and os.access(CHROMIUM_PATH, os.X_OK):
        return None
    return (
        f"Chromium not found at {CHROMIUM_PATH}: install Debian's chromium "
        "(sudo apt-get install chromium; `make chromium` does it) or set LMAPD_CHROMIUM"
    )


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


ADDRESS = re.compile(r"http://\S+")  # the address `lmapd app` prints, token included


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as response:
            return response.status == 200
    except (urllib.error.URLError, OSError):
        return False


def printed_address(output: str) -> str | None:
    """The address to open from the server's output: the first ``http://...`` on the line that
    ``lmapd app`` prints once it listens (the access token is part of it)."""
    for line in output.splitlines():
        if line.startswith("lmapd-sim app: http://"):
            found = ADDRESS.search(line)
            return found.group(0) if found else None
    return None


@dataclasses.dataclass(frozen=True)
class RunningApp:
    """A started app server: the address it printed (with its token) and its process id."""

    url: str
    pid: int

    @property
    def port(self) -> int:
        return int(urllib.parse.urlsplit(self.url).port or 80)

    @property
    def token(self) -> str:
        return urllib.parse.parse_qs(urllib.parse.urlsplit(self.url).query)["token"][0]

    @property
    def origin(self) -> str:
        parts = urllib.parse.urlsplit(self.url)
        return f"{parts.scheme}://{parts.netloc}"


@contextlib.contextmanager
def app_process(
    host: str = "127.0.0.1",
    port: int | None = None,
    scene: str | None = None,
    timeout_s: float = 120.0,
    log_path: Path | None = None,
    app_args: tuple[str, ...] = (),
    sessions: bool = False,
) -> Iterator[RunningApp]:
    """Start ``python -m app`` on a free port, wait for the address it prints and for that address
    to answer, yield it, stop the server.

    The app runs as one process with one scene for every page (``--shared``) unless ``sessions``
    asks for the launcher (each page load its own session, with ``app_args`` such as
    ``--max-sessions``); the launcher's address then answers with a redirect to a new session,
    so it is waited for by its first line only.

    Raises RuntimeError (with the server's output) if it exits or does not answer in time.
    """
    port = port or free_port(host)
    cmd = [sys.executable, "-m", "app", "--host", host, "--port", str(port)]
    if not sessions:
        cmd.append("--shared")
    if scene:
        cmd += ["--scene", scene]
    cmd += list(app_args)
    log_file = open(log_path, "w+b") if log_path else tempfile.TemporaryFile()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, cwd=REPO_DIR, stdout=log_file, stderr=subprocess.STDOUT, env=env)

    def output() -> str:
        log_file.seek(0)
        return log_file.read().decode(errors="replace")

    try:
        deadline = time.monotonic() + timeout_s
        url = None
        while url is None or not (sessions or _answers(url)):
            if proc.poll() is not None or time.monotonic() > deadline:
                state = f"exited with {proc.returncode}" if proc.poll() is not None else "timed out"
                raise RuntimeError(f"the app server {state} before answering:\n{output()[-4000:]}")
            time.sleep(0.2)
            url = url or printed_address(output())
        yield RunningApp(url, proc.pid)
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
        log_file.close()


@contextlib.contextmanager
def app_server(
    host: str = "127.0.0.1",
    port: int | None = None,
    scene: str | None = None,
    timeout_s: float = 120.0,
    log_path: Path | None = None,
    app_args: tuple[str, ...] = (),
    sessions: bool = False,
) -> Iterator[str]:
    """:func:`app_process`, yielding only the address to open (``http://HOST:PORT/?token=...``)."""
    with app_process(host, port, scene, timeout_s, log_path, app_args, sessions) as running:
        yield running.url


# JavaScript helpers evaluated in the page (window.trame is trame's client API).
JS_FRAMES = "() => (window.lmapdFrames || []).length"
JS_STATE = "(name) => window.trame.state.get(name)"


# the drawer's controls are built and their sliders named (app/static/a11y.js names them in the
# animation frame after they appear)
JS_CONTROLS_READY = """() => !!document.querySelector('.controls')
  && [...document.querySelectorAll('[data-a11y-name] [role=slider]')]
    .every((thumb) => thumb.hasAttribute('aria-label'))"""


# what the page holds when a wait for its first frame or its controls runs out: the failure says
# which part never came
JS_PAGE_REPORT = """() => {
  const lmapd = (window.trame && window.trame.utils && window.trame.utils.lmapd) || null;
  const unnamed = [...document.querySelectorAll('[data-a11y-name]')]
    .filter((box) => [...box.querySelectorAll('[role=slider]')]
      .some((thumb) => !thumb.hasAttribute('aria-label')))
    .map((box) => box.dataset.a11yName);
  return {
    url: window.location.href, visibility: document.visibilityState,
    connected: !!(window.trame && window.trame.client && window.trame.client.isConnected()),
    frames: (window.lmapdFrames || []).length, frame_key: window.trame && window.trame.state
      ? window.trame.state.get('frame_key') : null,
    pending: lmapd ? lmapd.pending.length : null,
    controls_flag: lmapd ? lmapd.page.controls : null,
    controls: document.querySelectorAll('.controls').length,
    loading: document.querySelectorAll('.controls-loading').length,
    unnamed_sliders: unnamed,
    text: document.body ? document.body.innerText.slice(0, 300) : '',
    errors: window.lmapdErrors || [],
  };
}"""


def page_report(page) -> dict:
    """What the page holds now (``JS_PAGE_REPORT``), or why it could not be read."""
    try:
        return page.evaluate(JS_PAGE_REPORT)
    except Exception as exc:  # a page that navigated or crashed: say so
        return {"unreadable": f"{type(exc).__name__}: {exc}"}


def wait_first_frame(page, timeout_s: float = 90.0) -> None:
    """Wait until the page has drawn its first simulated frame and built its controls (they
    come right after it: app/static/frame.js); a timeout says what the page held then."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    waits = (("its first frame", JS_FRAMES + " > 0"), ("its controls", JS_CONTROLS_READY))
    for what, script in waits:
        try:
            page.wait_for_function(script, timeout=timeout_s * 1000)
        except PlaywrightTimeout:
            raise AssertionError(
                f"the page did not show {what} within {timeout_s:g} s; it held {page_report(page)}"
            ) from None


def wait_settled(page, timeout_s: float = 60.0) -> None:
    """Wait until the page has sent every change (trame's client holds a changed value until its
    previous call is answered: under load the last slider step can still be waiting), nothing is
    computing, the newest frame is drawn and the charts are mounted (their library loads after
    the first frame: app/static/charts.js)."""
    page.wait_for_function(
        """() => {
            const s = window.trame.state, frames = window.lmapdFrames || [];
            return s.dirtyKeys.size === 0 && !s.client.isBusy() && !s.get('busy')
                && frames.length > 0 && frames[frames.length - 1].key === s.get('frame_key')
                && !!(window.lmapdCharts || {}).mounted;
        }""",
        timeout=timeout_s * 1000,
    )


def set_field(page, key: str, value: float) -> None:
    """Type ``value`` into the number field of control ``key`` and commit it (Enter)."""
    field = page.locator(f".value-{key} input")
    field.fill(str(value))
    field.press("Enter")
