"""Regenerate the documentation's screenshots of the app (docs/img/app-*.png) from the current code:
the real app server and Debian's headless Chromium (tests/support/launch.py), as the browser tests
and scripts/bench_app.py drive them.

    .venv/bin/python scripts/screenshots.py [--out docs/img] [--url URL]

Each shot sets the page up through its own controls (a lesson, number fields, buttons), waits
until the frame is drawn, and saves the viewport: the paper scene with the double-peaked echoes
selected (1600 x 1000), a pose with the cloud coloured by SNR, the fly-around mode, a pinned frame
compared with a changed one (the whole page), a projector (1280 x 720) and a phone (412 x 915).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

from playwright.sync_api import sync_playwright
from support.launch import (
    CHROMIUM_ARGS,
    CHROMIUM_PATH,
    app_server,
    chromium_missing_message,
    set_field,
    wait_first_frame,
    wait_settled,
)

DESKTOP = {"width": 1600, "height": 1000}
PROJECTOR = {"width": 1280, "height": 720}
PHONE = {"width": 412, "height": 915}


def settle(page) -> None:
    wait_settled(page)
    page.wait_for_timeout(600)  # plotly's and vtk.js's last redraws


def trigger(page, name: str, *args) -> None:
    page.evaluate("([name, args]) => window.trame.trigger(name, args)", [name, list(args)])


def paper_with_double_peaks(page) -> None:
    """The paper scene with the double-peak lesson's pixels selected, its card closed."""
    trigger(page, "open_lesson", "double-peak")
    settle(page)
    trigger(page, "leave_lesson")
    settle(page)


def pose_and_snr(page) -> None:
    set_field(page, "pitch_deg", 25)
    set_field(page, "azimuth_deg", -35)
    page.get_by_role("button", name="SNR", exact=True).click()
    page.get_by_role("button", name="Peak power", exact=True).click()
    settle(page)


def flyaround(page) -> None:
    page.locator(".mode-flyaround").click()
    settle(page)


def compare(page) -> None:
    page.locator(".pin-frame").click()
    settle(page)
    set_field(page, "distance_m", 1500)
    settle(page)


# (file name, viewport, set-up, whole page)
SHOTS = (
    ("app.png", DESKTOP, paper_with_double_peaks, False),
    ("app-pose-snr.png", DESKTOP, pose_and_snr, False),
    ("app-flyaround.png", DESKTOP, flyaround, False),
    ("app-compare.png", DESKTOP, compare, True),
    ("app-projector.png", PROJECTOR, paper_with_double_peaks, False),
    ("app-phone.png", PHONE, paper_with_double_peaks, False),
)


def take(url: str, out: Path, only: set[str] | None = None) -> list[Path]:
    """Take every shot (or those named in ``only``) into ``out``; each on a fresh page and, since
    all pages share the server's scene, each starting with the controls reset."""
    out.mkdir(parents=True, exist_ok=True)
    saved = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS)
        for name, viewport, setup, full_page in SHOTS:
            if only and name not in only:
                continue
            page = browser.new_page(viewport=viewport)
            page.goto(url)
            wait_first_frame(page)
            trigger(page, "unpin_frame")
            trigger(page, "reset_controls")
            with contextlib.suppress(Exception):  # single mode, if a shot left fly-around on
                page.locator(".mode-single").click(timeout=2000)
            settle(page)
            setup(page)
            page.mouse.move(0, viewport["height"] - 1)  # no hover tooltips
            path = out / name
            page.screenshot(path=str(path), full_page=full_page)
            saved.append(path)
            print(f"{path}: {viewport['width']} x {viewport['height']}")
            page.close()
        browser.close()
    return saved


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=Path(__file__).resolve().parent.parent / "docs/img"
    )
    parser.add_argument("--url", help="an app already running (else one is started)")
    parser.add_argument("--only", nargs="*", help="file names of the shots to take")
    args = parser.parse_args(argv)
    problem = chromium_missing_message()
    if problem:
        print(problem, file=sys.stderr)
        return 1
    only = set(args.only) if args.only else None
    if args.url:
        take(args.url, args.out, only)
    else:
        with app_server() as url:
            take(url, args.out, only)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
