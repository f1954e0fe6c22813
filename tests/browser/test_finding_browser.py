"""Finding things on the detector array in a real headless Chromium, on a server of its own: the
Multi-peak mode marks the double-peak lesson's pixels (magenta on the page), Ctrl + wheel zooms
about the pointer (the wheel alone scrolls the page until the image is clicked), the readout
names the pixel under the pointer with its echo peaks, a click on the zoomed image selects the
pixel under the pointer, and the keys and buttons zoom and pan; a part's row in the materials
panel highlights the part."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled
from test_lessons_browser import open_from_the_panel

from app.logic.lessons import BY_KEY
from app.payloads.image import MULTI_PEAK_RGB

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def finding_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-finding.log") as url:
        yield url


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def pixel_on_screen(page, row: int, col: int) -> tuple[float, float]:
    """The page coordinates of the centre of pixel (row, col) with the current zoom."""
    box = page.locator(".array-box").bounding_box()
    zoom, n = state(page, "array_zoom"), state(page, "array_image")["pixels"]
    x = box["x"] + ((col + 0.5) / n - zoom["x"]) * zoom["s"] * box["width"]
    y = box["y"] + ((row + 0.5) / n - zoom["y"]) * zoom["s"] * box["height"]
    return x, y


def test_multi_peak_mode_zoom_hover_and_click(page, finding_url, artifacts_dir):
    page.goto(finding_url)
    wait_first_frame(page)
    wait_settled(page)
    lesson = BY_KEY["double-peak"]
    open_from_the_panel(page, lesson.key)
    page.locator(".image-multi-peak").click()
    page.wait_for_function("() => !!(window.trame.state.get('array_image').multi_peak)")
    wait_settled(page)
    marked = {tuple(p) for p in state(page, "array_image")["multi_peak"]}
    (r, c), _ = lesson.selection
    assert {tuple(p) for p in lesson.selection} <= marked
    assert len(marked) == lesson.figures["n_double"]

    # the wheel alone scrolls the page; with Ctrl it zooms about the pointer: the lesson's
    # first pixel stays under it
    page.locator(".array-box").scroll_into_view_if_needed()
    page.mouse.move(*pixel_on_screen(page, r, c))
    scrolled = page.evaluate("() => window.scrollY")
    page.mouse.wheel(0, -100)
    page.wait_for_timeout(300)
    assert state(page, "array_zoom")["s"] == 1
    assert page.evaluate("() => window.scrollY") < scrolled  # the page went up
    page.locator(".array-box").scroll_into_view_if_needed()
    page.mouse.move(*pixel_on_screen(page, r, c))
    page.keyboard.down("Control")
    for _ in range(12):
        page.mouse.wheel(0, -100)
    page.keyboard.up("Control")
    page.wait_for_function("() => window.trame.state.get('array_zoom').s >= 10")
    zoom = state(page, "array_zoom")
    x, y = pixel_on_screen(page, r, c)
    page.mouse.move(x + 1, y + 1)  # a move: the readout of the pixel now under the pointer
    page.wait_for_function(
        "([r, c]) => { const p = window.trame.state.get('pixel_readout'); "
        "return p && p.row === r && p.col === c; }",
        arg=[r, c],
    )
    assert "2 echo peaks" in page.locator(".pixel-readout").inner_text()
    # the zoomed pixel on the screen is magenta, several screen pixels wide
    png = page.screenshot(path=artifacts_dir / "app-multi-peak-zoomed.png")
    shot = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    ratio = page.evaluate("() => window.devicePixelRatio")
    size_px = zoom["s"] * page.locator(".array-box").bounding_box()["width"] / 256
    assert size_px > 6
    sx, sy = round(x * ratio), round(y * ratio)
    assert np.abs(shot[sy, sx] - MULTI_PEAK_RGB).max() <= 12, shot[sy, sx]

    # a click on the zoomed image selects the pixel under the pointer
    page.mouse.click(x, y)
    page.wait_for_function(
        "([r, c]) => JSON.stringify(window.trame.state.get('selected_pixels'))"
        " === JSON.stringify([[r, c]])",
        arg=[r, c],
    )

    # a drag pans, and its mouse-up selects nothing
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x - 80, y - 40, steps=5)
    page.mouse.up()
    moved = state(page, "array_zoom")
    assert moved["s"] == zoom["s"] and moved["x"] > zoom["x"] and moved["y"] > zoom["y"]
    assert state(page, "selected_pixels") == [[r, c]]
    page.mouse.wheel(0, 100)  # the image was clicked: the wheel alone zooms it now
    page.wait_for_function("(s) => window.trame.state.get('array_zoom').s < s", arg=moved["s"])

    # keys on the focused image: 0 resets, + zooms about the centre, Ctrl + arrows pan
    page.locator(".array-box").focus()
    page.keyboard.press("0")
    assert state(page, "array_zoom") == {"s": 1, "x": 0, "y": 0}
    page.keyboard.press("+")
    assert state(page, "array_zoom")["s"] == pytest.approx(1.5)
    x0 = state(page, "array_zoom")["x"]
    page.keyboard.press("Control+ArrowRight")
    assert state(page, "array_zoom")["x"] > x0
    page.get_by_role("button", name="Reset zoom").click()
    assert state(page, "array_zoom") == {"s": 1, "x": 0, "y": 0}
    page.get_by_role("button", name="Zoom in").click()
    assert state(page, "array_zoom")["s"] == pytest.approx(1.5)

    # pointing at a part's row in the materials panel highlights it in the 3D scene
    page.get_by_role("button", name="Target materials (per part)").click()
    row = page.locator(".material-row").first  # the dish: part "cover"
    row.scroll_into_view_if_needed()
    row.hover()
    page.wait_for_function("() => window.trame.state.get('highlight_part') === 'cover'")
    assert page.locator(".highlight-row").inner_text().startswith("part cover")
    page.mouse.move(1, 1)
    page.wait_for_function("() => window.trame.state.get('highlight_part') === ''")
