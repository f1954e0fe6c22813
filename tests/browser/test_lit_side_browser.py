"""The lit side in a real headless Chromium, on a server of its own (the test sets the Sun every
page shares): by night the scene view has no "Show lit side" switch; with a Sun it has one, with
its accessible name, the state holds each facet's flags (facing the Sun, facing the Earth: n . s
> 0, checked here on facets whose normals this test computes) and the page's colours follow
them; the switch draws them in the view and the legend counts them."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from support.launch import JS_STATE, app_server, wait_first_frame, wait_settled
from test_a11y_browser import controls_in_tree

import simcore
from app.payloads import encode, scene3d
from simcore.sun import direction_from_angles

pytestmark = pytest.mark.browser

SWITCH = "Show lit side"
AZIMUTH, ELEVATION = 20.0, 10.0
# the bits of the state's lit side as plain arrays, and the colours the page draws of them
JS_LIT = """(facets) => {
    const lit = window.trame.state.get('lit_side'), bin = window.trame.utils.lmapdBin.bin;
    if (!lit) return null;
    const colors = window.trame.utils.lmapdLit.colors(lit);
    return { sun: Array.from(bin(lit.sun)), earth: Array.from(bin(lit.earth)),
             n: lit.n_facets, colors: facets.map((i) => Array.from(colors.slice(3 * i, 3 * i + 3))),
             palette: lit.palette };
}"""
MAX_SHOTS = 20  # screenshots of the view while it redraws (a bound on the tries, not on time)


@pytest.fixture(scope="module")
def lit_url(artifacts_dir):
    with app_server(log_path=artifacts_dir / "app-server-lit.log") as url:
        yield url + "&pixels=32"


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def set_state(page, **values) -> None:
    page.evaluate("(v) => window.trame.state.update(v)", values)


def chosen_facets(model, direction_body: np.ndarray, k: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """``k`` facets clearly on either side of the direction (normals from the corners' cross
    product, |cos| > 0.05, half facing it) and whether each faces it."""
    v, f = model.mesh.vertices, model.mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    norm = np.linalg.norm(n, axis=1)
    cos = (n @ (model.body_from_mesh.T @ direction_body)) / np.maximum(norm, 1e-300)
    picks = []
    for side in (cos > 0.05, cos < -0.05):
        candidates = np.flatnonzero(side & (norm > 0))
        picks.append(candidates[np.linspace(0, len(candidates) - 1, k // 2).astype(int)])
    facets = np.concatenate(picks)
    return facets, cos[facets] > 0


def sunlit_pixels(page) -> int:
    """Pixels of the scene view in the Sun's yellow (lit by the view's headlight or not)."""
    shot = page.locator(".scene-box canvas").first.screenshot()
    rgb = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB")).astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((r > 90) & (g > 0.6 * r) & (g < 0.95 * r) & (b < 0.4 * r)))


def test_the_lit_side_switch_shows_the_facets_the_sun_and_the_earth_light(
    page, lit_url, artifacts_dir
):
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(lit_url)
    wait_first_frame(page)
    wait_settled(page)
    switch = page.get_by_label(SWITCH)

    # by night: no lit side, no switch
    assert state(page, "sun_mode") == "none"
    assert state(page, "lit_side") is None
    assert switch.count() == 0

    # with a Sun: the switch, named, and the flags of every facet
    generation = state(page, "frame_generation")
    set_state(page, sun_mode="manual", sun_azimuth_deg=AZIMUTH, sun_elevation_deg=ELEVATION)
    page.wait_for_function(
        "(g) => window.trame.state.get('frame_generation') > g"
        " && !!window.trame.state.get('lit_side')",
        arg=generation,
    )
    wait_settled(page)
    assert switch.is_visible() and not switch.is_checked()
    names = [c["name"] for c in controls_in_tree(page)]
    assert SWITCH in names

    model = simcore.load_target(simcore.load_scene().target)  # the paper scene's MRO
    sun_facets, faces_sun = chosen_facets(model, direction_from_angles(AZIMUTH, ELEVATION))
    earth_facets, faces_earth = chosen_facets(model, np.array([0.0, 0.0, 1.0]))  # nadir: +z
    facets = np.concatenate([sun_facets, earth_facets])
    lit = page.evaluate(JS_LIT, facets.tolist())
    n = len(model.mesh.faces)
    assert lit["n"] == n
    sun = np.unpackbits(np.asarray(lit["sun"], np.uint8), count=n).astype(bool)
    earth = np.unpackbits(np.asarray(lit["earth"], np.uint8), count=n).astype(bool)
    assert np.array_equal(sun[sun_facets], faces_sun)
    assert np.array_equal(earth[earth_facets], faces_earth)
    # the page's colour of each facet: the palette's, by its two bits
    wanted = [lit["palette"][int(sun[i]) + 2 * int(earth[i])] for i in facets]
    assert lit["colors"] == wanted
    assert lit["palette"][1] == list(encode.rgb_of(scene3d.SUN_COLOR))

    # the switch: the lit side drawn (the Sun's yellow on the target) and its legend
    before = sunlit_pixels(page)
    page.locator(".scene-box").scroll_into_view_if_needed()
    switch.check()
    page.wait_for_function("() => window.trame.state.get('show_lit_side') === true")
    rows = page.locator(".scene-card .lit-row")
    assert rows.first.inner_text().startswith("faces the Sun only")
    assert rows.count() == 4
    assert page.locator(".scene-card .legend-head").inner_text().startswith("lit side")
    after = before
    for _ in range(MAX_SHOTS):
        after = sunlit_pixels(page)
        if after > before + 200:
            break
    page.screenshot(path=artifacts_dir / "app-lit-side.png")
    assert after > before + 200, (before, after)

    # by night again: the switch goes, the materials' legend comes back
    set_state(page, sun_mode="none")
    page.wait_for_function("() => window.trame.state.get('lit_side') === null")
    wait_settled(page)
    assert switch.count() == 0
    assert page.locator(".scene-card .legend-head").inner_text().startswith("material")
    assert errors == []
