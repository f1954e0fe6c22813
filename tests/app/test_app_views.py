"""What each view draws, checked on real results without a browser: typed arrays decode to the
input, the 3D scene greys hidden facets, the frustum spans the field of view, the cloud keeps
outliers apart, the array image is n x n, the waveform chart shows what the issue lists."""

from __future__ import annotations

import io
import math
import time

import msgpack
import numpy as np
import pytest
from PIL import Image

import simcore
from app.engine import Engine, Request
from app.payloads import cloud, encode, image, scene3d, stats, style, waveforms


@pytest.fixture(scope="module")
def engine():
    return Engine(simcore.load_scene())


@pytest.fixture(scope="module")
def scene():
    return simcore.with_overrides(simcore.load_scene(), {"pixels": 64})


@pytest.fixture(scope="module")
def frame(engine, scene):
    return engine.compute(Request(scene))


decoded = encode.decoded


def test_typed_arrays_travel_as_raw_bytes_and_decode_to_the_same_values_and_dtype():
    for values in (
        np.arange(12, dtype=np.uint32).reshape(4, 3),
        np.linspace(0, 1, 5, np.float32),
        np.arange(7, dtype=np.uint16),
    ):
        typed = encode.typed_array(values)
        assert np.array_equal(decoded(typed), values) and decoded(typed).dtype == values.dtype
        assert typed["dtype"] == values.dtype.name and typed["shape"] == list(values.shape)
        # msgpack carries bytes as binary: the packed payload is the raw values plus a small head
        assert isinstance(typed["bytes"], bytes) and len(typed["bytes"]) == values.nbytes
        assert len(msgpack.packb(typed)) < values.nbytes + 64
    assert encode.typed_array(np.zeros(0, np.float32)) == []
    with pytest.raises(TypeError):
        encode.typed_array(np.zeros(3, np.int64))


def test_the_colour_bar_gradient_ends_on_the_colours_of_the_extremes():
    lut = encode.colormap_lut("viridis")
    gradient = encode.css_gradient("viridis")
    assert gradient.startswith(f"linear-gradient(to right, {encode.hex_color(lut[0])}")
    assert gradient.endswith(f"{encode.hex_color(lut[255])})")
    colors = encode.colors_of(np.array([0.0, 1.0, np.nan]), "viridis")
    assert np.array_equal(colors, lut[[0, 255, 0]])


def test_si_text_picks_the_prefix():
    assert encode.si_text(3.2e-7, "W") == "320 nW"
    assert encode.si_text(4.1e-3, "W") == "4.1 mW"
    assert encode.si_text(float("nan"), "W") == "–"


def test_the_display_frame_keeps_the_target_mesh_rigid_and_centred(engine):
    frame = engine.frame
    assert np.allclose(frame.rotation @ frame.rotation.T, np.eye(3))
    assert np.linalg.det(frame.rotation) == pytest.approx(1.0)
    vertices = frame.from_target(engine.model.mesh.vertices)
    assert np.allclose(vertices.min(axis=0), -vertices.max(axis=0), atol=1e-6)


def test_target_points_land_on_the_mesh_in_the_display_frame(engine, frame):
    """A target point, taken from the sensor frame to the display frame, lies on the target:
    within the mesh's box and within a few range sigmas of a vertex."""
    result = frame.result
    pose = result.hits.pose
    target = ~result.attributes["is_outlier"]
    points = engine.frame.from_sensor(result.points[target], pose.rotation, pose.translation_m)
    vertices = engine.frame.from_target(engine.model.mesh.vertices)
    lo, hi = vertices.min(axis=0) - 0.2, vertices.max(axis=0) + 0.2
    assert np.all((points >= lo) & (points <= hi))


def test_the_seen_facets_are_drawn_in_their_material_colours_over_the_grey_target(frame, engine):
    mesh = frame.seen_facets
    model = frame.result.target
    visible = frame.result.visible_faces
    points = decoded(mesh["mesh"]["points"])
    cells = decoded(mesh["mesh"]["polys"]).reshape(-1, 4)
    colors = decoded(mesh["field"]["values"])
    assert mesh["field"]["location"] == "CellData"
    assert len(cells) == len(colors) == len(visible) and np.all(cells[:, 0] == 3)
    triangles = points[cells[:, 1:]]
    expected = engine.frame.from_target(model.mesh.vertices)[model.mesh.faces[visible]]
    assert np.allclose(triangles, expected, atol=1e-5)
    names = np.array(simcore.MATERIAL_NAMES)[model.face_material_library[visible]]
    assert np.array_equal(colors, [encode.rgb_of(scene3d.material_color(n)) for n in names])


def test_the_legend_counts_every_facet_once(frame):
    legend = frame.legend
    total = sum(row["total"] for row in legend if row["name"] != "hidden")
    seen = sum(row["seen"] for row in legend if row["name"] != "hidden")
    hidden = next(row for row in legend if row["name"] == "hidden")
    assert total == hidden["total"] == len(frame.result.target.mesh.faces)
    assert seen + hidden["seen"] == total
    assert {row["name"] for row in legend} >= {"solar_panel", "coating_1", "coating_2"}


def test_the_seen_facets_are_reused_while_the_hits_and_materials_stay(engine, scene):
    a = engine.compute(Request(scene))
    b = engine.compute(Request(simcore.with_overrides(scene, {"tnr": 7})))
    c = engine.compute(Request(simcore.with_overrides(scene, {"distance_m": 520})))
    d = engine.compute(
        Request(simcore.with_overrides(scene, {"target.materials": {"foil": "lambertian"}}))
    )
    assert a.faces_key == b.faces_key and a.seen_facets is b.seen_facets
    assert c.faces_key != a.faces_key and d.faces_key != a.faces_key


def test_a_computation_overtaken_by_a_newer_request_skips_the_views(engine, scene):
    from app.runner import StaleRequest

    with pytest.raises(StaleRequest):
        engine.compute(Request(scene), stale=lambda: True)


def test_the_frustum_spans_the_field_of_view_at_the_target_distance():
    fov = 0.03
    points, segments = scene3d.frustum_sensor(fov, 500.0, 9.0)
    footprint = points[8:12]
    assert np.allclose(footprint[:, 2], 500.0)
    assert np.allclose(np.abs(footprint[:, :2]), 500.0 * math.tan(fov / 2))
    assert segments.max() < len(points) and len(segments) == 9
    close, _ = scene3d.frustum_sensor(fov, 20.0, 9.0)
    assert np.allclose(close[:4], 0.0)  # the lidar itself is the apex when it is close


def test_the_cloud_view_splits_target_points_from_outliers(frame):
    cloud = frame.cloud
    attrs = frame.result.attributes
    assert cloud["n_outliers"] == int(attrs["is_outlier"].sum()) > 0
    assert cloud["n_target"] + cloud["n_outliers"] == len(frame.result.points)
    points = decoded(cloud["points"]["mesh"]["points"])
    rgb = decoded(cloud["points"]["field"]["values"])
    verts = decoded(cloud["points"]["mesh"]["verts"])
    assert points.shape == (cloud["n_target"], 3) and rgb.shape == (cloud["n_target"], 3)
    assert verts[0] == cloud["n_target"] and np.array_equal(verts[1:], np.arange(verts[0]))
    red = decoded(cloud["outliers"]["field"]["values"])
    assert np.all(red == encode.rgb_of(style.OUTLIER_COLOR))
    assert cloud["colorbar"]["title"] == "Range"


@pytest.mark.parametrize("color_by", ["range", "snr", "outlier", "range_error", "part"])
def test_every_colouring_gives_one_colour_per_target_point(frame, color_by):
    result = frame.result
    target = ~result.attributes["is_outlier"]
    rgb, bar = cloud.point_colors(result, target, color_by)
    assert rgb.shape == (int(target.sum()), 3) and rgb.dtype == np.uint8
    assert (bar is None) == (color_by == "outlier")


def test_range_error_colours_are_symmetric_about_the_truth(frame):
    result = frame.result
    target = ~result.attributes["is_outlier"]
    error_m = result.attributes["range_error_m"][target]
    rgb, bar = cloud.point_colors(result, target, "range_error")
    assert bar["title"].startswith("Range error")
    assert (
        bar["lo"].startswith("-") and bar["hi"].startswith("+") and bar["lo"][1:] == bar["hi"][1:]
    )
    lut = encode.colormap_lut(style.ERROR_CMAP)
    # the point nearest its truth is drawn in the map's middle colour (within one step of it)
    centre = rgb[np.argmin(np.abs(error_m))].astype(int)
    assert (
        np.abs(centre - lut[128].astype(int)).max() <= np.abs(lut[129].astype(int) - lut[127]).max()
    )


def test_points_of_one_part_share_one_colour_and_two_parts_differ(frame):
    result = frame.result
    target = ~result.attributes["is_outlier"]
    part = result.attributes["part_id"][target]
    rgb, bar = cloud.point_colors(result, target, "part")
    assert bar["title"] == "Part"
    parts = np.unique(part)
    assert len(parts) >= 2
    colours = [np.unique(rgb[part == p], axis=0) for p in parts[:2]]
    assert all(len(c) == 1 for c in colours) and not np.array_equal(colours[0], colours[1])


def test_an_empty_point_set_is_one_hidden_point():
    mesh = cloud.points_mesh(np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    assert decoded(mesh["mesh"]["points"]).shape == (1, 3)


@pytest.mark.parametrize("kind", ["range", "peak_power"])
def test_the_array_image_is_n_by_n_with_row_zero_at_the_top(frame, kind):
    payload = image.array_image(frame.result, kind)
    png = payload["png"]
    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    n = frame.result.pixels
    assert pixels.shape == (n, n, 3) and payload["pixels"] == n
    no_echo = (
        ~np.isfinite(frame.result.range_image_m)
        if kind == "range"
        else (frame.result.peak_power_image_w <= 0)
    )
    assert np.all(pixels[no_echo] == style.NO_ECHO_RGB)
    assert np.any(pixels[~no_echo] != style.NO_ECHO_RGB)


def test_the_waveform_chart_shows_power_pulse_half_max_threshold_and_range(frame):
    pixel = waveforms.default_pixel(frame.result)
    figure = waveforms.waveform_figure(frame.result, [pixel])
    names = [trace["name"] for trace in figure["data"]]
    wave = frame.result.waveform(*pixel)
    assert names[0].startswith(f"({pixel[0]}, {pixel[1]}) R = {wave.range_m:.3f} m")
    assert "emitted pulse (delayed by 2R/c)" in names and "half-maximum time" in names
    assert any(n.startswith("threshold") for n in names)
    assert len(figure["layout"]["shapes"]) == 1  # the detected range
    received = figure["data"][0]
    assert len(received["x"]) == len(wave.t_s) > 10
    assert figure["layout"]["xaxis"]["title"]["text"] == "time since emission (ns)"


def test_several_pixels_overlay_in_their_own_colours(frame):
    attrs = frame.result.attributes
    target = ~attrs["is_outlier"]
    rows, cols = attrs["row"][target][:3], attrs["col"][target][:3]
    pixels = [[int(r), int(c)] for r, c in zip(rows, cols, strict=True)]
    figure = waveforms.waveform_figure(frame.result, pixels)
    first = [t for t in figure["data"] if t["name"].startswith("(")]
    assert len(first) == 3
    assert len({t["line"]["color"] for t in first}) == 3


def test_a_pixel_without_echo_says_so_and_no_selection_asks_for_a_click(frame):
    no_echo = np.argwhere(frame.result.peak_power_image_w <= 0)[0]
    figure = waveforms.waveform_figure(frame.result, [no_echo.tolist()])
    assert figure["data"][0]["name"].endswith("no echo")
    empty = waveforms.waveform_figure(frame.result, [])
    assert "Click a pixel" in empty["layout"]["annotations"][0]["text"]


def test_clicks_select_and_shift_clicks_toggle_pixels():
    assert waveforms.toggle_pixel([[1, 1]], [2, 2], add=False, limit=8) == [[2, 2]]
    assert waveforms.toggle_pixel([[1, 1]], [2, 2], add=True, limit=8) == [[1, 1], [2, 2]]
    assert waveforms.toggle_pixel([[1, 1], [2, 2]], [1, 1], add=True, limit=8) == [[2, 2]]
    assert waveforms.toggle_pixel([[0, i] for i in range(8)], [5, 5], True, 8)[-1] == [5, 5]
    assert len(waveforms.toggle_pixel([[0, i] for i in range(8)], [5, 5], True, 8)) == 8


def test_a_selection_follows_its_spot_when_the_array_size_changes():
    assert waveforms.rescale_selection([[127, 128], [0, 255]], 256, 64) == [[31, 32], [0, 63]]
    assert waveforms.rescale_selection([[10, 10], [11, 11]], 256, 16) == [[0, 0]]


def test_the_stats_panel_lists_counts_snr_and_stage_times(frame):
    labels = [row["label"] for row in frame.stats]
    for wanted in ("Points", "Outliers (false alarms)", "Dropped pixels (missed)", "Median SNR"):
        assert wanted in labels
    rows = stats.stage_rows({"hits": 0.012, "target": 0.0}, {"views (app)": 0.003})
    assert [r["stage"] for r in rows][: len(simcore.STAGES)] == list(simcore.STAGES)
    assert rows[0] == {"stage": "target", "ms": "cached", "cached": True}
    assert rows[2]["ms"] == "12.0" and rows[-1]["stage"] == "views (app)"
    histogram = frame.snr_histogram
    assert sum(histogram["data"][0]["y"]) == len(frame.result.receiver.snr)


def test_the_frame_shown_is_scored_against_the_true_target_on_demand():
    from support.app_helpers import settle, small_app

    with small_app(pixels=32) as app:
        assert app.state.quality_rows == []
        app.server.controller.trigger_fn("score_quality")()
        deadline = time.monotonic() + 60
        while app.state.quality_busy and time.monotonic() < deadline:
            time.sleep(0.02)
        rows = {r["label"]: r["value"] for r in app.state.quality_rows}
        q = app.logic.last_frame.result.quality
        assert rows["Precision (within 5 cm of the target)"] == f"{q['precision']:.1%}"
        assert rows["F-score"] == f"{q['f_score']:.3f}"
        # a new frame clears the score: it was the previous frame's
        with app.state:
            app.state.tnr = 4.0
        settle(app)
        assert app.state.quality_rows == []
