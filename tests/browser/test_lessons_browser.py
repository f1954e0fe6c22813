"""Lessons in a real headless Chromium, on a server of their own (a lesson sets the scene every
page shares): a lesson's button opens its scene, its card above the views and its selected pixels
(markers on the array image, their echoes in the chart); leaving keeps the scene; the fly-around
lesson draws the orbits' map and the day/night one the Sun and the Earth; every control the
lessons add has an accessible name."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled
from test_a11y_browser import controls_in_tree

import simcore
from app.logic.lessons import BY_KEY, LESSONS

pytestmark = pytest.mark.browser

PANEL = "Lessons (one-click scenes)"


@pytest.fixture(scope="module")
def lessons_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-lessons.log") as url:
        yield url


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def open_from_the_panel(page, key: str) -> None:
    """Click the lesson's button (opening the panel if needed) and wait for its frame."""
    button = page.get_by_role("button", name=BY_KEY[key].title, exact=True)
    if not button.is_visible():
        page.get_by_role("button", name=PANEL).click()
    generation = state(page, "frame_generation")
    button.click()
    page.wait_for_function(
        "([k, g]) => (window.trame.state.get('lesson') || {}).key === k"
        " && window.trame.state.get('frame_generation') > g",
        arg=[key, generation],
    )
    wait_settled(page)


def shown_basic(lesson) -> str:
    return lesson.card()["basic"]


def test_a_lesson_opens_with_its_card_and_its_selected_pixels(page, lessons_url, artifacts_dir):
    page.goto(lessons_url)
    wait_first_frame(page)
    wait_settled(page)
    assert page.locator(".lesson-card").count() == 0  # no lesson open at first
    lesson = BY_KEY["double-peak"]
    open_from_the_panel(page, lesson.key)
    card = page.get_by_role("region", name="Lesson")
    assert card.is_visible()
    if state(page, "lesson_folded"):
        page.locator(".fold-lesson").click()
    assert shown_basic(lesson) in card.inner_text()  # the reader's text first
    page.locator(".lesson-detail-button").click()  # then "More detail"
    text = card.inner_text()
    shown = lesson.card()
    assert f"Lesson: {lesson.title}" in text
    for part in ("look", "why", "try_next", "reference_title"):
        assert shown[part] in text, part
    selection = [list(p) for p in lesson.selection]
    assert state(page, "selected_pixels") == selection
    assert page.locator(".pixel-marker").count() == len(selection)
    names = [trace["name"] for trace in state(page, "waveforms")["data"]]
    assert all(any(n.startswith(f"({r}, {c})") for n in names) for r, c in selection), names
    expected = simcore.simulate(overrides={"preset": "interactive"}).summary()["n_points"]
    count = page.locator(".point-count").inner_text().split()[0].replace(",", "")
    assert int(count) == expected  # the paper scene's frame, as the core computes it
    page.screenshot(path=artifacts_dir / "app-lesson.png")


def test_leaving_a_fly_around_lesson_keeps_its_frame(page, lessons_url):
    page.goto(lessons_url)
    wait_first_frame(page)
    wait_settled(page)
    open_from_the_panel(page, "flyaround-edge-on")
    assert (state(page, "mode"), state(page, "fly_t_s")) == ("flyaround", 1500)
    assert page.locator(".slider-fly_t_s").is_visible()
    # the orbits' map: the Earth, both orbits, the target, the lidar's path around it and the dots
    traces = page.locator(".fly-map-box .js-plotly-plot .scatterlayer .trace")
    traces.nth(6).wait_for(state="attached", timeout=20_000)
    assert traces.count() == 7
    keys = ("pixels", "pulse_energy_mj", "tnr", "seed", "mode", "fly_t_s", "selected_pixels")
    before = {key: state(page, key) for key in keys}
    points = page.locator(".point-count").inner_text()
    page.get_by_role("button", name="Leave lesson").click()
    page.wait_for_function("() => !window.trame.state.get('lesson')")
    wait_settled(page)
    assert page.locator(".lesson-card").count() == 0
    assert {key: state(page, key) for key in keys} == before
    assert page.locator(".point-count").inner_text() == points  # the same frame
    page.locator(".mode-single").click()  # back to the single frame for the next test
    wait_settled(page)


def test_the_day_night_lesson_draws_the_sun_and_the_earth_in_the_scene(page, lessons_url):
    page.goto(lessons_url)
    wait_first_frame(page)
    wait_settled(page)
    open_from_the_panel(page, "day-night")  # the Sun behind the lidar: at the zenith
    sun = page.locator(".scene-card .sun-row")
    assert sun.inner_text().startswith("Sun: azimuth 0°, elevation 90° (target frame)")
    assert (
        "km below (the target's nadir, +z)" in page.locator(".scene-card .earth-row").inner_text()
    )
    assert state(page, "sun_arrow") and state(page, "earth_arrow")
    page.get_by_role("button", name="Leave lesson").click()


def test_every_lesson_control_has_an_accessible_name(page, lessons_url):
    page.goto(lessons_url)
    wait_first_frame(page)
    wait_settled(page)
    open_from_the_panel(page, "tnr-trade")  # the panel open, a card shown
    found = controls_in_tree(page)
    names = {c["name"].casefold() for c in found if c["role"] == "button"}  # Vuetify's buttons
    wanted = {x.title for x in LESSONS} | {PANEL, "Leave lesson"}  # show their text in capitals
    assert {name.casefold() for name in wanted} <= names
    assert [c for c in found if not c["name"]] == []
