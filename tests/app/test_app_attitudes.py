"""The "Attitudes" panel (app.logic.attitudes, app.payloads.attitudes) without a browser: the map
of the scene over every attitude comes level by level at the light preset, each cell the frame
of its attitude; it is drawn equal-area, its colour scale names the metric and its unit, cells
where the target is not seen are "not seen" (never zero), the current attitude is marked; a
click moves the pose sliders; a new scene stops the map and never shows its results; a map over
the session's budget is refused with a message. The work is bounded by coarse levels (90 deg:
6 attitudes) and 16 x 16 pixel arrays."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.app_helpers import ANYTHING, change, settle, small_app

import simcore
from app.logic.attitudes import LIGHT_PIXELS, light_scene
from app.payloads.attitudes import (
    MAP_METRICS,
    attitude_figure,
    column_edges_deg,
    row_edges_deg,
    wrapped_deg,
)
from simcore.atlas import METRICS, attitude_grid, attitude_row

COARSE = (90.0,)  # 6 attitudes: the poles and four on the equator


@pytest.fixture(scope="module")
def app():
    with small_app(pixels=16) as lmapd:
        lmapd.logic.attitudes.levels_deg = COARSE
        yield lmapd


def wait_map(app, timeout_s: float = 60.0) -> None:
    """Wait until the map is done (or refused)."""
    deadline = time.monotonic() + timeout_s
    while app.state.attitudes_busy and time.monotonic() < deadline:
        time.sleep(0.01)
    assert app.logic.attitudes.runner.wait_idle(timeout_s)


def cells(figure: dict) -> dict[tuple[float, float], float | None]:
    """(pitch, azimuth) -> the value drawn, from the heatmap's cells."""
    heat = figure["data"][0]
    out = {}
    for z_row, c_row in zip(heat["z"], heat["customdata"], strict=True):
        for z, (pitch, azimuth) in zip(z_row, c_row, strict=True):
            out[(pitch, azimuth)] = z
    return out


@pytest.mark.slow
def test_the_map_comes_at_the_light_preset_each_cell_the_frame_of_its_attitude(app):
    assert app.logic.attitudes.level is None
    app.server.controller.trigger_fn("attitudes_compute")()
    # frames computed beside the map, on the same loaded target: a new pose keeps the map
    change(app, pitch_deg=-30.0, azimuth_deg=60.0)
    change(app, pitch_deg=10.0, azimuth_deg=20.0)
    wait_map(app)
    state, logic = app.state, app.logic.attitudes
    assert state.attitudes_message == "" and not state.attitudes_busy
    assert len(logic.level.grid) == 6 and logic.first_level_s is not None
    assert "90° grid, 6 attitudes at 16 × 16 px" in state.attitudes_status
    light = light_scene(app.logic.last_frame.result.scene)
    assert light.detector.pixels == min(16, LIGHT_PIXELS)
    pipe = simcore.Pipeline()
    drawn = cells(state.attitudes_map)
    for (pitch, azimuth), row in logic.level.rows.items():
        frame = simcore.with_overrides(light, pitch_deg=pitch, azimuth_deg=azimuth)
        assert row == attitude_row(pipe.run(frame))  # rows reproduced exactly
        assert drawn[(pitch, wrapped_deg(azimuth))] == row["n_target_points"]
    # the current attitude is marked; the colour scale names the metric and its unit
    marker = state.attitudes_map["data"][1]
    assert marker["name"] == "current attitude"
    assert marker["x"] == [20.0] and marker["y"] == [pytest.approx(math.sin(math.radians(10.0)))]
    title = state.attitudes_map["data"][0]["colorbar"]["title"]["text"]
    assert title == METRICS["n_target_points"][1] == "target points [-]"


def test_the_metric_chooser_redraws_the_map_and_refuses_what_it_does_not_offer(app):
    if app.logic.attitudes.level is None:
        app.server.controller.trigger_fn("attitudes_compute")()
        wait_map(app)
    rows = app.logic.attitudes.level.rows
    for metric in MAP_METRICS:
        change(app, wait_busy=False, attitudes_metric=metric)
        heat = app.state.attitudes_map["data"][0]
        assert heat["colorbar"]["title"]["text"] == METRICS[metric][1]
        column = METRICS[metric][0]
        for (pitch, azimuth), z in cells(app.state.attitudes_map).items():
            key = (pitch, 0.0) if abs(pitch) == 90 else (pitch, azimuth % 360.0)
            assert z == pytest.approx(rows[key][column], rel=1e-5)  # 6 digits drawn
    assert "F-score" in METRICS["f_score"][1] and "[m^2]" in METRICS["seen_area_m2"][1]
    for other in ("range_bias_m", ["f_score"], None, 3):
        change(app, wait_busy=False, attitudes_metric=other)
        assert app.state.attitudes_metric == "n_target_points"


def test_a_click_on_a_cell_moves_the_sliders_there_and_the_frame_follows_the_map_stays(app):
    if app.logic.attitudes.level is None:
        app.server.controller.trigger_fn("attitudes_compute")()
        wait_map(app)
    level = app.logic.attitudes.level
    app.server.controller.trigger_fn("attitudes_click")([0.0, -90.0])
    settle(app)
    assert (app.state.pitch_deg, app.state.azimuth_deg) == (0.0, -90.0)
    pose = app.logic.last_frame.result.scene.pose
    assert (pose.pitch_deg, pose.azimuth_deg) == (0.0, -90.0)
    assert app.logic.attitudes.level is level  # the same map: only its mark moved
    marker = app.state.attitudes_map["data"][1]
    assert marker["x"] == [-90.0] and marker["y"] == [0.0]
    # the grid's own 0-360 azimuth goes to the slider's range
    app.server.controller.trigger_fn("attitudes_click")([45.0, 270.0])
    settle(app)
    assert (app.state.pitch_deg, app.state.azimuth_deg) == (45.0, -90.0)


@settings(max_examples=10, deadline=None)
@given(args=st.lists(ANYTHING, max_size=3))
def test_a_click_with_anything_but_an_attitude_changes_nothing_and_never_raises(app, args):
    before = (app.state.pitch_deg, app.state.azimuth_deg)
    app.server.controller.trigger_fn("attitudes_click")(*args)
    real = [a for a in args if isinstance(a, int | float) and not isinstance(a, bool)]
    ok = len(args) == len(real) == 2 and all(abs(a) < 1e300 for a in real)
    if not (ok and abs(args[0]) <= 90 and -180 <= args[1] <= 360):
        assert (app.state.pitch_deg, app.state.azimuth_deg) == before
    app.logic.runner.wait_idle(30)


@pytest.mark.slow
def test_a_new_scene_stops_the_map_under_way_and_never_shows_it(app):
    with small_app(pixels=16, model=app.logic.engine.model) as lmapd:
        logic = lmapd.logic.attitudes
        logic.levels_deg = (90.0, 45.0, 22.5)  # stopped long before the finest
        shown: list[int] = []
        draw = logic._show_level
        logic._show_level = lambda epoch, level: (shown.append(len(level.grid)), draw(epoch, level))
        lmapd.server.controller.trigger_fn("attitudes_compute")()
        deadline = time.monotonic() + 60
        while lmapd.state.attitudes_map is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert lmapd.state.attitudes_map is not None  # the first level is on screen
        change(lmapd, pixels=20)  # a new scene (its map is another)
        assert logic.runner.wait_idle(60)
        time.sleep(0.05)
        assert lmapd.state.attitudes_map is None and logic.level is None
        assert "compute it again" in lmapd.state.attitudes_message
        assert not lmapd.state.attitudes_busy
        assert logic.runner.n_dropped == 1  # stopped through should_stop, its outcome dropped
        assert shown[0] == 6 and set(shown) <= {6, 26}  # the finest level (114) never came


def test_a_map_over_the_sessions_budget_is_refused_with_a_message(app):
    with small_app(pixels=16, model=app.logic.engine.model) as lmapd:
        logic = lmapd.logic.attitudes
        logic.levels_deg = COARSE
        logic.max_frame_s = 0.0  # any frame is too slow
        lmapd.server.controller.trigger_fn("attitudes_compute")()
        wait_map(lmapd)
        message = lmapd.state.attitudes_message
        assert message.startswith("Attitudes refused: one attitude of this scene takes")
        assert lmapd.state.attitudes_map is None and not lmapd.state.attitudes_busy
        logic.max_frame_s = 10.0
        lmapd.logic.engine.frame_budget_bytes = 1000  # a session with next to no memory
        lmapd.server.controller.trigger_fn("attitudes_compute")()
        wait_map(lmapd)
        assert "GB of memory" in lmapd.state.attitudes_message
        change(lmapd, mode="flyaround")  # its attitude comes from the orbit
        lmapd.server.controller.trigger_fn("attitudes_compute")()
        assert "Switch to Single frame" in lmapd.state.attitudes_message


# -- the figure, without a simulation --------------------------------------------------------------
@pytest.mark.parametrize("step_deg", [90.0, 45.0, 22.5, 11.25, 360.0 / 7.0])
def test_each_cell_of_the_map_has_the_area_of_its_solid_angle(step_deg):
    """Lambert's cylindrical equal-area projection: a cell's map area (degrees of azimuth times
    the sine of the pitch) times pi / 180 is its solid angle; the map's area is 4 pi sr."""
    grid = attitude_grid(step_deg)
    x_edges, azimuths = column_edges_deg(grid)
    y_edges = np.sin(np.radians(row_edges_deg(grid)))
    width_deg = np.diff(x_edges)
    assert x_edges[0] == -180 and x_edges[-1] == 180 and np.all(width_deg > 0)
    assert sorted(set(azimuths)) == sorted({a for p, a in grid.attitudes() if abs(p) != 90})
    total_sr = 0.0
    for i, pitch in enumerate(grid.pitch_deg):
        height = y_edges[i + 1] - y_edges[i]
        pole = abs(pitch) == 90.0
        per_cell: dict[float, float] = {}
        for w, a in zip(width_deg, azimuths, strict=True):  # a cell split at +-180: two parts
            per_cell[a] = per_cell.get(a, 0.0) + w * height * math.pi / 180.0
        drawn = [sum(per_cell.values())] if pole else list(per_cell.values())
        for area_sr in drawn:
            assert area_sr == pytest.approx(grid.solid_angle_sr(float(pitch)), rel=1e-9)
        total_sr += sum(drawn)
    assert total_sr == pytest.approx(4 * math.pi, rel=1e-9)


def row_of(points: int, recall: float | None, f_score: float | None = None) -> dict:
    return {
        "n_target_points": points,
        "quality.recall": recall,
        "quality.f_score": f_score,
        "seen_area_m2": 0.0 if recall is None else 3.0,
        "dominant_part": "bus" if points else None,
        "dominant_material": "foil" if points else None,
    }


def test_a_cell_where_the_target_is_not_seen_is_not_seen_not_zero():
    grid = attitude_grid(90.0)
    rows = {a: row_of(5, 0.5, 0.4) for a in grid.attitudes()}
    rows[(0.0, 90.0)] = row_of(0, None)  # nothing of the target in view
    rows[(0.0, 180.0)] = row_of(0, 0.0, 0.0)  # seen, but no point: a true zero
    for metric in MAP_METRICS:
        figure = attitude_figure(grid, rows, metric, (0.0, 0.0))
        drawn = cells(figure)
        assert drawn[(0.0, 90.0)] is None
        assert drawn[(0.0, 180.0)] == 0.0 if metric != "seen_area_m2" else 3.0
        text = figure["data"][0]["text"]
        flat = [t for r in text for t in r]
        assert sum("not seen" in t for t in flat) == 1
    assert figure["layout"]["plot_bgcolor"] == "#9e9e9e"  # what a cell without a value shows


def test_the_pole_is_one_cell_across_the_map_and_the_180_cell_is_at_both_edges():
    grid = attitude_grid(45.0)
    rows = {a: row_of(int(a[0] + 100 + a[1]), 0.5) for a in grid.attitudes()}
    figure = attitude_figure(grid, rows, "n_target_points")
    heat = figure["data"][0]
    assert set(heat["z"][0]) == {rows[(-90.0, 0.0)]["n_target_points"]}
    assert set(heat["z"][-1]) == {rows[(90.0, 0.0)]["n_target_points"]}
    middle = heat["z"][2]
    assert middle[0] == middle[-1] == rows[(0.0, 180.0)]["n_target_points"]
    assert heat["customdata"][2][0] == heat["customdata"][2][-1] == [0.0, 180.0]
    assert len(figure["data"]) == 1  # no current attitude given: no mark
