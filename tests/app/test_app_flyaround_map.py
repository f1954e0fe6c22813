"""The fly-around's map (app.payloads.orbits, in the fly-around panel): not drawn for a single
frame; in fly-around mode the Earth, both orbits at their radius and the lidar's path around the
target, the dots where the frame's time puts them (the lidar's at the frame's distance)."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app

from app.payloads.orbits import N_TRACK, OrbitMap, relative_lvlh_m
from simcore import orbit


@pytest.fixture(scope="module")
def app():
    with small_app(pixels=32) as lmapd:
        yield lmapd


def traces(figure: dict) -> dict[str, dict]:
    return {t["name"]: t for t in figure["data"]}


def xy(trace: dict) -> np.ndarray:
    return np.column_stack([trace["x"], trace["y"]])


def test_a_single_frame_draws_no_map(app):
    change(app, mode="single")
    assert app.state.fly_map is None


def test_in_fly_around_mode_the_map_shows_the_earth_the_orbits_and_the_lidar_around_the_target(app):
    change(app, mode="flyaround", fly_t_s=1500.0)
    fig = traces(app.state.fly_map)
    earth = np.hypot(*xy(fig["Earth"]).T)
    assert np.allclose(earth, orbit.R_EARTH_M / 1e3, rtol=1e-4)
    for name, elements in (
        ("target's orbit", orbit.PAPER_TARGET),
        ("lidar's orbit", orbit.PAPER_IMAGING),
    ):
        radius_km = np.hypot(*xy(fig[name]).T)
        assert len(radius_km) == N_TRACK
        r, _ = orbit.propagate(elements, np.linspace(0.0, orbit.PAPER_PERIOD_S, N_TRACK))
        assert np.allclose(radius_km, np.linalg.norm(r, axis=1) / 1e3, atol=2e-3)  # in its plane
    # the lidar's dot: at the frame's distance from the target (the readout's 222.6 m)
    pose = app.logic.flyaround.poses.pose(False)
    i = app.logic.flyaround.poses.index_of(1500.0)
    (x, up) = xy(fig["lidar now"])[0]
    r_tgt, v_tgt = orbit.propagate(orbit.PAPER_TARGET, np.array([1500.0]))
    r_img, _ = orbit.propagate(orbit.PAPER_IMAGING, np.array([1500.0]))
    rel = relative_lvlh_m(r_tgt, v_tgt, r_img)[0]
    assert (x, up) == pytest.approx((rel[0], -rel[2]), abs=1e-3)
    assert np.linalg.norm(rel) == pytest.approx(pose.distance_m[i], rel=1e-9)
    assert app.state.fly_readout["distance"] == f"{np.linalg.norm(rel):.1f} m"


def test_the_dots_move_with_the_time_slider_and_the_tracks_stay(app):
    change(app, mode="flyaround", fly_t_s=0.0)
    before = traces(app.state.fly_map)
    change(app, fly_t_s=3000.0)
    after = traces(app.state.fly_map)
    assert after["target's orbit"] == before["target's orbit"]
    assert after["lidar around the target"] == before["lidar around the target"]
    assert after["target now"] != before["target now"] and after["lidar now"] != before["lidar now"]
    # half an orbit later (the period is about 6,000 s) the target is across the Earth
    (x0, y0), (x1, _) = xy(before["target now"])[0], xy(after["target now"])[0]
    assert x0 > 0 and abs(y0) < 1e-6 and x1 < 0


def test_the_relative_path_is_the_lidar_minus_the_target_in_the_targets_lvlh_frame():
    t = np.array([0.0, 700.0, 4100.0])
    r_tgt, v_tgt = orbit.propagate(orbit.PAPER_TARGET, t)
    r_img, _ = orbit.propagate(orbit.PAPER_IMAGING, t)
    rel = relative_lvlh_m(r_tgt, v_tgt, r_img)
    body = orbit.lvlh_attitude(r_tgt, v_tgt)
    assert np.allclose(np.einsum("nij,nj->ni", body, rel), r_img - r_tgt, atol=1e-6)
    assert np.allclose(np.linalg.norm(rel, axis=1), np.linalg.norm(r_img - r_tgt, axis=1))


def test_the_map_with_j2_is_its_own():
    m = OrbitMap()
    assert m.figure(1500.0, True)["data"] != m.figure(1500.0, False)["data"]
