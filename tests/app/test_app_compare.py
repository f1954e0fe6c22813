"""Compare (app.logic.compare): a pinned frame's figures and cloud stay while anything changes,
side by side with the new frame's; unpin and a change of target drop them."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app

from app.logic import compare
from app.payloads import encode


@pytest.fixture()
def app():
    with small_app() as lmapd:
        yield lmapd


def decoded_points(mesh: dict) -> np.ndarray:
    """(n, 3) float32 points of a vtk.js mesh payload (app.payloads.cloud.points_mesh)."""
    return encode.decoded(mesh["mesh"]["points"]).reshape(-1, 3)


def test_nothing_is_pinned_at_start(app):
    assert app.state.pinned is None
    assert app.state.compare_rows == [] and app.state.pinned_cloud is None


def test_pin_then_change_shows_both_frames_figures_side_by_side(app):
    app.logic.pin_frame()
    pinned = app.logic.last_frame.summary
    assert app.state.pinned["label"].startswith("pitch 0°, azimuth 0°, 500 m, 48 px")
    rows = app.state.compare_rows
    assert [r["label"] for r in rows] == [c[0] for c in compare.COMPARED]
    assert all(r["pinned"] == r["now"] for r in rows)  # the same frame, before any change
    assert rows[0]["pinned"] == f"{pinned['n_points']:,d}" and rows[0]["change"] == "0"

    change(app, tnr=2.0)  # more false alarms, fewer dropped pixels
    now = app.logic.last_frame.summary
    rows = {r["label"]: r for r in app.state.compare_rows}
    assert app.state.pinned["label"].endswith("TNR 5")  # the pinned frame's scene, kept
    for label, key, kind in compare.COMPARED:
        assert rows[label]["pinned"] == compare.figure_text(pinned[key], kind)
        assert rows[label]["now"] == compare.figure_text(now[key], kind)
    d_outliers = now["n_outliers"] - pinned["n_outliers"]
    assert d_outliers > 0  # a lower threshold: more noise crossings (Eq. 31's Rice rate)
    assert rows["Outliers (false alarms)"]["change"] == f"{d_outliers:+,d}"


def test_the_pinned_cloud_is_the_pinned_frames_points_and_stays(app):
    app.logic.pin_frame()
    result = app.logic.last_frame.result
    pose = result.hits.pose
    expected = app.logic.engine.frame.from_sensor(result.points, pose.rotation, pose.translation_m)
    points = decoded_points(app.state.pinned_cloud)
    assert app.state.n_pinned_points == len(result.points) > 0
    assert np.array_equal(points, expected.astype(np.float32))
    change(app, distance_m=600.0)
    assert np.array_equal(decoded_points(app.state.pinned_cloud), points)
    assert app.logic.last_frame.summary["n_points"] != app.state.n_pinned_points


def test_unpin_and_a_new_target_drop_the_pinned_frame(app):
    app.logic.pin_frame()
    app.logic.compare.unpin()
    assert app.state.pinned is None and app.state.compare_rows == []
    change(app, pulse_energy_mj=2.0)
    assert app.state.compare_rows == []  # frames after an unpin add no table
    app.logic.pin_frame()
    app.logic.use_target(
        app.logic.base_scene, app.logic.engine, app.logic.initial_controls, "same again"
    )
    assert app.state.pinned is None and app.state.pinned_cloud is None


def test_pin_without_a_frame_is_a_message(app):
    app.logic.last_frame = None
    app.logic.pin_frame()
    assert app.state.pinned is None and "no frame" in app.state.error_message


def test_figures_and_changes_carry_their_units():
    assert compare.figure_text(0.00657, "sigma_m") == "0.657 cm"
    assert compare.change_text(0.01, 0.0125, "sigma_m") == "+0.25 cm"
    assert compare.figure_text(None, "snr") == "–" and compare.change_text(None, 3, "snr") == "–"
    assert compare.change_text(13750, 13617, "count") == "-133"
    assert compare.figure_text(float("nan"), "count") == "–"
