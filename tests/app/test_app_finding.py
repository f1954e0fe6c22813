"""Finding things on the detector array, without a browser: the multi-peak mode marks exactly the
pixels whose echo has two or more peaks (the double-peak lesson's among them), the readout of
the pixel under the pointer, and selected pixels that keep their direction when the pixel count
changes."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from support.app_helpers import ANYTHING, change, settle, small_app

import simcore
from app.engine import Engine
from app.logic.lessons import BY_KEY
from app.main import LmapdApp
from app.payloads import encode, image, waveforms
from simcore import reproduce
from simcore.geometry import subray_tangents


def png_rgb(png: bytes) -> np.ndarray:
    """(h, w, 3) uint8 pixels of a PNG file's bytes."""
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def brute_force_multi_peak(result: simcore.Result) -> set[int]:
    """Flat indices of the lit pixels whose band-limited echo has two or more peaks, every lit
    pixel counted with ``reproduce.n_peaks`` (no shortcut)."""
    e = result.echo
    return {int(p) for i, p in enumerate(e.pixel) if reproduce.n_peaks(e.waveform_per_j(i)[2]) >= 2}


@pytest.fixture(scope="module")
def lesson_app():
    """The app at its start-up scene (256 x 256), on the double-peak lesson."""
    scene = simcore.load_scene()
    app = LmapdApp(scene, engine=Engine(scene), flow_control=False, debounce_s=0.0)
    app.state.ready()
    settle(app)
    app.server.controller.trigger_fn("open_lesson")("double-peak")
    settle(app)
    yield app
    app.logic.runner.close()


def test_the_multi_peak_mode_marks_the_double_peak_lessons_pixels(lesson_app):
    lesson = BY_KEY["double-peak"]
    change(lesson_app, image_kind="multi_peak")
    shown = lesson_app.state.array_image
    marked = {tuple(p) for p in shown["multi_peak"]}
    assert {tuple(p) for p in lesson.selection} <= marked
    assert len(marked) == lesson.figures["n_double"]  # the lesson's card: 15 of the lit pixels
    rgb = png_rgb(shown["png"])
    assert rgb.shape == (256, 256, 3)
    magenta = np.all(rgb == image.MULTI_PEAK_RGB, axis=2)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(magenta), strict=True)} == marked
    lit = lesson_app.logic.last_frame.result.echo.pixel
    assert f"{len(marked):,} of {len(lit):,}" in shown["colorbar"]["title"]
    change(lesson_app, image_kind="range")
    assert "multi_peak" not in lesson_app.state.array_image


@pytest.mark.parametrize("pitch_deg", [0.0, 7.0])
def test_the_multi_peak_shortcut_finds_every_pixel_the_brute_force_count_finds(pitch_deg):
    """Only pixels whose delays span more than half the two-copy separation are counted peak
    by peak: every lit pixel counted gives the same set (coarse pixels, 16 sub-rays: many
    pixels see several depths)."""
    scene = simcore.with_overrides(
        simcore.load_scene(), {"pixels": 64, "fidelity.subrays": 16, "pose.pitch_deg": pitch_deg}
    )
    result = simcore.Pipeline().run(scene)
    found = set(image.multi_peak_pixels(result).tolist())
    assert found == brute_force_multi_peak(result)
    assert found  # the comparison sees some double peaks
    separation_s = image._two_peak_separation_s(result)
    pulse = result.echo.shape
    # two copies closer than the pulse's rise (half maximum to peak) never split
    assert separation_s > pulse.t_peak_s - pulse.t_half_s


def test_the_readout_gives_the_pointers_pixel_range_snr_and_peaks(lesson_app):
    (r, c), _ = BY_KEY["double-peak"].selection
    hover = lesson_app.server.controller.trigger_fn("pixel_hover")
    hover(r, c)
    readout = lesson_app.state.pixel_readout
    result = lesson_app.logic.last_frame.result
    i = int(np.searchsorted(result.echo.pixel, r * result.pixels + c))
    assert (readout["row"], readout["col"], readout["peaks"]) == (r, c, 2)
    assert readout["range_m"] == result.range_image_m[r, c]
    assert readout["snr"] == float(result.receiver.snr[i])
    assert f"({r}, {c})" in readout["text"] and "2 echo peaks" in readout["text"]
    hover(0, 0)  # a corner of the array sees nothing at 500 m
    assert lesson_app.state.pixel_readout["peaks"] == 0
    assert "no echo" in lesson_app.state.pixel_readout["text"]
    hover()  # the pointer left the image
    assert lesson_app.state.pixel_readout is None


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(args=st.lists(ANYTHING, max_size=3))
def test_the_hover_trigger_takes_anything_a_page_sends(lesson_app, args):
    lesson_app.server.controller.trigger_fn("pixel_hover")(*args)
    readout = lesson_app.state.pixel_readout
    assert readout is None or 0 <= readout["row"] < 256


def tangents_of(pixel, n: int, fov_rad: float) -> tuple[float, float]:
    """The centre tangents (x/f, y/f) of a pixel, from the core's grid."""
    tx, ty = subray_tangents(n, fov_rad, 1, np.array([pixel[0] * n + pixel[1]]))
    return float(tx.ravel()[0]), float(ty.ravel()[0])


def sees(pixel, tangents, n: int, fov_rad: float) -> bool:
    """Does ``pixel`` of the n x n array see the direction of ``tangents``?"""
    half_pitch = math.tan(fov_rad / 2.0) / n
    cx, cy = tangents_of(pixel, n, fov_rad)
    return abs(tangents[0] - cx) <= half_pitch * (1 + 1e-9) and abs(
        tangents[1] - cy
    ) <= half_pitch * (1 + 1e-9)


def test_selected_pixels_keep_their_direction_when_the_pixel_count_changes():
    with small_app(48) as app:
        fov_rad = app.logic.base_scene.receive.fov_rad
        app.logic.on_pixel_click(24, 30, False)
        app.logic.on_pixel_click(25, 31, True)
        clicked = [tangents_of(p, 48, fov_rad) for p in ([24, 30], [25, 31])]
        for n in (16, 96, 32, 48, 80, 48):
            change(app, pixels=n)
            chosen = app.state.selected_pixels
            assert all(any(sees(p, t, n, fov_rad) for p in chosen) for t in clicked), n
            assert len(chosen) == len({tuple(p) for p in chosen})
        # back on 48 x 48 after 16 x 16 (both clicks in one coarse pixel) and others: the
        # very pixels clicked, not the coarse pixel's centre
        assert app.state.selected_pixels == [[24, 30], [25, 31]]
        change(app, pixels=16)
        assert app.state.selected_pixels == [[8, 10]]
        app.logic.on_pixel_click(2, 3, False)  # a new click on the coarse array: its centre
        change(app, pixels=48)
        assert app.state.selected_pixels == [[7, 10]]


def test_rescaling_maps_pixel_centres_to_the_pixels_that_see_them():
    fov_rad = math.radians(1.72)
    for n_from, n_to in ((256, 64), (64, 256), (48, 96), (48, 17), (17, 256)):
        for pixel in ([0, 0], [n_from - 1, n_from - 1], [n_from // 3, n_from // 2 + 1]):
            (chosen,) = waveforms.rescale_selection([pixel], n_from, n_to)
            assert sees(chosen, tangents_of(pixel, n_from, fov_rad), n_to, fov_rad)


# -- the materials panel's part in the 3D scene ---------------------------------------------------
decoded = encode.decoded  # the numbers of an ``encode.typed_array``


def test_hovering_or_choosing_a_part_highlights_its_facets():
    with small_app(16) as app:
        s, model = app.state, app.logic.engine.model
        with s:
            s.part_chosen = "lens"
        assert s.highlight_part == "lens"
        with s:
            s.part_hover = "foil"  # the pointer over another row wins while it stays there
        assert s.highlight_part == "foil"
        cells = decoded(s.highlight_cells).reshape(-1, 4).astype(np.int64)
        foil = model.mesh.faces[model.face_part == model.part_names.index("foil")]
        assert np.all(cells[:, 0] == 3) and np.array_equal(cells[:, 1:], foil)
        with s:
            s.part_hover = None  # the pointer left: the chosen part again
        assert s.highlight_part == "lens"
        assert len(decoded(s.highlight_cells)) == 4 * 44  # the lens: 44 facets
        with s:
            s.part_chosen = "not a part"
        assert s.highlight_part == "" and s.highlight_cells == []


@pytest.fixture(scope="module")
def tiny_app():
    with small_app(16) as app:
        yield app


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(hover=ANYTHING, chosen=ANYTHING)
def test_the_part_highlight_takes_anything_a_page_sends(tiny_app, hover, chosen):
    with tiny_app.state:
        tiny_app.state.update({"part_hover": hover, "part_chosen": chosen})
    assert tiny_app.state.highlight_part in ("", *tiny_app.logic.engine.model.part_names)


# -- the 3D scene camera and the field of view ----------------------------------------------------
def angle_from_axis_deg(points: np.ndarray, camera: dict) -> np.ndarray:
    """Angles [deg] of display-frame points from the camera's line of sight."""
    position, focal = np.array(camera["position"]), np.array(camera["focalPoint"])
    axis = (focal - position) / np.linalg.norm(focal - position)
    rays = points - position
    cos = rays @ axis / np.linalg.norm(rays, axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


@pytest.mark.parametrize("distance_m", [50.0, 500.0, 1000.0, 3000.0, 5000.0])
def test_the_scene_camera_keeps_the_field_of_view_readable_at_any_distance(tiny_app, distance_m):
    """The footprint at the target lies inside the scene camera's view (30 deg), and it or the
    target fills a fifth of it (the fixed camera had the footprint's corners outside from 390 m
    and its whole rectangle from 550 m: at 3 km only the boresight crossed the view)."""
    with contextlib.nullcontext(tiny_app) as app:
        change(app, distance_m=distance_m)
        camera = app.state.scene_camera
        points = decoded(app.state.frustum["mesh"]["points"]).astype(np.float64)
        half_view_deg = camera["viewAngle"] / 2.0
        assert np.all(angle_from_axis_deg(points[8:12], camera) < half_view_deg)
        footprint = points[8:12]  # the rectangle at the target's distance
        side_m = np.linalg.norm(footprint[1] - footprint[0])
        assert side_m == pytest.approx(2 * distance_m * math.tan(0.015), rel=1e-5)
        camera_m = np.linalg.norm(np.array(camera["position"]) - camera["focalPoint"])
        shown_m = max(side_m, 2 * app.logic.engine.frame.radius_m)
        assert 2 * math.degrees(math.atan(shown_m / 2 / camera_m)) > camera["viewAngle"] / 5
        # the frustum keeps its shape: as deep as it is wide, or deeper
        depth_m = np.linalg.norm(points[12] - points[13])
        assert depth_m >= min(side_m, 3.7 * app.logic.engine.frame.radius_m)


def test_the_scene_view_is_reframed_when_the_scale_changes(tiny_app, monkeypatch):
    calls = []
    monkeypatch.setattr(tiny_app.server, "js_call", lambda *args: calls.append(args))
    change(tiny_app, distance_m=500.0)
    calls.clear()
    change(tiny_app, distance_m=510.0)  # the same scale: the user's camera stays
    assert calls == []
    change(tiny_app, distance_m=3000.0)
    assert calls == [("scene_view", "setCamera", tiny_app.state.scene_camera)]
