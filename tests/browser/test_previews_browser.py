"""Progressive frames in the browser: after a change that recasts the rays the page draws the
preview first (the chip says so), then the chosen preset's frame; arrays arrive as binary."""

from __future__ import annotations

import pytest
from support.launch import JS_STATE, set_field, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

CHIP_LOG = """() => {
  window.lmapdChips = [];
  const chip = document.querySelector('.frame-kind');
  new MutationObserver(() => window.lmapdChips.push(chip.innerText.trim()))
    .observe(chip, { subtree: true, childList: true, characterData: true });
}"""


def test_a_distance_change_draws_the_preview_then_the_presets_frame(page, app_url):
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    assert page.locator(".frame-kind").inner_text().strip() == "interactive preset"
    page.evaluate(CHIP_LOG)
    n0 = page.evaluate("() => window.lmapdFrames.length")
    set_field(page, "distance_m", 650)
    wait_settled(page)
    generation = page.evaluate(JS_STATE, "frame_generation")
    frames = page.evaluate("(n0) => window.lmapdFrames.slice(n0)", n0)
    keys = [f["key"] for f in frames]
    # both pictures of the new value were drawn, the preview first
    assert keys[-2:] == [f"p{generation}", f"g{generation}"], keys
    assert frames[-2]["kind"] == "preview" and frames[-1]["kind"] == "preset"
    assert frames[-2]["t"] <= frames[-1]["t"]
    chips = page.evaluate("() => window.lmapdChips")
    assert "preview: 1 ray per pixel" in chips and chips[-1] == "interactive preset", chips
    assert page.locator(".frame-kind").inner_text().strip() == "interactive preset"
    # a pure detection change (TNR) recasts nothing: the frame comes at once, with no preview
    n1 = page.evaluate("() => window.lmapdFrames.length")
    set_field(page, "tnr", 4.5)
    wait_settled(page)
    kinds = page.evaluate("(n) => window.lmapdFrames.slice(n).map(f => f.kind)", n1)
    assert kinds and "preview" not in kinds


def test_clouds_and_images_arrive_as_binary_arrays(page, app_url):
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    found = page.evaluate(
        """() => {
          const s = window.trame.state, points = s.get('cloud_points').mesh.points;
          const image = s.get('array_image'), target = s.get('target_points');
          const img = document.querySelector('.array-image');
          return { points: points.bytes instanceof Uint8Array, dtype: points.dtype,
                   nbytes: points.bytes.byteLength, shape: points.shape,
                   png: image.png instanceof Uint8Array, target: target.bytes instanceof Uint8Array,
                   src: img.getAttribute('src'), loaded: img.complete && img.naturalWidth };
        }"""
    )
    assert found["points"] and found["target"] and found["png"]
    n, three = found["shape"]
    assert found["dtype"] == "float32" and three == 3 and found["nbytes"] == 12 * n
    assert found["src"].startswith("blob:") and found["loaded"] == page.evaluate(
        "() => window.trame.state.get('array_image').pixels"
    )
