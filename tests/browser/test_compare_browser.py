"""Compare in the browser: pin the frame, change the distance; the stats show both frames side by
side and the cloud view draws the pinned cloud with the new one."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, set_field, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser


def test_pin_then_change_shows_both_frames(page, app_url, artifacts_dir):
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    page.get_by_role("button", name="Pin this frame").click()
    page.wait_for_function("() => !!window.trame.state.get('pinned')", timeout=10000)
    pinned_points = page.evaluate(JS_STATE, "n_points")
    set_field(page, "distance_m", 900)
    wait_settled(page)
    now_points = page.evaluate(JS_STATE, "n_points")
    assert now_points != pinned_points
    rows = page.locator(".compare-table tbody tr")
    assert rows.count() == 5
    first = rows.first
    assert first.locator(".compare-pinned").inner_text() == f"{pinned_points:,d}"
    assert first.locator(".compare-now").inner_text() == f"{now_points:,d}"
    assert page.locator(".pinned-legend").is_visible()
    assert page.evaluate(JS_STATE, "n_pinned_points") == pinned_points
    page.screenshot(path=str(artifacts_dir / "compare.png"), full_page=True)
    page.get_by_role("button", name="Unpin the pinned frame").click()
    page.wait_for_function("() => !window.trame.state.get('pinned')", timeout=10000)
    assert page.locator(".compare-table").count() == 0
    page.locator(".reset-button").click()
    wait_settled(page)
