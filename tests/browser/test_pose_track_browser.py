"""The fly-around's "Track pose" switch in a real headless Chromium, on a server of its own (the
mode and the switch are server state shared by every client): found by its accessible name, it
draws the true and the estimated target frames in the 3D scene and the chart of the errors
along the track, which grows by a frame when the time slider moves on."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

SWITCH = "Track pose"


@pytest.fixture(scope="module")
def track_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-pose-track.log") as url:
        yield url + "&pixels=32"


def test_the_track_pose_switch_draws_both_frames_and_the_errors_along_the_track(
    page, track_url, artifacts_dir
):
    page.goto(track_url)
    wait_first_frame(page)
    wait_settled(page)
    page.locator(".mode-flyaround").click()
    page.wait_for_function("() => window.trame.state.get('frame_generation') >= 2")
    wait_settled(page)
    switch = page.get_by_label(SWITCH)
    assert switch.is_visible() and not switch.is_checked()
    switch.check()
    page.wait_for_function(
        "() => !!window.trame.state.get('fly_track_chart')"
        " && !!window.trame.state.get('fly_triad_estimate')",
        timeout=120_000,
    )
    assert page.evaluate(JS_STATE, "fly_triad_true") is not None
    assert page.locator(".fly-track-text").inner_text().startswith("Pose track:")
    chart = page.evaluate(JS_STATE, "fly_track_chart")
    assert len(chart["data"][0]["x"]) + len(chart["data"][-1]["x"]) >= 1  # tracked or lost
    assert page.locator(".fly-track-box .js-plotly-plot").count() == 1  # drawn by Plotly
    # the next frame: the chart holds both
    page.evaluate("() => { window.trame.state.set('fly_t_s', 300); }")
    page.wait_for_function(
        "() => { const c = window.trame.state.get('fly_track_chart'); if (!c) return false;"
        " const frames = c.data.filter((t) => t.name !== 'translation error (m)');"
        " return frames.reduce((n, t) => n + t.x.length, 0) >= 2; }",  # tracked or lost
        timeout=120_000,
    )
    page.locator(".scene-box").scroll_into_view_if_needed()
    page.screenshot(path=artifacts_dir / "app-pose-track.png")
    switch.uncheck()
    page.wait_for_function("() => window.trame.state.get('fly_track_chart') === null")
    assert page.evaluate(JS_STATE, "fly_triad_true") is None
