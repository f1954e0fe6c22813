"""Soak the live app in real headless Chromium and print the figures for the reliability
section: slider changes sent, frames drawn, server memory growth, the final-state check and the
two-clients check.

    .venv/bin/python scripts/soak_app.py [--changes 300] [--url URL]

It starts the app server itself on a free 127.0.0.1 port (unless --url is given: then the server
must run on this machine, as its memory is read from /proc/<pid>/status). Exit status 0 if every
check passed (server alive, memory growth < 100 MB, final state shown, both clients correct).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

from playwright.sync_api import sync_playwright
from support.launch import CHROMIUM_ARGS, CHROMIUM_PATH, app_server, chromium_missing_message
from support.soak import run_soak

MAX_GROWTH_MB = 100.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--changes", type=int, default=300, help="slider changes (default 300)")
    parser.add_argument(
        "--url",
        default=None,
        help="the address an app already running on this machine printed (with its token)",
    )
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(f"soak_app: {problem}", file=sys.stderr)
        return 2
    server = contextlib.nullcontext(args.url) if args.url else app_server()
    with server as url, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
        try:
            report = run_soak(browser, url, n_changes=args.changes)
        finally:
            browser.close()
    print(f"soak of {url.split('?')[0]}")
    for line in report.lines():
        print(f"  {line}")
    ok = (
        report.server_alive
        and report.rss_growth_mb < MAX_GROWTH_MB
        and report.final_state_ok
        and report.two_clients_ok
    )
    print("all checks passed" if ok else "SOME CHECKS FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
