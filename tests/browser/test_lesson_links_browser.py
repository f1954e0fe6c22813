"""The classroom's third pass in a real headless Chromium, on a server of its own: "Read more"
draws its maths and shows no LaTeX or test names; a lesson starts clean (lesson 8 after lesson
6: the whole array, its selected pixel in view, one outline); ``?lesson=KEY`` opens the lesson
with its card and its view in sight at 1280 x 720 and on a phone, the view's name whole, the
card unfolded with its view below it; "Share this lesson" writes the link; a first visit's
welcome line starts the first lesson; the Geiger-mode chart opens on the echo, the whole window
a click away; a pixel whose stop went to a false alarm says so (checked against the core's own
stops), and the stats' screen-reader description names the point count shown."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled

import simcore
from app.logic.lessons import BY_KEY, LESSONS

pytestmark = [pytest.mark.browser, pytest.mark.slow]  # about 3 minutes, the server's start included


@pytest.fixture(scope="module")
def links_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-lesson-links.log") as url:
        yield url


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def open_lesson(page, key: str) -> None:
    generation = state(page, "frame_generation")
    page.evaluate("(k) => window.trame.trigger('open_lesson', [k])", key)
    wait_lesson(page, key, generation)


def wait_lesson(page, key: str, generation: int = 0) -> None:
    page.wait_for_function(
        "([k, g]) => (window.trame.state.get('lesson') || {}).key === k"
        " && window.trame.state.get('frame_generation') > g",
        arg=[key, generation],
        timeout=120_000,
    )
    wait_settled(page, 120)
    page.wait_for_timeout(600)  # the scroll after the card's transition


def box(page, selector: str) -> dict:
    return page.evaluate(
        "(s) => { const r = document.querySelector(s).getBoundingClientRect();"
        " return { top: r.top, bottom: r.bottom, left: r.left, right: r.right,"
        " height: r.height }; }",
        selector,
    )


def test_read_more_draws_its_maths_and_shows_no_latex_or_test_names(page, links_url):
    page.set_viewport_size({"width": 1280, "height": 900})
    page.goto(links_url)
    wait_first_frame(page)
    open_lesson(page, "tnr-trade")
    if state(page, "lesson_folded"):
        page.locator(".fold-lesson").click()
    page.locator(".lesson-card .physics-link").click()
    dialog = page.get_by_role("region", name="Physics page")
    dialog.wait_for()
    text = dialog.inner_text()
    for raw in ("$", "\\frac", "\\mathrm", "tests/", "test_", ".py", "docs/"):
        assert raw not in text, raw
    assert text.startswith(BY_KEY["tnr-trade"].reference_title)
    # MathML drawn by the browser: a fraction laid out taller than a line of text
    fraction = dialog.locator("math[display='block'] mfrac").first
    assert fraction.count() == 1
    size = fraction.bounding_box()
    assert size is not None and size["width"] > 10 and size["height"] > 20
    # the full derivation, one click away, its maths drawn too
    dialog.locator(".physics-full-link").click()
    page.wait_for_function("() => window.trame.state.get('physics_section').kind === 'physics'")
    assert "$" not in dialog.locator(".physics-text").inner_text()
    assert dialog.locator(".physics-text math").count() > 0
    page.get_by_role("button", name="Close the physics page").click()


def test_lesson_8_after_lesson_6_shows_the_whole_array_with_its_selected_pixel(page, links_url):
    page.set_viewport_size({"width": 1280, "height": 900})
    page.goto(links_url)
    wait_first_frame(page)
    open_lesson(page, "flyaround-edge-on")
    assert state(page, "array_zoom")["s"] > 1  # lesson 6's card is about the array: zoomed
    open_lesson(page, "lm-vs-gm")
    assert state(page, "array_zoom") == {"s": 1, "x": 0, "y": 0}
    # the Geiger-mode chart: opened on the echo, the whole window one click away
    plot = page.locator(".waveform-card .js-plotly-plot")
    echo = plot.evaluate("(p) => p.layout.xaxis.range.slice()")
    page.locator(".waveform-card .updatemenu-button", has_text="Whole window").click()
    page.wait_for_function(
        "(r) => { const p = document.querySelector('.waveform-card .js-plotly-plot');"
        " return p.layout.xaxis.range[1] - p.layout.xaxis.range[0] > 1.5 * (r[1] - r[0]); }",
        arg=echo,
    )
    assert state(page, "selected_pixels") == [list(p) for p in BY_KEY["lm-vs-gm"].selection]
    page.locator(".array-card").scroll_into_view_if_needed()
    image, marker = box(page, ".array-box"), box(page, ".pixel-marker")
    middle_x, middle_y = (
        (marker["left"] + marker["right"]) / 2,
        (marker["top"] + marker["bottom"]) / 2,
    )
    assert (
        image["left"] <= middle_x <= image["right"] and image["top"] <= middle_y <= image["bottom"]
    )
    lit = page.evaluate(  # the pixels of the image as shown that are not black
        """() => { const img = document.querySelector('.array-image');
            const c = document.createElement('canvas');
            c.width = img.naturalWidth; c.height = img.naturalHeight;
            const g = c.getContext('2d'); g.drawImage(img, 0, 0);
            const d = g.getImageData(0, 0, c.width, c.height).data; let n = 0;
            for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] > 60) n++;
            return n; }"""
    )
    assert lit >= 300  # the target's ~480 pixels at 3 km, not a black corner of it
    # one outline at a time: a lesson opened within the 4 s of another's leaves only its own
    open_lesson(page, "double-peak")
    page.evaluate("() => window.trame.trigger('open_lesson', ['panels-azimuth'])")
    wait_lesson(page, "panels-azimuth")
    outlined = page.evaluate(
        "() => [...document.querySelectorAll('.lesson-view')].map((e) => e.className)"
    )
    assert len(outlined) == 1 and "array-card" in outlined[0], outlined
    page.wait_for_timeout(4300)
    assert page.locator(".lesson-view").count() == 0


@pytest.mark.parametrize(("width", "height"), [(1280, 720), (412, 915)])
def test_a_lessons_link_opens_its_card_and_its_view_in_sight(page, links_url, width, height):
    page.context.grant_permissions(["clipboard-read", "clipboard-write"])
    page.set_viewport_size({"width": width, "height": height})
    page.goto(links_url + "&lesson=double-peak")
    wait_first_frame(page)
    wait_lesson(page, "double-peak")
    assert page.locator(".welcome-line").count() == 0  # a lesson's link: no welcome
    assert state(page, "selected_pixels") == [list(p) for p in BY_KEY["double-peak"].selection]
    card, view = box(page, ".lesson-card"), box(page, ".waveform-card")
    assert page.locator(".lesson-card .lesson-title").is_visible()
    where = page.evaluate("() => [window.scrollY, !!trame.utils.lmapdLesson.pending]")
    assert card["bottom"] <= view["top"] + 1, (card, view, where)
    assert view["top"] < height - view["height"] / 3, (card, view, where)
    name = page.locator(".lesson-view-name")
    assert name.inner_text() == "· look at the waveform chart"
    assert name.evaluate("(e) => e.scrollWidth <= e.clientWidth + 1")  # never cut
    # unfolded, the card grows: its view goes below it again
    if state(page, "lesson_folded"):
        page.locator(".fold-lesson").click()
        page.wait_for_timeout(700)
        card, view = box(page, ".lesson-card"), box(page, ".waveform-card")
        assert card["bottom"] <= view["top"] + 1 and view["top"] < height, (card, view)
    # the app bar's title whole; on a phone Plotly's toolbar off the chart's legend
    title = page.locator(".v-app-bar .v-toolbar-title__placeholder")
    assert title.evaluate("(e) => e.scrollWidth <= e.clientWidth + 1"), title.inner_text()
    toolbar = page.locator(".waveform-card .modebar-container")
    shown = toolbar.evaluate("(e) => getComputedStyle(e).display !== 'none'")
    assert toolbar.count() == 1 and shown == (width >= 600)
    # "Share this lesson" writes the lesson's link
    page.locator(".share-lesson").click()
    page.locator(".lesson-link-copied").wait_for()
    link = page.evaluate("() => navigator.clipboard.readText()")
    assert link.endswith("lesson=double-peak") and "pitch_deg" not in link


@pytest.mark.parametrize(("width", "height"), [(1280, 720), (412, 915)])
def test_a_first_visit_says_welcome_and_starts_the_first_lesson(page, links_url, width, height):
    page.set_viewport_size({"width": width, "height": height})
    page.goto(links_url)
    wait_first_frame(page)
    if state(page, "lesson"):  # one scene for all pages: an earlier test's lesson is open
        page.evaluate("() => window.trame.trigger('leave_lesson')")
        page.wait_for_function("() => !window.trame.state.get('lesson')")
        page.evaluate("() => window.localStorage.clear()")  # (that page was welcomed by it)
        page.reload()
        wait_first_frame(page)
    line = page.locator(".welcome-line")
    line.wait_for()
    assert page.locator(".welcome-menu").is_visible() == (width < 960)  # the menu, on a phone
    page.locator(".start-here").click()
    wait_lesson(page, LESSONS[0].key)
    assert line.count() == 0
    page.reload()
    wait_first_frame(page)
    page.wait_for_timeout(500)
    assert page.locator(".welcome-line").count() == 0  # once per browser


def test_a_pixel_taken_by_a_false_alarm_is_labelled_so_and_the_stats_are_described(page, links_url):
    # a scene built for it: strong echoes under a low threshold, false alarms in a fifth of the
    # pixels; the frame the page shows is the core's (same seed), whose stops are read here
    page.set_viewport_size({"width": 1280, "height": 900})
    page.goto(links_url + "&pixels=64&tnr=4")
    wait_first_frame(page)
    page.evaluate("() => window.trame.trigger('leave_lesson')")
    page.wait_for_function("() => window.trame.state.get('tnr') === 4")
    wait_settled(page, 120)
    result = simcore.simulate(overrides={"preset": "interactive"}, pixels=64, tnr=4.0)
    d = result.detection
    alarms: dict[int, list[float]] = {}
    for pixel, range_m in zip(d.outliers.pixel.tolist(), d.outliers.range_m.tolist(), strict=True):
        alarms.setdefault(pixel, []).append(range_m)
    taken = [  # (flat pixel, the false alarm before its echo) of the echoes not detected
        (pixel, min(alarms[pixel]))
        for i, pixel in enumerate(result.echo.pixel.tolist())
        if not d.detected[i] and any(r < d.range_true_m[i] for r in alarms.get(pixel, []))
    ]
    assert len(taken) >= 3
    row = page.locator(".stats-table tr", has_text="Taken by a false alarm")
    assert row.locator(".stat-value").inner_text() == f"{len(taken):,d}"
    (pixel, alarm_m) = taken[0]
    generation = state(page, "frame_generation")
    page.evaluate("(rc) => window.trame.trigger('pixel_click', rc)", list(divmod(pixel, 64)))
    page.wait_for_function(
        "(g) => window.trame.state.get('frame_generation') > g"
        " || ((window.trame.state.get('waveforms') || {}).data || []).some("
        "(t) => (t.name || '').includes('taken by'))",
        arg=generation,
    )
    legend = page.locator(".waveform-card .legendtext", has_text="taken by a false alarm")
    legend.first.wait_for()
    assert f"taken by a false alarm at {alarm_m:.1f} m" in legend.first.text_content()
    # the screen reader's description of the stats names the point count shown
    shown = page.locator(".point-count").inner_text().split()[0]
    said = page.locator("#stats-description").inner_text()
    assert f"Points {shown}," in said and said.startswith("Statistics of this flash: ")
    assert page.locator(".stats-card").get_attribute("aria-describedby") == "stats-description"
    chart = page.locator("#waveform-description").text_content()
    assert f"taken by a false alarm at {alarm_m:.1f} m" in chart
    cloud = page.locator("#cloud-description").text_content()
    assert cloud.startswith("The point cloud: ") and "outliers (false alarms)" in cloud
    assert "The 3D scene: " in page.locator("#scene-description").text_content()
    alt = page.locator(".array-image").get_attribute("alt")
    assert alt.startswith("Detector array image, 64 by 64 pixels") and f"{shown} points" in alt


def test_a_cards_glossary_words_and_the_stats_info_buttons_open_the_glossary(page, links_url):
    page.set_viewport_size({"width": 1280, "height": 1000})
    page.goto(links_url)
    wait_first_frame(page)
    open_lesson(page, "tnr-trade")
    if state(page, "lesson_folded"):
        page.locator(".fold-lesson").click()
    page.locator(".lesson-detail-button").click()
    words = page.locator(".lesson-card .glossary-link")
    terms = set(words.evaluate_all("(links) => links.map((a) => a.dataset.term)"))
    assert {"Rice's rate", "σ (sigma)", "Threshold", "False alarm"} <= terms
    page.locator('.lesson-card .glossary-link[data-term="Rice\'s rate"]').first.click()
    asked = page.locator(".glossary-asked .glossary-term")
    asked.wait_for()
    assert asked.inner_text() == "Rice's rate"
    listed = {t.strip() for t in page.locator(".glossary-list .glossary-term").all_text_contents()}
    assert terms <= listed  # every card word links to an entry of the glossary's list
    page.get_by_role("button", name="Close the glossary").click()
    page.wait_for_function("() => !window.trame.state.get('glossary_open')")
    button = page.get_by_role("button", name="What is σ (sigma)?")
    button.scroll_into_view_if_needed()
    button.click()
    asked.wait_for()
    assert asked.inner_text() == "σ (sigma)"
