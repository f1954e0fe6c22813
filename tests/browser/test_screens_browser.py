"""The page on a projector (1280 x 720) and a phone (412 x 915): every panel is inside the page's
width and reachable by scrolling (not covered by the drawer, the app bar or another panel), and
the mouse wheel over a 3D view scrolls the page unless the view was clicked first. Screenshots go
to test-artifacts/."""

from __future__ import annotations

import pytest
from support.launch import wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

PANELS = {
    "controls": ".controls",
    "3D scene": ".scene-card",
    "point cloud": ".cloud-card",
    "array image": ".array-card",
    "waveform chart": ".waveform-card",
    "stats": ".stats-card",
}
# a point of the panel, given as fractions of its box, that must be the panel's own on screen
UNCOVERED = """([selector, fx, fy]) => {
  const el = document.querySelector(selector), r = el.getBoundingClientRect();
  const x = r.left + fx * r.width, y = Math.min(r.top + fy * r.height, window.innerHeight - 2);
  const hit = document.elementFromPoint(x, y);
  return { inside: !!hit && el.contains(hit), left: r.left, right: r.right, width: r.width,
           pageWidth: document.documentElement.scrollWidth };
}"""


def open_page(browser, app_url, width: int, height: int):
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    page.wait_for_timeout(500)
    return page


def check_panel(page, name: str, selector: str, width: int) -> None:
    panel = page.locator(selector).first
    panel.scroll_into_view_if_needed()
    page.wait_for_timeout(200)
    for fx, fy in ((0.5, 0.15), (0.1, 0.5), (0.9, 0.5)):
        seen = page.evaluate(UNCOVERED, [selector, fx, fy])
        assert seen["inside"], f"{name} is covered at ({fx}, {fy}) at width {width}: {seen}"
    assert seen["left"] >= 0 and seen["right"] <= width + 0.5, f"{name} is cut off: {seen}"
    assert seen["pageWidth"] <= width, f"the page is wider than the screen: {seen}"


@pytest.mark.parametrize("width, height", [(1280, 720), (412, 915)])
def test_every_panel_is_inside_the_page_and_reachable(
    browser, app_url, artifacts_dir, width, height
):
    page = open_page(browser, app_url, width, height)
    page.screenshot(path=str(artifacts_dir / f"screen-{width}x{height}.png"))
    page.screenshot(path=str(artifacts_dir / f"screen-{width}x{height}-page.png"), full_page=True)
    phone = width < 960
    drawer = page.locator(".v-navigation-drawer")
    if phone:  # the drawer starts closed and opens over the views
        assert not drawer.evaluate("d => d.classList.contains('v-navigation-drawer--active')")
    for name, selector in PANELS.items():
        if name == "controls":
            continue
        check_panel(page, name, selector, width)
    if phone:
        page.get_by_role("button", name="Show or hide the controls").click()
        page.wait_for_timeout(500)
        assert drawer.evaluate("d => d.classList.contains('v-navigation-drawer--temporary')")
    check_panel(page, "controls", ".controls", width)
    page.locator(".help-text").scroll_into_view_if_needed()  # the drawer's end, by scrolling
    assert page.locator(".help-text").is_visible()
    if phone:
        page.screenshot(path=str(artifacts_dir / f"screen-{width}x{height}-drawer.png"))
    page.close()


def test_the_wheel_over_a_3d_view_scrolls_the_page_until_the_view_is_clicked(browser, app_url):
    page = open_page(browser, app_url, 1280, 720)
    box = page.locator(".cloud-box").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.wheel(0, 120)
    page.wait_for_function("() => window.scrollY > 0", timeout=5000)
    scrolled = page.evaluate("window.scrollY")
    assert scrolled > 0
    box = page.locator(".cloud-box").bounding_box()  # moved up with the page
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.click(x, y)  # into the view: now the wheel zooms it
    assert "view-active" in page.locator(".cloud-box").get_attribute("class")
    page.mouse.wheel(0, 120)
    page.wait_for_timeout(500)
    assert page.evaluate("window.scrollY") == scrolled
    page.mouse.move(2, 700)  # leaving the view gives the wheel back to the page
    assert "view-active" not in page.locator(".cloud-box").get_attribute("class")
    page.close()
