"""Soak test in real headless Chromium: 300 rapid changes across all sliders leave the server
alive, its memory grown by less than 100 MB, and the view showing the final state's result; two
clients at once both see correct results (tests/support/soak.py does the work; scripts/soak_app.py
prints it).

The work is bounded (300 changes, then two client changes), not the wall time: this shared 2-core
machine drifts by 2x between spells, so the elapsed time is reported (soak.txt, and in the test's
output with ``-s``), never asserted. A hang still fails: every wait in the soak has its own
limit."""

from __future__ import annotations

import pytest
from support.soak import run_soak

pytestmark = pytest.mark.browser


def test_300_rapid_slider_changes_then_two_clients(browser, app_url, artifacts_dir):
    report = run_soak(browser, app_url, n_changes=300)
    (artifacts_dir / "soak.txt").write_text("\n".join(report.lines()) + "\n")
    assert report.server_alive
    assert report.rss_growth_mb < 100, report.lines()
    assert report.final_state_ok, report.lines()
    assert report.two_clients_ok, report.lines()
    assert report.frames_drawn >= 1
    assert report.changes_sent == 300
    print("\n".join(report.lines()))  # the figures, the elapsed time among them
