"""Soak test of the live app in real headless Chromium, shared by tests/browser/test_soak.py and
scripts/soak_app.py: rapid changes of every slider, then checks that the server is alive, how much
its memory grew, and that the view shows the result of the final state (no stale frame); then two
browser clients at once.

The server's memory is its resident set size (VmRSS of /proc/<pid>/status); the server process is
found by the port it listens on.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import simcore
from app.logic.scene_map import scene_from_controls
from app.state import SPECS, STATE_KEYS, Controls, sanitize_controls
from support.launch import JS_FRAMES, JS_STATE, set_field, wait_first_frame, wait_settled

SLIDERS = tuple(key for key in SPECS if key != "seed")  # the seed has a field, no slider
# the sliders every page shows; the others belong to a choice (the manual Sun, the filter, the
# Geiger-mode receiver) and are built only while it is chosen
ALWAYS_SHOWN = ("pitch_deg", "azimuth_deg", "distance_m", "pixels", "pulse_energy_mj", "tnr")
# keys pressed on the sliders' thumbs
UP, DOWN = "ArrowRight", "ArrowLeft"


@dataclass
class SoakReport:
    changes_sent: int = 0
    n_sliders: int = 0
    frames_drawn: int = 0
    burst_s: float = 0.0
    settle_s: float = 0.0
    rss_before_mb: float = 0.0
    rss_after_mb: float = 0.0
    server_alive: bool = False
    final_points_page: tuple = ()  # (points, target points, outliers, pixels per side)
    final_points_expected: tuple = (None,)
    final_page: dict = field(default_factory=dict)  # what the page held then (PAGE_HELD)
    two_clients_points: list[tuple] = field(default_factory=list)
    two_clients_expected: tuple = (None,)
    elapsed_s: float = 0.0

    @property
    def rss_growth_mb(self) -> float:
        return self.rss_after_mb - self.rss_before_mb

    @property
    def final_state_ok(self) -> bool:
        return self.final_points_page == self.final_points_expected

    @property
    def two_clients_ok(self) -> bool:
        return len(self.two_clients_points) == 2 and all(
            n == self.two_clients_expected for n in self.two_clients_points
        )

    def lines(self) -> list[str]:
        return [
            f"slider changes sent: {self.changes_sent} in {self.burst_s:.1f} s "
            f"({self.changes_sent / max(self.burst_s, 1e-9):.0f}/s) "
            f"across {self.n_sliders} sliders",
            f"frames drawn by the page during the burst and settling: {self.frames_drawn}",
            f"settled {self.settle_s:.1f} s after the last change",
            f"server alive afterwards: {'yes' if self.server_alive else 'NO'}",
            f"server memory (RSS): {self.rss_before_mb:.0f} MB -> {self.rss_after_mb:.0f} MB "
            f"(growth {self.rss_growth_mb:+.1f} MB)",
            f"final state shown: {'yes' if self.final_state_ok else 'NO'} "
            f"(page {self.final_points_page}, expected {self.final_points_expected}: "
            "points, target points, outliers, pixels per side)"
            + ("" if self.final_state_ok else f"; the page held {self.final_page}"),
            f"two clients at once: {'both correct' if self.two_clients_ok else 'WRONG'} "
            f"(pages {self.two_clients_points}, expected {self.two_clients_expected})",
            f"total {self.elapsed_s:.1f} s",
        ]


def listening_pid(port: int) -> int:
    """The pid of the process of ours listening on TCP ``port`` (via /proc)."""
    inodes = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if int(fields[1].rsplit(":", 1)[1], 16) == port and fields[3] == "0A":
                inodes.add(fields[9])
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
                if link.startswith("socket:[") and link[8:-1] in inodes:
                    return int(pid)
        except OSError:
            continue
    raise RuntimeError(f"no process of ours listens on port {port}")


def rss_mb(pid: int) -> float:
    """Resident set size of ``pid`` in MB (VmRSS of /proc/<pid>/status)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for pid {pid}")


def alive(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in status


def point_count(page) -> tuple[int, int, int, int]:
    """What the page shows: points (the app bar's chip), target points, outliers, array size."""
    shown = int(page.locator(".point-count").inner_text().split()[0].replace(",", ""))
    state = [page.evaluate(JS_STATE, k) for k in ("n_target_points", "n_outliers", "array_image")]
    return shown, int(state[0]), int(state[1]), int(state[2]["pixels"])


# what a page holds besides its figures: its frame, its message, its last frames logged and the
# controls the expected figures are simulated from (a wrong final state then says which part)
PAGE_HELD = """(keys) => {
  const s = window.trame.state;
  return { frame_key: s.get('frame_key'), frame_kind: s.get('frame_kind'),
           busy: s.get('busy'), error_message: s.get('error_message'),
           frames: (window.lmapdFrames || []).slice(-4).map((f) => f.key),
           controls: Object.fromEntries(keys.map((k) => [k, s.get(k)])) };
}"""


def page_held(page) -> dict:
    """What the page holds now (``PAGE_HELD``): its controls and, for a report, its frame."""
    return page.evaluate(PAGE_HELD, list(STATE_KEYS))


def expected_points(page, raw: dict | None = None) -> tuple[int, int, int, int]:
    """The same figures as ``point_count`` for the page's controls (``raw``: as ``page_held``
    read them; else read now), simulated here (same scene, same seed, so the same result)."""
    raw = page_held(page)["controls"] if raw is None else raw
    controls, _ = sanitize_controls(raw, Controls(materials=dict(raw.get("materials") or {})))
    scene = scene_from_controls(simcore.load_scene(), controls)
    result = simcore.Pipeline().run(scene)
    s = result.summary()
    return int(s["n_points"]), int(s["n_target_points"]), int(s["n_outliers"]), result.pixels


def shown_sliders(page) -> tuple[str, ...]:
    """The sliders on the page now (every one of ALWAYS_SHOWN among them)."""
    shown = tuple(k for k in SLIDERS if page.locator(f".slider-{k} .v-slider-thumb").count())
    missing = [k for k in ALWAYS_SHOWN if k not in shown]
    assert not missing, f"sliders missing from the page: {missing}"
    return shown


def slider_burst(page, n_changes: int) -> int:
    """``n_changes`` keyboard steps on the thumbs of the sliders shown, round robin, no pause
    between; returns how many sliders took them."""
    sliders = shown_sliders(page)
    handles = [
        page.locator(f".slider-{key} .v-slider-thumb").first.element_handle() for key in sliders
    ]
    for i in range(n_changes):
        k = i % len(sliders)
        visit = i // len(sliders)
        # the pixel count goes up and down (its frames stay cheap), the others mostly up
        backwards = visit % 2 == 1 if sliders[k] == "pixels" else visit % 3 == 2
        handles[k].press(DOWN if backwards else UP)
    return len(sliders)


def run_soak(browser, url: str, n_changes: int = 300, settle_timeout_s: float = 60.0) -> SoakReport:
    """The soak on the app at ``url`` with a playwright ``browser``; returns the figures."""
    t_start = time.perf_counter()
    report = SoakReport()
    pid = listening_pid(urlsplit(url).port or 80)  # url: the printed address, token included
    viewport = {"width": 1600, "height": 1000}
    first = browser.new_context(viewport=viewport)
    page = first.new_page()
    try:
        page.goto(url)
        wait_first_frame(page)
        wait_settled(page)
        page.locator(".reset-button").click()  # from the starting scene, whatever came before
        time.sleep(0.3)
        wait_settled(page, settle_timeout_s)
        report.rss_before_mb = rss_mb(pid)
        frames0 = page.evaluate(JS_FRAMES)
        t0 = time.perf_counter()
        report.n_sliders = slider_burst(page, n_changes)
        report.changes_sent = n_changes
        report.burst_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        time.sleep(0.3)  # let the last change reach the server
        wait_settled(page, settle_timeout_s)
        report.settle_s = time.perf_counter() - t1
        report.frames_drawn = page.evaluate(JS_FRAMES) - frames0
        report.server_alive = alive(pid)
        report.rss_after_mb = rss_mb(pid)
        report.final_points_page = point_count(page)
        report.final_page = page_held(page)
        report.final_points_expected = expected_points(page, report.final_page["controls"])

        second = browser.new_context(viewport=viewport)
        other = second.new_page()
        try:
            other.goto(url)
            wait_first_frame(other)
            set_field(page, "distance_m", 640)  # a change from one client ...
            for p in (page, other):  # ... reaches both
                p.wait_for_function("() => window.trame.state.get('distance_m') === 640")
                wait_settled(p, settle_timeout_s)
            set_field(other, "tnr", 4.4)  # and one from the other
            for p in (page, other):
                p.wait_for_function("() => window.trame.state.get('tnr') === 4.4")
                wait_settled(p, settle_timeout_s)
            report.two_clients_points = [point_count(p) for p in (page, other)]
            report.two_clients_expected = expected_points(other)
        finally:
            second.close()
        report.server_alive = report.server_alive and alive(pid)
        page.locator(".reset-button").click()  # leave the shared scene as the next test expects
        time.sleep(0.3)
        wait_settled(page, settle_timeout_s)
    finally:
        first.close()
    report.elapsed_s = time.perf_counter() - t_start
    return report
