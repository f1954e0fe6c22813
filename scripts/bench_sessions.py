"""Benchmark of the launcher (``lmapd app`` without ``--shared``): a new tab's time to its first
frame with the warm spare process and without it, and one session's memory after its first frame
(paper scene, 256 x 256, real headless Chromium).

    .venv/bin/python scripts/bench_sessions.py [--repeats 5]

Each repeat starts a launcher with a spare and one without (interleaved), waits until the spare
(if any) listens, then opens the printed address in a fresh page and times, in the page's clock,
from the navigation's start to the first frame painted (the page logs it: window.lmapdFrames);
then reads the session process's resident memory (RSS). Medians with their range are printed.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

import psutil
from playwright.sync_api import sync_playwright
from support.launch import (
    CHROMIUM_ARGS,
    CHROMIUM_PATH,
    app_process,
    chromium_missing_message,
    wait_first_frame,
    wait_settled,
)

FIRST_FRAME_MS = "() => window.lmapdFrames[0].t"  # performance.now(): from the navigation's start


def listening(proc: psutil.Process) -> bool:
    try:
        return any(c.status == psutil.CONN_LISTEN for c in proc.net_connections())
    except psutil.Error:
        return False


def one_tab(browser, spare: bool) -> tuple[float, float]:
    """(ms from navigation to the first frame, the session's RSS in MB after it settled)."""
    options = () if spare else ("--no-spare",)
    with app_process(sessions=True, app_args=options) as running:
        launcher = psutil.Process(running.pid)
        deadline = time.monotonic() + 120
        while spare and not any(listening(c) for c in launcher.children()):
            if time.monotonic() > deadline:
                raise RuntimeError("the spare did not start")
            time.sleep(0.1)
        time.sleep(1.0)  # let the spare finish its own first frame (it computes one at start)
        page = browser.new_page(viewport={"width": 1600, "height": 1000})
        page.goto(running.url)
        wait_first_frame(page, timeout_s=300)
        ms = float(page.evaluate(FIRST_FRAME_MS))
        wait_settled(page, timeout_s=300)
        sessions = launcher.children()  # without a spare: the one session
        rss_mb = max(c.memory_info().rss for c in sessions) / 2**20 if sessions else 0.0
        page.close()
        return ms, rss_mb


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    with_spare, without, rss = [], [], []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
        for _ in range(args.repeats):
            for spare, times in ((True, with_spare), (False, without)):
                ms, rss_mb = one_tab(browser, spare)
                times.append(ms)
                if not spare:
                    rss.append(rss_mb)
                print(f"{'with' if spare else 'without'} spare: {ms:.0f} ms, {rss_mb:.0f} MB")
        browser.close()

    def line(values: list[float], unit: str) -> str:
        med = statistics.median(values)
        return f"{med:.0f} {unit} (range {min(values):.0f}-{max(values):.0f}, n={len(values)})"

    print(f"new tab to its first frame, with the spare: {line(with_spare, 'ms')}")
    print(f"new tab to its first frame, without:        {line(without, 'ms')}")
    print(f"one session's RSS after its first frame:    {line(rss, 'MB')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
