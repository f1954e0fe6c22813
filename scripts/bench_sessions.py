"""Benchmark of the launcher (``lmapd app`` without ``--shared``) as a class meets it, in real
headless Chromium: tabs opened together, each tab's time to its first words (the door's "Starting
your session") and to its first frame painted; and one tab's first frame while other sessions are
open (paper scene, 256 x 256, 1280 x 720 pages).

    .venv/bin/python scripts/bench_sessions.py [--tabs 1 5] [--open 10] [--repeats 3]
                                               [--modes fork process]
                                               [--no-browser-settle]

For each repeat, mode (sessions forked from the preloaded parent, the default on Linux, or a
process each) and count of tabs: a launcher starts, its spare session is left to get ready,
``--open`` sessions are opened without a browser (as bench_session_memory.py does, each to its
first frame) and the launcher's processes are left to go quiet (the next spare started), a
browser context and page are opened for each tab (a student's browser, open before the class
starts) and the browser is left to go quiet too, then the tabs open the printed address at the
same moment (``--no-browser-settle``: at once, as this script did before 2026-11-27, when each
new page's own start, about 0.7 s of CPU, ran into the timed seconds). Times are
wall-clock seconds from that moment: the door's first answer (the response's headers and first
words), measured here, and the first frame painted, at the time the page logged it
(window.lmapdFrames, on the page's clock).
Medians with their range over every tab of every repeat are printed; the one-minute load average
is printed beside them (the machine must be quiet for these times to mean anything).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*
sys.path.insert(0, str(Path(__file__).resolve().parent))

import psutil
from bench_session_memory import open_session
from playwright.async_api import async_playwright
from support.launch import (
    CHROMIUM_ARGS,
    CHROMIUM_PATH,
    JS_FRAMES,
    app_process,
    chromium_missing_message,
)

SPARE_WAIT_S = 120.0
FRAME_WAIT_S = 300.0
POLL_MS = 100  # how often a tab's page is asked whether its first frame is on screen


def _listening(proc: psutil.Process) -> bool:
    try:
        return any(c.status == psutil.CONN_LISTEN for c in proc.net_connections())
    except psutil.Error:
        return False


async def _spare_ready(launcher_pid: int) -> None:
    """Wait until a session process (the spare) listens, then a little for its own first frame."""
    deadline = time.monotonic() + SPARE_WAIT_S
    launcher = psutil.Process(launcher_pid)
    while not any(_listening(c) for c in launcher.children(recursive=True)):
        if time.monotonic() > deadline:
            raise RuntimeError("the spare session did not start")
        await asyncio.sleep(0.1)
    await asyncio.sleep(2.0)


def _cpu_s(processes: list[psutil.Process]) -> float:
    total = 0.0
    for proc in processes:
        try:
            times = proc.cpu_times()
            total += times.user + times.system
        except psutil.Error:
            pass
    return total


async def _quiet(processes, what: str, quiet_share: float = 0.05, window_s: float = 0.5) -> None:
    """Wait until ``processes()`` use under ``quiet_share`` of one core over ``window_s``."""
    deadline = time.monotonic() + SPARE_WAIT_S
    while time.monotonic() < deadline:
        tree = processes()
        before = _cpu_s(tree)
        await asyncio.sleep(window_s)
        if _cpu_s(tree) - before < quiet_share * window_s:
            return
    raise RuntimeError(f"{what} did not settle")


async def _settled(launcher_pid: int) -> None:
    """Wait until the launcher and its processes are quiet (the open sessions' frames done and
    the next spare started)."""
    launcher = psutil.Process(launcher_pid)
    await _quiet(lambda: [launcher, *launcher.children(recursive=True)], "the sessions")


def _browser_processes() -> list[psutil.Process]:
    """The browser's processes (Chromium's, under the Playwright driver this script started)."""
    found = []
    for proc in psutil.Process().children(recursive=True):
        try:
            if "chrom" in proc.name().lower():
                found.append(proc)
        except psutil.Error:
            pass
    return found


async def _browser_settled() -> None:
    """Wait until the browser is quiet: a new page's process keeps starting (Playwright's own
    scripts in it: about 0.7 s of CPU a page here) after ``new_page`` returns."""
    await _quiet(_browser_processes, "the browser")


async def _open_page(browser):
    """A student's browser, open before the class starts: its own context (cookies) and page."""
    context = await browser.new_context(viewport={"width": 1280, "height": 720})
    return context, await context.new_page()


async def _one_tab(page, url: str, t0: float, epoch0: float) -> tuple[float, float]:
    """(s to the door's first answer, s to the first frame painted), both from ``t0`` (the same
    moment as ``epoch0``, the system clock's seconds). The first frame's time is the one the
    page logged (its clock: ``performance.timeOrigin``, system-clock milliseconds), not the
    moment this script next looked: the wait looks every ``POLL_MS`` (Playwright's default, at
    every animation frame, kept each page drawing frames while it loaded)."""
    answered: list[float] = []
    page.on("response", lambda _r: answered or answered.append(time.perf_counter() - t0))
    await page.goto(url, wait_until="commit")
    await page.wait_for_function(JS_FRAMES + " > 0", timeout=FRAME_WAIT_S * 1000, polling=POLL_MS)
    shown_ms = await page.evaluate("() => performance.timeOrigin + window.lmapdFrames[0].t")
    return answered[0] if answered else float("nan"), shown_ms / 1000 - epoch0


async def one_round(
    browser, fork: bool, tabs: int, n_open: int, settle_browser: bool = True
) -> list[tuple[float, float]]:
    mode = "--fork-sessions" if fork else "--process-sessions"
    args = (mode, "--max-sessions", str(n_open + tabs + 2))
    with app_process(sessions=True, app_args=args) as running:
        await _spare_ready(running.pid)
        held = []
        for _ in range(n_open):
            client, _page, _s = await open_session(running)
            held.append(client)
        await _settled(running.pid)  # a quiet machine with the sessions open
        opened = [await _open_page(browser) for _ in range(tabs)]
        if settle_browser:
            await _browser_settled()  # the students' browsers open and idle
        t0, epoch0 = time.perf_counter(), time.time()
        times = await asyncio.gather(
            *(_one_tab(page, running.url, t0, epoch0) for _, page in opened)
        )
        for context, _ in opened:
            await context.close()
        for client in held:
            await client.close()
    return list(times)


def _line(values: list[float]) -> str:
    return (
        f"{statistics.median(values):.2f} s (range {min(values):.2f}-{max(values):.2f}, "
        f"n={len(values)})"
    )


async def main_async(args) -> int:
    async with async_playwright() as pw:
        browser = await pw.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
        results: dict[tuple[str, int], list[tuple[float, float]]] = {}
        loads = []
        for _ in range(args.repeats):
            for mode in args.modes:
                for tabs in args.tabs:
                    loads.append(os.getloadavg()[0])
                    times = await one_round(
                        browser, mode == "fork", tabs, args.open, args.browser_settle
                    )
                    results.setdefault((mode, tabs), []).extend(times)
                    print(
                        f"{mode}, {tabs} tab(s), {args.open} open: "
                        + ", ".join(f"{a:.2f}/{b:.2f}" for a, b in times)
                        + " s (first words / first frame)",
                        flush=True,
                    )
        await browser.close()
    print(f"\none-minute load average at each round's start: {min(loads):.1f}-{max(loads):.1f}")
    for (mode, tabs), times in results.items():
        label = "forked" if mode == "fork" else "a process each"
        print(f"{label}, {tabs} tab(s) together, {args.open} sessions open:")
        print(f"  first words (the door's answer): {_line([a for a, _ in times])}")
        print(f"  first frame painted:             {_line([b for _, b in times])}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tabs", type=int, nargs="+", default=[1, 5])
    parser.add_argument("--open", type=int, default=0, help="sessions open before the tabs")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modes", nargs="+", choices=("fork", "process"), default=["fork"])
    parser.add_argument(
        "--no-browser-settle",
        dest="browser_settle",
        action="store_false",
        help="open the tabs as soon as their pages exist, not once the browser is quiet",
    )
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    return asyncio.run(main_async(args))


if __name__ == "__main__":
    raise SystemExit(main())
