"""Fly-around mode in a real headless Chromium, on a server of its own (the mode is server state
shared by every client, so the other browser tests must not see it): the mode switch hides the
pose sliders and shows the time slider and the readout; play steps through the frames, each one
drawn before the next time is set."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def flyaround_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-flyaround.log") as url:
        yield url


def test_fly_around_mode_shows_the_orbit_and_plays_one_drawn_frame_per_step(
    page, flyaround_url, artifacts_dir
):
    page.goto(flyaround_url)
    wait_first_frame(page)
    wait_settled(page)
    assert page.locator(".slider-distance_m").is_visible()
    assert not page.locator(".slider-fly_t_s").is_visible()

    page.locator(".mode-flyaround").click()
    page.wait_for_function("() => window.trame.state.get('frame_generation') >= 2")
    wait_settled(page)
    assert not page.locator(".slider-distance_m").is_visible()
    label = page.locator(".control-fly_t_s .control-label").inner_text()
    assert label.startswith("Time") and "(s)" in label
    readout = page.evaluate(JS_STATE, "fly_readout")
    assert readout["t"].startswith("0 s") and 150 < float(readout["distance"].split()[0]) < 300
    assert "6 m of the 15 m MRO" in page.locator(".fly-hint").inner_text()

    page.locator(".fly-play").click()
    page.wait_for_function("() => window.trame.state.get('fly_t_s') >= 600", timeout=60_000)
    page.locator(".fly-play").click()  # pause
    page.wait_for_function("() => window.trame.state.get('fly_playing') === false")
    wait_settled(page)
    t_s = page.evaluate(JS_STATE, "fly_t_s")
    drawn = page.evaluate("() => window.lmapdFrames.map((f) => f.key)")
    # one drawn frame per step: the first, the mode switch, then one per time step
    assert len(drawn) >= 2 + t_s // 300
    page.screenshot(path=artifacts_dir / "app-flyaround.png")
