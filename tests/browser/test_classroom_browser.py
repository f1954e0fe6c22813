"""The classroom's second pass in a real headless Chromium, on a server of its own: the
Geiger-mode chart shows its measured counts, a refused combination puts the sliders back, the
array image selects pixels from the keyboard, the glossary opens from the TNR slider, "Copy link"
confirms, and a lesson's view is in sight at 1280 x 720 and on a phone."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def classroom_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-classroom.log") as url:
        yield url


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def set_state(page, **values) -> None:
    page.evaluate("(v) => window.trame.state.update(v)", values)


def in_viewport(page, selector: str) -> bool:
    """The element's top is on screen, below the app bar, and a third of it at least shows."""
    return page.evaluate(
        """(sel) => { const r = document.querySelector(sel).getBoundingClientRect();
            const h = window.innerHeight, shown = Math.min(r.bottom, h) - Math.max(r.top, 0);
            return r.top >= 40 && r.top < h && shown >= Math.min(r.height, h) / 3; }""",
        selector,
    )


def test_the_classroom_views_keys_words_and_links(page, classroom_url):
    page.context.grant_permissions(["clipboard-read", "clipboard-write"])
    page.set_viewport_size({"width": 1280, "height": 900})
    page.goto(classroom_url + "&pixels=64&receiver.kind=gm_apd")
    wait_first_frame(page)
    wait_settled(page)

    # the Geiger-mode chart: the measured counts drawn, inside the time axis, titled as counts
    # (once the selected pixels' chart has come for this receiver: a loaded machine sends the
    # frame's picture first and its chart after it)
    page.wait_for_function(
        "() => ((window.trame.state.get('waveforms') || {}).data || [{}])[0].type === 'bar'",
        timeout=60_000,
    )
    figure = state(page, "waveforms")
    bars = figure["data"][0]
    assert bars["type"] == "bar" and max(bars["y"]) > 0
    lo, hi = figure["layout"]["xaxis"]["range"]  # opened on the echo, its busy bins in view
    busy = [x for x, y in zip(bars["x"], bars["y"], strict=True) if y >= max(bars["y"]) / 10]
    assert lo <= min(busy) and max(busy) <= hi
    menu = figure["layout"].get("updatemenus") or [{"buttons": []}]
    for button in menu[0]["buttons"][1:]:  # the whole window a click away: every bar in it
        whole_lo, whole_hi = button["args"][0]["xaxis.range"]
        assert whole_lo <= min(bars["x"]) and max(bars["x"]) <= whole_hi
    assert page.locator(".waveform-card .card-title").inner_text().startswith("Photon counts")
    assert page.locator(".waveform-card .js-plotly-plot .barlayer path").count() > 0

    # a combination over the budget is refused and the sliders go back
    set_state(page, gm_pulses=1000, gm_dark_count_rate_hz=1e8)
    page.wait_for_function("() => (window.trame.state.get('error_message') || '').length > 0")
    wait_settled(page)
    assert page.locator(".error-message").inner_text().startswith("Refused:")
    assert (state(page, "gm_pulses"), state(page, "gm_dark_count_rate_hz")) == (100, 1e4)
    thumb = page.get_by_role("slider", name="Pulses per frame")
    assert thumb.get_attribute("aria-valuenow") == "100"

    # keyboard: the cursor pixel moves with the arrows, Enter selects, Shift+Enter adds
    start = state(page, "selected_pixels")[-1]
    page.locator(".array-box").focus()
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowDown")
    cursor = [start[0] + 1, start[1] + 2]
    assert state(page, "array_cursor") == cursor
    page.keyboard.press("Enter")
    page.wait_for_function(
        "(c) => JSON.stringify(window.trame.state.get('selected_pixels')) === JSON.stringify([c])",
        arg=cursor,
    )
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("Shift+Enter")
    page.wait_for_function("() => window.trame.state.get('selected_pixels').length === 2")
    assert state(page, "selected_pixels") == [cursor, [cursor[0], cursor[1] - 1]]
    # a log slider steps a hundredth of a decade per arrow, a tenth per Page key
    distance = page.get_by_role("slider", name="Distance")
    distance.focus()
    page.keyboard.press("ArrowRight")
    page.wait_for_function("() => window.trame.state.get('distance_m') === 512")
    page.keyboard.press("PageUp")
    page.wait_for_function("() => window.trame.state.get('distance_m') === 645")
    assert distance.get_attribute("aria-valuetext") == "645 m"
    wait_settled(page)

    # the glossary from the TNR slider: its entry in a tooltip, then the dialog at that entry
    info = page.get_by_role("button", name="What is TNR?")
    info.hover()
    tooltip = page.locator(".v-overlay--active .glossary-tip").first
    tooltip.wait_for()
    assert tooltip.inner_text().startswith("TNR: Threshold-to-noise ratio")
    info.click()
    asked = page.locator(".glossary-asked")
    asked.wait_for()
    assert asked.locator(".glossary-term").inner_text() == "TNR"
    page.get_by_role("button", name="Close the glossary").click()

    # "Copy link" confirms, and the link holds only what differs from the start
    page.get_by_role("button", name="Share this scene (link)").click()
    page.locator(".copy-link").click()
    page.locator(".link-copied").wait_for()
    assert page.locator(".link-copied").inner_text().startswith("Link copied")
    link = page.evaluate("() => navigator.clipboard.readText()")
    assert "distance_m=645" in link and "gm.pulses" not in link and "tnr=" not in link


@pytest.mark.parametrize(("width", "height"), [(1280, 720), (412, 915)])
def test_a_lessons_view_is_in_sight_when_its_card_opens(page, classroom_url, width, height):
    page.set_viewport_size({"width": width, "height": height})
    page.goto(classroom_url + "&pixels=256")
    wait_first_frame(page)
    wait_settled(page)
    for key, view in (("double-peak", ".waveform-card"), ("panels-azimuth", ".array-card")):
        generation = state(page, "frame_generation")
        page.evaluate("(k) => window.trame.trigger('open_lesson', [k])", key)
        page.wait_for_function(
            "([k, g]) => (window.trame.state.get('lesson') || {}).key === k"
            " && window.trame.state.get('frame_generation') > g",
            arg=[key, generation],
        )
        wait_settled(page, 120)
        page.wait_for_timeout(600)  # the scroll after the card's transition
        assert in_viewport(page, view), key
        assert page.locator(".lesson-card .lesson-title").is_visible()
        if width < 960:
            assert state(page, "main_drawer") is False  # the drawer closed over the card
