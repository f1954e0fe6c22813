"""The Sun and the Earth in the 3D scene view: by night none; with a Sun an arrow towards each,
drawn outside the target and pointing where the Sun control's angles say (in the target's frame),
and a legend row each giving those angles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.app_helpers import change, small_app

from app.payloads import encode
from app.payloads.scene3d import ARROW_FROM, ARROW_TO, arrow_lines, azimuth_elevation_deg
from simcore.sun import direction_from_angles


@pytest.fixture(scope="module")
def app():
    with small_app() as lmapd:
        yield lmapd


def arrow_direction(app, name: str) -> np.ndarray:
    """The unit vector from an arrow's tail to its tip, in the target's mesh frame."""
    points = encode.decoded(app.state[f"{name}_arrow"]["mesh"]["points"]).reshape(-1, 3)
    along = points[1].astype(np.float64) - points[0]
    mesh = along @ app.engine.frame.rotation  # display -> mesh frame (a rotation)
    return mesh / np.linalg.norm(mesh)


def test_by_night_there_are_no_arrows_and_no_legend_rows(app):
    change(app, sun_mode="none")
    s = app.state
    assert s.sun_arrow is None and s.earth_arrow is None
    assert s.sun_text == "" and s.earth_text == ""


@pytest.mark.parametrize(("azimuth", "elevation"), [(20.0, 10.0), (-120.0, 55.0), (90.0, -30.0)])
def test_the_sun_arrow_points_where_the_controls_angles_say(app, azimuth, elevation):
    change(app, sun_mode="manual", sun_azimuth_deg=azimuth, sun_elevation_deg=elevation)
    body_from_mesh = app.engine.model.body_from_mesh
    sun_body = direction_from_angles(azimuth, elevation)
    assert np.allclose(body_from_mesh @ arrow_direction(app, "sun"), sun_body, atol=1e-5)
    earth_body = body_from_mesh @ arrow_direction(app, "earth")
    assert np.allclose(earth_body, [0.0, 0.0, 1.0], atol=1e-5)  # the Earth below: +z, the nadir
    assert app.state.sun_text.startswith(
        f"Sun: azimuth {azimuth:.0f}°, elevation {elevation:.0f}° (target frame)"
    )
    assert app.state.earth_text.startswith("Earth: ") and "km below" in app.state.earth_text


def test_an_arrow_lies_outside_the_target_with_its_head_at_the_far_end():
    center, direction, radius = np.array([1.0, -2.0, 0.5]), np.array([0.0, 3.0, 4.0]), 2.0
    points, segments = arrow_lines(center, direction, radius)
    distances = np.linalg.norm(points - center, axis=1)
    assert distances[0] == pytest.approx(ARROW_FROM * radius)
    assert distances[1] == pytest.approx(ARROW_TO * radius)
    assert np.allclose(
        (points[1] - points[0]) / np.linalg.norm(points[1] - points[0]), [0, 0.6, 0.8]
    )
    assert segments.tolist() == [[0, 1], [1, 2], [1, 3], [1, 4], [1, 5]]
    barbs = points[2:] - points[1]  # each barb goes back from the tip
    assert np.all(barbs @ np.array([0, 0.6, 0.8]) < 0)


@pytest.mark.parametrize(("azimuth", "elevation"), [(0.0, 0.0), (135.0, 40.0), (-45.0, -80.0)])
def test_the_legend_angles_invert_the_controls_direction(azimuth, elevation):
    az, el = azimuth_elevation_deg(direction_from_angles(azimuth, elevation))
    assert math.isclose(az, azimuth, abs_tol=1e-9) and math.isclose(el, elevation, abs_tol=1e-9)


def test_from_the_orbit_the_arrows_follow_the_sun_of_the_ephemeris(app):
    from simcore import sun

    change(app, sun_mode="orbit")
    scene = app.logic.last_frame.result.scene
    geo = sun.sun_geometry(scene)
    body_from_mesh = app.engine.model.body_from_mesh
    assert np.allclose(body_from_mesh @ arrow_direction(app, "sun"), geo.direction_body, atol=1e-5)
    earth = geo.earth_center_body_m / np.linalg.norm(geo.earth_center_body_m)
    assert np.allclose(body_from_mesh @ arrow_direction(app, "earth"), earth, atol=1e-5)
    az, el = azimuth_elevation_deg(geo.direction_body)
    assert f"azimuth {az:.0f}°, elevation {el:.0f}°" in app.state.sun_text
    assert ("Earth's shadow" in app.state.sun_text) == geo.eclipsed
