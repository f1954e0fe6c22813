"""The app in a real headless Chromium: the page loads and draws, the Distance slider changes the
point cloud, a click on the detector array draws that pixel's waveform, bad input is refused with a
message. Screenshots go to test-artifacts/."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image
from support.launch import JS_STATE, set_field, wait_first_frame, wait_settled

import simcore
from app.ui.views3d import BACKGROUND_RGB

pytestmark = pytest.mark.browser

CONSOLE_NOISE = ("405", "GPU stall", "Vue.use", "GL Driver Message")


def non_background_fraction(png: bytes, background=BACKGROUND_RGB, tolerance: int = 24) -> float:
    """Fraction of the pixels of a screenshot that differ from the background colour."""
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)
    differs = np.abs(rgb - np.array(background, np.int16)).max(axis=-1) > tolerance
    return float(differs.mean())


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def point_count(page) -> int:
    return int(page.locator(".point-count").inner_text().split()[0].replace(",", ""))


def drag_slider(page, key: str, dx_px: float) -> None:
    thumb = page.locator(f".slider-{key} .v-slider-thumb").first
    box = thumb.bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + dx_px, y, steps=4)
    page.mouse.up()


def detected_pixel_far_from(page, avoid: tuple[int, int]) -> tuple[int, int]:
    """A pixel the current scene detects on the target, at least 20 pixels from ``avoid``
    (simulated here with the page's own settings: same scene, same seed, same result)."""
    overrides = {
        "pixels": state(page, "pixels"),
        "distance_m": state(page, "distance_m"),
        "pitch_deg": state(page, "pitch_deg"),
        "azimuth_deg": state(page, "azimuth_deg"),
    }
    preset = state(page, "preset")
    if preset == "custom":
        overrides["fidelity.subrays"] = state(page, "subrays")
    else:
        overrides["preset"] = preset
    result = simcore.Pipeline().run(simcore.with_overrides(simcore.load_scene(), overrides))
    attrs = result.attributes
    rows, cols = attrs["row"][~attrs["is_outlier"]], attrs["col"][~attrs["is_outlier"]]
    # with its 8 neighbours detected too: below 1 CSS px per pixel a click may land next to it
    detected = np.zeros((result.pixels + 2, result.pixels + 2), dtype=int)
    detected[rows + 1, cols + 1] = 1
    shifts = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)]
    block = sum(detected[rows + 1 + dr, cols + 1 + dc] for dr, dc in shifts)
    far = (np.hypot(rows - avoid[0], cols - avoid[1]) >= 20) & (block == 9)
    i = int(np.flatnonzero(far)[len(np.flatnonzero(far)) // 2])
    return int(rows[i]), int(cols[i])


def click_pixel(page, row: int, col: int, shift: bool = False) -> None:
    """Click the centre of pixel (row, col) of the array image (with Shift: add it)."""
    image = page.locator(".array-image")
    box = image.bounding_box()
    n = state(page, "array_image")["pixels"]
    position = {"x": (col + 0.5) * box["width"] / n, "y": (row + 0.5) * box["height"] / n}
    image.click(position=position, modifiers=["Shift"] if shift else [])


def test_the_app_draws_reacts_to_the_distance_slider_and_shows_a_clicked_pixels_echo(
    page, app_url, artifacts_dir
):
    errors: list[str] = []
    page.on(
        "console",
        lambda m: (
            m.type == "error"
            and not any(s in m.text for s in CONSOLE_NOISE)
            and errors.append(m.text)
        ),
    )
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    page.screenshot(path=artifacts_dir / "app-loaded.png")

    assert page.title() == "lmapd-sim"
    # the page's own scripts and styles (app/static/, served by app.ui.static) loaded and applied
    assert page.evaluate(
        "() => ['lmapd', 'lmapdBin', 'lmapdLink', 'lmapdLesson']"
        ".every((name) => window.trame.utils[name])"
    )
    sheets = page.evaluate("() => [...document.styleSheets].map((s) => s.href || '')")
    for name in ("page.css", "markers.css", "glossary.css", "lessons.css"):
        assert sum(href.endswith(f"/{name}") for href in sheets) == 1, (name, sheets)
    assert page.locator(".scene-box").evaluate("(el) => getComputedStyle(el).borderRadius") == "4px"
    assert (
        "Courtesy NASA/JPL-Caltech (NASA 3D Resources)" in page.locator(".nasa-credit").inner_text()
    )
    for box in (".scene-box", ".cloud-box"):
        canvas = page.locator(f"{box} canvas").first
        drawn = non_background_fraction(canvas.screenshot())
        assert drawn > 0.02, f"the {box} 3D canvas is blank ({drawn:.2%} drawn)"

    # the Distance slider changes the point count
    before_points, before_distance = point_count(page), state(page, "distance_m")
    drag_slider(page, "distance_m", 40)
    wait_settled(page)
    after_distance = state(page, "distance_m")
    assert after_distance > before_distance
    assert point_count(page) != before_points
    page.screenshot(path=artifacts_dir / "app-after-distance.png")

    # clicking a pixel of the array draws its waveform; shift-click overlays a second one
    default = tuple(state(page, "selected_pixels")[0])
    aim = detected_pixel_far_from(page, default)
    click_pixel(page, *aim)
    page.wait_for_function(
        "(d) => { const s = window.trame.state.get('selected_pixels');"
        " return s.length === 1 && (s[0][0] !== d[0] || s[0][1] !== d[1]); }",
        arg=list(default),
        timeout=20_000,
    )
    [[row, col]] = state(page, "selected_pixels")
    assert abs(row - aim[0]) <= 1 and abs(col - aim[1]) <= 1  # the pixel clicked (or next to it)
    legend = page.locator(".waveform-box .legendtext")
    legend.filter(has_text=f"({row}, {col}) R = ").wait_for(timeout=20_000)
    traces = page.locator(".waveform-box .scatterlayer .trace")
    assert traces.count() >= 3  # received, unfiltered, emitted pulse (+ threshold)
    path = traces.first.locator("path.js-line").get_attribute("d")
    assert path and path.count("L") > 20, "the waveform line is not drawn"
    click_pixel(page, *default, shift=True)
    legend.filter(has_text=f"({default[0]}, {default[1]})").wait_for(timeout=20_000)
    assert state(page, "selected_pixels") == [[row, col], list(default)]
    page.locator(".waveform-card").screenshot(path=artifacts_dir / "app-waveforms.png")

    # the measuring cursor: plotly's click on the chart (as a click on a trace emits it) places A,
    # then B; a dashed line each on the chart, their difference in the readout
    chart = ".waveform-box .js-plotly-plot"
    for t_ns in (3335.64, 3344.81):
        page.evaluate(
            "([sel, x]) => document.querySelector(sel).emit('plotly_click', { points: [{ x }] })",
            [chart, t_ns],
        )
    readout = page.locator(".wave-cursor-text")
    readout.filter(has_text="B − A: 9.17 ns, 1.375 m in range").wait_for(timeout=10_000)
    assert readout.inner_text().startswith("A: 3,335.64 ns (500.")
    cursors = (
        f"() => document.querySelector('{chart}').layout.shapes.filter(s => s.name === 'cursor')"
    )
    page.wait_for_function(f"() => ({cursors})().length === 2", timeout=10_000)
    assert [s["x0"] for s in page.evaluate(cursors)] == [3335.64, 3344.81]
    page.locator(".wave-cursor-clear").click()
    page.wait_for_function(f"() => ({cursors})().length === 0", timeout=10_000)

    # a value outside the range is clamped, with a visible message and no stack trace
    set_field(page, "distance_m", 99999)
    message = page.locator(".input-message")
    message.wait_for(timeout=20_000)
    assert "outside 20 to 5000 m" in message.inner_text()
    page.wait_for_function("() => window.trame.state.get('distance_m') === 5000")
    wait_settled(page)
    assert "Traceback" not in page.content()
    page.screenshot(path=artifacts_dir / "app-clamped.png")
    assert not errors, f"console errors: {errors}"
