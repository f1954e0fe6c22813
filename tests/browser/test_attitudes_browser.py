"""The Attitudes panel in a real headless Chromium, on a server of its own (the paper scene at
64 x 64 pixels; a click moves the pose, which is server state shared by every client): the
button brings the coarse map on screen, and a click on one of its cells moves the pitch and
azimuth sliders to that cell and the frame follows. The map is stopped once the click is checked
(bounded work: its first levels, 6 and 26 attitudes at 32 x 32 pixels)."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled

from simcore._assets import ASSETS_DIR

pytestmark = [pytest.mark.browser, pytest.mark.slow]

CHART = ".attitudes-box .js-plotly-plot"
# the page position of the centre of the cell at (pitch, azimuth) [deg] on the drawn map
JS_CELL_AT = """([pitch, azimuth]) => {
  const gd = document.querySelector('.attitudes-box .js-plotly-plot');
  const fl = gd._fullLayout, box = gd.getBoundingClientRect();
  return [box.left + fl._size.l + fl.xaxis.l2p(azimuth),
          box.top + fl._size.t + fl.yaxis.l2p(Math.sin(pitch * Math.PI / 180))];
}"""
JS_SLIDER_VALUE = """(key) => Number(document.querySelector(
  `.slider-${key} [role=slider]`).getAttribute('aria-valuenow'))"""


@pytest.fixture(scope="module")
def attitudes_url(artifacts_dir, tmp_path_factory):
    """A server of the paper scene at 64 x 64 pixels (light frames: the map is the work here)."""
    paper = (ASSETS_DIR / "scenes" / "paper.toml").read_text()
    assert "pixels = 256\n" in paper
    scene = tmp_path_factory.mktemp("attitudes") / "paper-64.toml"
    scene.write_text(paper.replace("pixels = 256\n", "pixels = 64\n"))
    with app_server(scene=str(scene), log_path=artifacts_dir / "app-server-attitudes.log") as url:
        yield url


def test_the_coarse_map_appears_and_a_click_on_a_cell_moves_the_pose_sliders_there(
    page, attitudes_url, artifacts_dir
):
    page.goto(attitudes_url)
    wait_first_frame(page)
    wait_settled(page)
    button = page.locator(".attitudes-compute")
    assert button.get_attribute("aria-label") == "Map the imaging quality over every attitude"
    button.scroll_into_view_if_needed()
    button.click()
    page.wait_for_function(
        f"() => !!document.querySelector('{CHART} .hm') || "
        f"!!document.querySelector('{CHART} .heatmaplayer image')",
        timeout=90_000,
    )
    first = page.evaluate(JS_STATE, "attitudes_map")
    assert first["data"][0]["colorbar"]["title"]["text"] == "target points [-]"
    assert len(first["data"][0]["z"]) in (3, 5)  # the 90-degree grid's rows, or the 45's
    assert "attitudes at 32 × 32 px" in page.locator(".attitudes-status").inner_text()
    page.wait_for_function(  # the 45-degree grid (5 rows), refined on the page
        "() => (window.trame.state.get('attitudes_map') || {data: [{z: []}]}).data[0].z.length "
        ">= 5",
        timeout=90_000,
    )

    page.locator(".attitudes-box").scroll_into_view_if_needed()
    x, y = page.evaluate(JS_CELL_AT, [45, -90])  # a cell of the 45-degree grid and the finer
    page.mouse.click(x, y)
    page.wait_for_function(
        "() => window.trame.state.get('pitch_deg') === 45 "
        "&& window.trame.state.get('azimuth_deg') === -90",
        timeout=30_000,
    )
    wait_settled(page)
    assert page.evaluate(JS_SLIDER_VALUE, "pitch_deg") == 45
    assert page.evaluate(JS_SLIDER_VALUE, "azimuth_deg") == -90
    marker = page.evaluate(JS_STATE, "attitudes_map")["data"][1]
    assert marker["name"] == "current attitude" and marker["x"] == [-90]
    page.screenshot(path=artifacts_dir / "app-attitudes.png")
    page.locator(".attitudes-metric").click()  # the chooser: another metric, its unit named
    page.get_by_role("option", name="Recall").click()
    page.wait_for_function(
        "() => window.trame.state.get('attitudes_map').data[0].colorbar.title.text "
        "=== 'recall at tau [-]'"
    )
    if page.evaluate(JS_STATE, "attitudes_busy"):
        page.locator(".attitudes-stop").click()  # the finer levels are not needed here
        page.wait_for_function("() => window.trame.state.get('attitudes_busy') === false")
