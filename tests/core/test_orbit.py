"""Tests of simcore.orbit: Kepler, elements <-> state, propagation, attitudes, relative pose.

Reference values come from closed forms derived here and from published textbook examples
(Vallado, Fundamentals of Astrodynamics and Applications, Examples 2-4 and 2-5). Tolerances are
stated in units and derived from the physics or from double-precision rounding; none is tuned.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from simcore import orbit
from simcore.orbit import (
    MU_EARTH_M3_S2,
    PAPER_IMAGING,
    PAPER_PERIOD_S,
    PAPER_TARGET,
    R_EARTH_M,
    Elements,
    OrbitError,
    distance_stats,
    elements_to_state,
    flyaround_times,
    lvlh_attitude,
    propagate,
    relative_pose_series,
    solve_kepler,
    state_to_elements,
    tracking_attitude,
)

EPS = np.finfo(float).eps
KM = 1e3
MOLNIYA = Elements(26_600 * KM, 0.7, 63.4, 40.0, 270.0, 10.0)
ROTATION_TOL = 1e-12  # [-] matrix entries: products of a few unit vectors, ~100 ulp


def wrapped_deg(x: float) -> float:
    """Angle difference folded into [-180, 180) deg."""
    return (x + 180.0) % 360.0 - 180.0


def assert_rotations(m: np.ndarray) -> None:
    """Every (3, 3) matrix of ``m`` is orthonormal with determinant +1."""
    eye = np.broadcast_to(np.eye(3), m.shape)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", m, m), eye, atol=ROTATION_TOL)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=ROTATION_TOL)


# ----------------------------------------------------------------------------------------------
# Kepler's equation
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("e", [0.0, 1e-6, 0.1, 0.5, 0.9, 0.99])
def test_kepler_residual_is_below_1e_12_rad_over_a_grid_of_anomalies(e):
    m = np.concatenate([np.linspace(-2 * np.pi, 4 * np.pi, 2001), [0.0, np.pi, -np.pi, 1e-9]])
    ecc_anomaly = solve_kepler(m, e)
    assert np.max(np.abs(ecc_anomaly - e * np.sin(ecc_anomaly) - m)) < 1e-12


def test_kepler_with_zero_eccentricity_returns_the_mean_anomaly_exactly():
    m = np.linspace(-10.0, 10.0, 101)
    np.testing.assert_array_equal(solve_kepler(m, 0.0), m)


@settings(max_examples=300, deadline=None)
@given(
    m=st.floats(-100.0, 100.0, allow_nan=False),
    e=st.floats(0.0, 0.99, allow_nan=False),
)
def test_kepler_residual_is_below_1e_12_rad_for_any_anomaly_and_eccentricity(m, e):
    ecc_anomaly = float(solve_kepler(m, e))
    assert abs(ecc_anomaly - e * math.sin(ecc_anomaly) - m) < 1e-12
    assert abs(ecc_anomaly - m) <= math.pi  # same revolution as M


@pytest.mark.parametrize("e", [1.0, 1.5, -0.1, float("nan")])
def test_kepler_rejects_eccentricities_outside_zero_to_one(e):
    with pytest.raises(OrbitError, match="eccentricity"):
        solve_kepler(1.0, e)


# ----------------------------------------------------------------------------------------------
# Elements: validation and built-ins
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"eccentricity": 1.0}, "eccentricity"),
        ({"eccentricity": 2.5}, "eccentricity"),
        ({"eccentricity": -1e-3}, "eccentricity"),
        ({"semi_major_axis_m": R_EARTH_M}, "semi_major_axis_m"),
        ({"semi_major_axis_m": 7073.22}, "semi_major_axis_m"),  # kilometres by mistake
        ({"inclination_deg": 180.5}, "inclination_deg"),
        ({"inclination_deg": -1.0}, "inclination_deg"),
    ]
    + [({f.name: float("nan")}, f.name) for f in dataclasses.fields(Elements)]
    + [({f.name: float("inf")}, f.name) for f in dataclasses.fields(Elements)],
)
def test_invalid_elements_raise_an_orbit_error_naming_the_element(changes, named):
    with pytest.raises(OrbitError, match=named):
        dataclasses.replace(PAPER_TARGET, **changes)


def test_orbit_error_is_a_value_error():
    assert issubclass(OrbitError, ValueError)


def test_table_3_elements_are_in_metres_and_degrees():
    assert PAPER_TARGET.semi_major_axis_m == pytest.approx(7_073_220.0, abs=1e-6)
    assert PAPER_IMAGING.semi_major_axis_m == pytest.approx(7_073_220.0, abs=1e-6)
    assert PAPER_TARGET.raan_deg == 314.880 and PAPER_TARGET.arg_perigee_deg == 60.047
    assert PAPER_IMAGING.raan_deg == 314.881 and PAPER_IMAGING.arg_perigee_deg == 59.904


def test_two_body_period_of_table_3_is_within_five_seconds_of_the_papers():
    # T = 2 pi sqrt(a^3/mu) by hand; the paper's 5924.521 s comes from software with J2, whose
    # anomalistic period exceeds the two-body one by ~ (3/4) J2 (R/a)^2 (3 cos^2 i - 1) * T ~ 3.7 s.
    a = 7073.22e3
    assert PAPER_TARGET.period_s == pytest.approx(2 * math.pi * math.sqrt(a**3 / 3.986004418e14))
    assert 0.0 < PAPER_PERIOD_S - PAPER_TARGET.period_s < 5.0


# ----------------------------------------------------------------------------------------------
# Elements <-> state
# ----------------------------------------------------------------------------------------------
def test_state_to_elements_reproduces_vallado_example_2_5():
    # Vallado (4th ed.) Example 2-5: r, v in km and km/s -> p, a, e, i, RAAN, argp, nu. The book's
    # printed outputs agree with its printed inputs only to ~1e-6: h^2/mu from these r, v is
    # 11067.798 km (book: 11067.790) and i = 87.869 deg (book: 87.870). So the published values are
    # checked to 10 m and 0.01 deg, and the exact closed forms (h^2/mu, vis-viva, cos i = h_z/h)
    # to rounding.
    r_m = np.array([6524.834, 6862.875, 6448.296]) * KM
    v_m_s = np.array([4.901327, 5.533756, -1.976341]) * KM
    el = state_to_elements(r_m, v_m_s)
    e = el.eccentricity
    p_m = el.semi_major_axis_m * (1 - e**2)
    assert p_m == pytest.approx(11067.790 * KM, abs=10.0)
    assert el.semi_major_axis_m == pytest.approx(36127.343 * KM, abs=10.0)
    assert e == pytest.approx(0.832853, abs=1e-6)
    assert el.inclination_deg == pytest.approx(87.870, abs=0.01)
    assert el.raan_deg == pytest.approx(227.898, abs=0.01)
    assert el.arg_perigee_deg == pytest.approx(53.38, abs=0.01)
    ecc_anomaly = float(solve_kepler(math.radians(el.mean_anomaly_deg), e))
    nu = 2 * math.atan2(
        math.sqrt(1 + e) * math.sin(ecc_anomaly / 2), math.sqrt(1 - e) * math.cos(ecc_anomaly / 2)
    )
    assert math.degrees(nu) == pytest.approx(92.335, abs=0.01)
    h = np.cross(r_m, v_m_s)
    vis_viva_a_m = 1 / (2 / np.linalg.norm(r_m) - v_m_s @ v_m_s / MU_EARTH_M3_S2)
    assert p_m == pytest.approx(h @ h / MU_EARTH_M3_S2, rel=1e-12)
    assert el.semi_major_axis_m == pytest.approx(vis_viva_a_m, rel=1e-12)
    assert el.inclination_deg == pytest.approx(math.degrees(math.acos(h[2] / np.linalg.norm(h))))


def test_propagation_reproduces_vallado_example_2_4():
    # Vallado (4th ed.) Example 2-4 (KEPLER): 40 min of two-body motion; result printed to 0.1 m
    # and 1 mm/s per component, so the vector may differ by sqrt(3)/2 of that.
    r0_m = np.array([1131.340, -2282.343, 6672.423]) * KM
    v0_m_s = np.array([-5.64305, 4.30333, 2.42879]) * KM
    r_m, v_m_s = propagate(state_to_elements(r0_m, v0_m_s), [2400.0])
    r_ref_m = np.array([-4219.7527, 4363.0292, -3958.7666]) * KM
    v_ref_m_s = np.array([3.689866, -1.916735, -6.112511]) * KM
    assert np.linalg.norm(r_m[0] - r_ref_m) < math.sqrt(3) * 0.05
    assert np.linalg.norm(v_m_s[0] - v_ref_m_s) < math.sqrt(3) * 0.5e-3


def test_a_circular_orbit_follows_its_closed_form_position_and_speed():
    # e = 0: r(t) = a (cos u P + sin u Q) with u = argp + M0 + n t, speed sqrt(mu/a).
    el = dataclasses.replace(PAPER_TARGET, eccentricity=0.0)
    t = np.linspace(0.0, 2 * el.period_s, 97)
    r_m, v_m_s = propagate(el, t)
    a, i, o = el.semi_major_axis_m, math.radians(el.inclination_deg), math.radians(el.raan_deg)
    u = (
        math.radians(el.arg_perigee_deg + el.mean_anomaly_deg)
        + math.sqrt(MU_EARTH_M3_S2 / a**3) * t
    )
    node = np.array([math.cos(o), math.sin(o), 0.0])
    ahead = np.array([-math.sin(o) * math.cos(i), math.cos(o) * math.cos(i), math.sin(i)])
    expected_m = a * (np.cos(u)[:, None] * node + np.sin(u)[:, None] * ahead)
    # phase rounding of n*t ~ eps * n * t rad: a few ulp of a at most
    assert np.max(np.linalg.norm(r_m - expected_m, axis=1)) < 100 * EPS * a
    np.testing.assert_allclose(np.linalg.norm(v_m_s, axis=1), math.sqrt(MU_EARTH_M3_S2 / a))


@pytest.mark.parametrize("el", [PAPER_TARGET, MOLNIYA], ids=["table3", "molniya"])
def test_energy_and_angular_momentum_are_conserved_along_two_body_propagation(el):
    t = np.linspace(0.0, 3 * el.period_s, 301)
    r_m, v_m_s = propagate(el, t)
    energy = 0.5 * np.sum(v_m_s**2, axis=1) - MU_EARTH_M3_S2 / np.linalg.norm(r_m, axis=1)
    h = np.cross(r_m, v_m_s)
    # each state is evaluated afresh from the elements: errors are rounding, not accumulated
    np.testing.assert_allclose(energy, -MU_EARTH_M3_S2 / (2 * el.semi_major_axis_m), rtol=1e-12)
    h_ref = math.sqrt(MU_EARTH_M3_S2 * el.semi_major_axis_m * (1 - el.eccentricity**2))
    assert np.max(np.linalg.norm(h - h[0], axis=1)) < 1e-12 * h_ref
    np.testing.assert_allclose(np.linalg.norm(h, axis=1), h_ref, rtol=1e-12)


@pytest.mark.parametrize("el", [PAPER_TARGET, MOLNIYA], ids=["table3", "molniya"])
def test_the_state_returns_to_itself_after_one_period(el):
    (r0, r1), (v0, v1) = propagate(el, [0.0, el.period_s])
    # n * T = 2 pi up to a few ulp of the phase; position moves by speed * that / n
    assert np.linalg.norm(r1 - r0) < 1e3 * EPS * el.semi_major_axis_m
    assert np.linalg.norm(v1 - v0) < 1e3 * EPS * np.linalg.norm(v0)


def assert_same_state(a: Elements, b: Elements) -> None:
    """Both element sets give the same state to 1e-11 of a (rounding amplified by <= ~200)."""
    r_a, v_a = elements_to_state(a)
    r_b, v_b = elements_to_state(b)
    assert np.linalg.norm(r_a - r_b) < 1e-11 * a.semi_major_axis_m
    assert np.linalg.norm(v_a - v_b) < 1e-11 * np.linalg.norm(v_a)


@settings(max_examples=300, deadline=None)
@given(
    a=st.floats(R_EARTH_M + 200e3, 50_000e3),
    e=st.one_of(st.floats(0.0, 0.95), st.sampled_from([0.0, 1e-9, 1e-6, 1e-4])),
    i=st.one_of(st.floats(0.0, 180.0), st.sampled_from([0.0, 1e-6, 1e-3, 90.0, 180.0])),
    raan=st.floats(0.0, 360.0, exclude_max=True),
    argp=st.floats(0.0, 360.0, exclude_max=True),
    m=st.floats(0.0, 360.0, exclude_max=True),
)
def test_elements_survive_a_trip_through_the_state_vector(a, e, i, raan, argp, m):
    el = Elements(a, e, i, raan, argp, m)
    back = state_to_elements(*elements_to_state(el))
    assert_same_state(el, back)
    assert back.semi_major_axis_m == pytest.approx(a, rel=1e-11)
    assert back.eccentricity == pytest.approx(e, abs=1e-11)
    assert back.inclination_deg == pytest.approx(i, abs=1e-9)
    sin_i = math.sin(math.radians(i))
    if e > 1e-3 and sin_i > 1e-2:  # away from the singular cases every angle comes back
        tol_deg = math.degrees(1e-11 / min(e, sin_i))
        assert abs(wrapped_deg(back.raan_deg - raan)) < tol_deg
        assert abs(wrapped_deg(back.arg_perigee_deg - argp)) < tol_deg
        assert abs(wrapped_deg(back.mean_anomaly_deg - m)) < tol_deg


def test_a_circular_orbit_comes_back_with_zero_argp_and_the_argument_of_latitude():
    el = Elements(7000 * KM, 0.0, 51.6, 120.0, 60.0, 100.0)
    back = state_to_elements(*elements_to_state(el))
    assert back.eccentricity == 0.0
    assert back.arg_perigee_deg == 0.0
    assert back.raan_deg == pytest.approx(120.0, abs=1e-9)
    assert wrapped_deg(back.mean_anomaly_deg - 160.0) == pytest.approx(0.0, abs=1e-9)
    assert_same_state(el, back)


def test_an_equatorial_orbit_comes_back_with_zero_raan_and_the_longitude_of_perigee():
    el = Elements(8000 * KM, 0.1, 0.0, 30.0, 40.0, 50.0)
    back = state_to_elements(*elements_to_state(el))
    assert back.raan_deg == 0.0
    assert wrapped_deg(back.arg_perigee_deg - 70.0) == pytest.approx(0.0, abs=1e-9)
    assert wrapped_deg(back.mean_anomaly_deg - 50.0) == pytest.approx(0.0, abs=1e-9)
    assert_same_state(el, back)


def test_a_retrograde_equatorial_orbit_comes_back_with_argp_minus_raan():
    el = Elements(8000 * KM, 0.1, 180.0, 30.0, 40.0, 50.0)
    back = state_to_elements(*elements_to_state(el))
    assert back.raan_deg == 0.0
    assert wrapped_deg(back.arg_perigee_deg - 10.0) == pytest.approx(0.0, abs=1e-9)
    assert_same_state(el, back)


def test_a_circular_equatorial_orbit_comes_back_with_the_true_longitude():
    el = Elements(42_164 * KM, 0.0, 0.0, 100.0, 20.0, 30.0)
    back = state_to_elements(*elements_to_state(el))
    assert (back.raan_deg, back.arg_perigee_deg, back.eccentricity) == (0.0, 0.0, 0.0)
    assert wrapped_deg(back.mean_anomaly_deg - 150.0) == pytest.approx(0.0, abs=1e-9)


def test_a_near_equatorial_nearly_circular_orbit_keeps_its_node_and_perigee():
    # i = 1e-3 deg and e = 1e-6 are far above the 1e-12 singular thresholds: regular elements.
    el = Elements(7000 * KM, 1e-6, 1e-3, 200.0, 10.0, 20.0)
    back = state_to_elements(*elements_to_state(el))
    assert back.raan_deg == pytest.approx(200.0, abs=1e-6)
    assert back.arg_perigee_deg == pytest.approx(10.0, abs=1e-6)
    assert back.eccentricity == pytest.approx(1e-6, rel=1e-6)
    assert_same_state(el, back)


@pytest.mark.parametrize(
    ("v_scale", "named"), [(1.5, "eccentricity"), (0.0, "parallel")], ids=["open", "radial"]
)
def test_state_to_elements_rejects_open_and_rectilinear_states(v_scale, named):
    r_m, v_m_s = elements_to_state(PAPER_TARGET)
    v = v_m_s * v_scale if v_scale else r_m * 1e-3
    with pytest.raises(OrbitError, match=named):
        state_to_elements(r_m, v)


def test_state_to_elements_rejects_a_state_inside_the_earth():
    v_circ = math.sqrt(MU_EARTH_M3_S2 / 6000e3)
    with pytest.raises(OrbitError, match="semi_major_axis_m"):
        state_to_elements([6000e3, 0.0, 0.0], [0.0, v_circ, 0.0])


# ----------------------------------------------------------------------------------------------
# J2
# ----------------------------------------------------------------------------------------------
def test_an_800_km_orbit_at_98_6_deg_is_sun_synchronous_with_j2():
    # Published: a circular 800 km sun-synchronous orbit has i = 98.6 deg; its node must advance
    # 360 deg per tropical year. Rounding i to 0.05 deg changes the cos(i) rate by tan(i)*0.05 deg.
    el = Elements(R_EARTH_M + 800e3, 0.0, 98.6, 0.0, 0.0, 0.0)
    day_s = 86400.0
    r_m, v_m_s = propagate(el, [0.0, day_s], j2=True)
    h = np.cross(r_m, v_m_s)
    raan = np.arctan2(h[:, 0], -h[:, 1])
    drift_deg_per_day = math.degrees(raan[1] - raan[0])
    sun_deg_per_day = 360.0 / 365.2422
    rel_tol = abs(math.tan(math.radians(98.6))) * math.radians(0.05)
    assert drift_deg_per_day == pytest.approx(sun_deg_per_day, rel=rel_tol)


def test_without_j2_the_orbit_plane_stays_fixed():
    r_m, v_m_s = propagate(PAPER_TARGET, [0.0, 86400.0])
    h = np.cross(r_m, v_m_s)
    h_hat = h / np.linalg.norm(h, axis=1, keepdims=True)
    assert np.linalg.norm(h_hat[1] - h_hat[0]) < 1e-12


# ----------------------------------------------------------------------------------------------
# Attitudes
# ----------------------------------------------------------------------------------------------
def test_lvlh_axes_are_orthonormal_nadir_pointing_and_along_track():
    t = np.linspace(0.0, PAPER_TARGET.period_s, 50)
    r_m, v_m_s = propagate(PAPER_TARGET, t)
    m = lvlh_attitude(r_m, v_m_s)
    assert m.shape == (50, 3, 3)
    assert_rotations(m)
    r_hat = r_m / np.linalg.norm(r_m, axis=1, keepdims=True)
    h = np.cross(r_m, v_m_s)
    np.testing.assert_allclose(m[:, :, 2], -r_hat, atol=ROTATION_TOL)
    np.testing.assert_allclose(
        m[:, :, 1], -h / np.linalg.norm(h, axis=1, keepdims=True), atol=ROTATION_TOL
    )
    # x is the local horizontal: off the velocity by the flight-path angle, sin(gamma) <= e
    v_hat = v_m_s / np.linalg.norm(v_m_s, axis=1, keepdims=True)
    cos_gamma = np.sum(m[:, :, 0] * v_hat, axis=1)
    assert np.all(cos_gamma >= math.sqrt(1 - PAPER_TARGET.eccentricity**2) - ROTATION_TOL)


def test_lvlh_x_is_the_velocity_on_a_circular_orbit():
    r_m, v_m_s = elements_to_state(dataclasses.replace(PAPER_TARGET, eccentricity=0.0))
    m = lvlh_attitude(r_m, v_m_s)
    np.testing.assert_allclose(m[0, :, 0], v_m_s / np.linalg.norm(v_m_s), atol=ROTATION_TOL)


@settings(max_examples=200, deadline=None)
@given(
    offset=st.tuples(*[st.floats(-2000.0, 2000.0)] * 3).filter(lambda p: np.linalg.norm(p) > 1.0),
    m_deg=st.floats(0.0, 360.0),
)
def test_tracking_axes_are_orthonormal_look_at_the_target_and_put_the_earth_down(offset, m_deg):
    r_l, v_l = elements_to_state(dataclasses.replace(PAPER_TARGET, mean_anomaly_deg=m_deg))
    r_t = r_l + np.array(offset)
    s = tracking_attitude(r_l, r_t, v_l)
    assert_rotations(s)
    x, y, z = s[0].T
    np.testing.assert_allclose(z, (r_t - r_l) / np.linalg.norm(r_t - r_l), atol=ROTATION_TOL)
    nadir = -r_l / np.linalg.norm(r_l)
    if np.linalg.norm(np.cross(nadir, z)) > 1e-6:  # regular case
        assert y @ nadir > 0.0  # image "down" points towards the Earth
        assert abs(x @ nadir) < ROTATION_TOL  # image rows stay level: no roll about boresight


def test_tracking_falls_back_to_the_orbit_normal_when_the_target_is_straight_below():
    r_l, v_l = elements_to_state(PAPER_IMAGING)
    s = tracking_attitude(r_l, 0.99 * r_l, v_l)
    assert_rotations(s)
    h = np.cross(r_l, v_l)
    np.testing.assert_allclose(s[0][:, 2], -r_l / np.linalg.norm(r_l), atol=ROTATION_TOL)
    np.testing.assert_allclose(s[0][:, 1], -h / np.linalg.norm(h), atol=ROTATION_TOL)


def test_tracking_rejects_a_lidar_sitting_on_the_target():
    r_l, v_l = elements_to_state(PAPER_IMAGING)
    with pytest.raises(OrbitError, match="coincide"):
        tracking_attitude(r_l, r_l, v_l)


# ----------------------------------------------------------------------------------------------
# Relative pose
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def paper_pose():
    return relative_pose_series(PAPER_TARGET, PAPER_IMAGING, np.linspace(0, PAPER_PERIOD_S, 400))


def test_quaternion_and_matrix_describe_the_same_rotation(paper_pose):
    q = paper_pose.quaternion_wxyz
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
    from_q = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(from_q, paper_pose.rotation, atol=ROTATION_TOL)
    assert_rotations(paper_pose.rotation)
    assert q[0, 0] >= 0.0
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0.0)  # continuous signs for interpolation


def test_euler_angles_rebuild_the_rotation_as_intrinsic_xyz(paper_pose):
    angles = np.radians(paper_pose.angles_deg)
    rx = Rotation.from_rotvec(angles[:, 0, None] * [1, 0, 0]).as_matrix()
    ry = Rotation.from_rotvec(angles[:, 1, None] * [0, 1, 0]).as_matrix()
    rz = Rotation.from_rotvec(angles[:, 2, None] * [0, 0, 1]).as_matrix()
    np.testing.assert_allclose(rx @ ry @ rz, paper_pose.rotation, atol=ROTATION_TOL)
    # middle angle: sensor x is level in both nadir frames, off only by the nadir difference
    # between the two satellites, ~ distance / r
    nadir_difference_deg = math.degrees(300.0 / PAPER_TARGET.semi_major_axis_m)
    assert np.max(np.abs(paper_pose.angles_deg[:, 1])) < nadir_difference_deg


def test_the_target_origin_sits_on_the_boresight_at_the_distance(paper_pose):
    # p_sensor = R @ p_body + (0, 0, d); the lidar is at p_body = relative_position_lvlh_m, so the
    # target origin (p_body = 0) seen from it is R @ (-relative_position) = (0, 0, d).
    seen = np.einsum("nij,nj->ni", paper_pose.rotation, -paper_pose.relative_position_lvlh_m)
    expected = np.zeros_like(seen)
    expected[:, 2] = paper_pose.distance_m
    np.testing.assert_allclose(seen, expected, atol=1e-9)
    np.testing.assert_allclose(
        np.linalg.norm(paper_pose.relative_position_lvlh_m, axis=1), paper_pose.distance_m
    )


def test_body_points_map_to_the_sensor_frame_as_computed_in_eci():
    t = np.array([0.0, 1000.0, 4000.0])
    pose = relative_pose_series(PAPER_TARGET, PAPER_IMAGING, t)
    r_t, v_t = propagate(PAPER_TARGET, t)
    r_i, v_i = propagate(PAPER_IMAGING, t)
    body, sensor = lvlh_attitude(r_t, v_t), tracking_attitude(r_i, r_t, v_i)
    p_body = np.array([7.5, -5.1, 2.75])  # a corner of the 15 x 10.25 x 5.5 m target
    p_eci = r_t + np.einsum("nij,j->ni", body, p_body)
    p_sensor = np.einsum("nji,nj->ni", sensor, p_eci - r_i)
    expected = np.einsum("nij,j->ni", pose.rotation, p_body)
    expected[:, 2] += pose.distance_m
    np.testing.assert_allclose(p_sensor, expected, atol=1e-8)  # ~ulp of 7e6 m coordinates


def test_the_earth_is_down_in_the_image_of_a_nadir_pointing_target(paper_pose):
    body_z_in_sensor = paper_pose.rotation[:, :, 2]  # target's nadir axis in sensor coordinates
    assert np.all(np.abs(body_z_in_sensor[:, 0]) < 300.0 / PAPER_TARGET.semi_major_axis_m)
    assert np.all(body_z_in_sensor[:, 1] >= -1e-12)


def test_pose_arrays_are_read_only(paper_pose):
    with pytest.raises(ValueError):
        paper_pose.distance_m[0] = 0.0


# ----------------------------------------------------------------------------------------------
# Relative motion: the linearised (Clohessy-Wiltshire) solution in relative orbital elements
# ----------------------------------------------------------------------------------------------
def linear_relative_position_lvlh_m(chief: Elements, deputy: Elements, t_s: np.ndarray):
    """First-order relative position of ``deputy`` about a near-circular ``chief``, LVLH [m].

    Relative orbital elements (D'Amico 2010), dimensionless: da = (a_d - a_c)/a_c,
    dl = (u_d - u_c) + dRAAN cos i_c (u = argp + M), de = e_vec,d - e_vec,c with
    e_vec = e (cos argp, sin argp), di = (i_d - i_c, dRAAN sin i_c). With u the chief's mean
    argument of latitude at t (two-body), the Clohessy-Wiltshire solution reads, in radial,
    along-track and normal components:

        R = a (da - de_x cos u - de_y sin u)
        T = a (-3/2 da (u - u0) + dl + 2 de_x sin u - 2 de_y cos u)
        N = a (di_x sin u - di_y cos u)

    and LVLH = (T, -N, -R). Returns the (n, 3) positions and the norm of the ROE vector.
    """
    a = chief.semi_major_axis_m
    n = math.sqrt(MU_EARTH_M3_S2 / a**3)
    rad = math.radians
    u = rad(chief.arg_perigee_deg + chief.mean_anomaly_deg) + n * t_s
    d_raan = rad(deputy.raan_deg - chief.raan_deg)
    d_u = rad(
        deputy.arg_perigee_deg + deputy.mean_anomaly_deg
        - chief.arg_perigee_deg - chief.mean_anomaly_deg
    )  # fmt: skip
    roe = np.array(
        [
            (deputy.semi_major_axis_m - a) / a,
            d_u + d_raan * math.cos(rad(chief.inclination_deg)),
            deputy.eccentricity * math.cos(rad(deputy.arg_perigee_deg))
            - chief.eccentricity * math.cos(rad(chief.arg_perigee_deg)),
            deputy.eccentricity * math.sin(rad(deputy.arg_perigee_deg))
            - chief.eccentricity * math.sin(rad(chief.arg_perigee_deg)),
            rad(deputy.inclination_deg - chief.inclination_deg),
            d_raan * math.sin(rad(chief.inclination_deg)),
        ]
    )
    da, dl, dex, dey, dix, diy = roe
    radial = a * (da - dex * np.cos(u) - dey * np.sin(u))
    along = a * (-1.5 * da * n * t_s + dl + 2 * dex * np.sin(u) - 2 * dey * np.cos(u))
    normal = a * (dix * np.sin(u) - diy * np.cos(u))
    return np.stack([along, -normal, -radial], axis=-1), float(np.linalg.norm(roe))


def linearisation_error_bound_m(chief: Elements, deputy: Elements, roe_norm: float) -> float:
    """Error bound of the linear solution: a |d| (10 e + 6 |d|), |d| = ROE norm (~ separation/a).

    The solution keeps terms of first order in d with circular-orbit coefficients. The dropped
    terms are of second order in the small quantities e and |d|: from
    r/a = 1 - e cos M + e^2 (1 - cos 2M)/2 and theta = M + 2 e sin M + 5/4 e^2 sin 2M, per
    component (radial, along, normal) about (3, 8, 3) a e |d|; from the curvature of the
    along-track arc and the products of differences about (5, 3, 1) a |d|^2. Their root-sum-square
    is below 10 a e |d| + 6 a |d|^2.
    """
    e = max(chief.eccentricity, deputy.eccentricity)
    return chief.semi_major_axis_m * roe_norm * (10 * e + 6 * roe_norm)


@pytest.mark.parametrize(
    "deputy_changes",
    [
        None,  # Table 3 as printed: chief e = 1.5e-3, separation ~200 m
        {"eccentricity": 0.0},  # circular chief, eccentric deputy: only the |d|^2 terms remain
    ],
    ids=["table3", "circular-chief"],
)
def test_table_3_relative_motion_matches_the_linearised_solution(deputy_changes):
    chief, deputy = PAPER_TARGET, PAPER_IMAGING
    if deputy_changes:  # circular chief; keep the deputy's e vector difference ~1.4e-5
        chief = dataclasses.replace(PAPER_TARGET, **deputy_changes)
        u_deg = deputy.arg_perigee_deg + deputy.mean_anomaly_deg
        deputy = dataclasses.replace(
            deputy, eccentricity=1.4e-5, arg_perigee_deg=30.0, mean_anomaly_deg=u_deg - 30.0
        )
    t = np.linspace(0.0, 2 * chief.period_s, 1000)
    pose = relative_pose_series(chief, deputy, t)
    linear_m, roe_norm = linear_relative_position_lvlh_m(chief, deputy, t)
    bound_m = linearisation_error_bound_m(chief, deputy, roe_norm)
    error_m = np.linalg.norm(pose.relative_position_lvlh_m - linear_m, axis=1)
    assert np.max(error_m) < bound_m
    assert bound_m < 0.02 * np.min(pose.distance_m)  # the check is sharp: 2 % of the separation


def test_table_3_fly_around_averages_about_200_m_not_500_m():
    # Table 3 decides between the paper's 200 m (Section 2.2.2) and 500 m (Section 4.2).
    stats = distance_stats(PAPER_TARGET, PAPER_IMAGING, n=4000)
    t = np.linspace(0.0, PAPER_TARGET.period_s, 4000, endpoint=False)
    linear_m, roe_norm = linear_relative_position_lvlh_m(PAPER_TARGET, PAPER_IMAGING, t)
    linear_distance_m = np.linalg.norm(linear_m, axis=1)
    bound_m = linearisation_error_bound_m(PAPER_TARGET, PAPER_IMAGING, roe_norm)
    assert stats["min_m"] == pytest.approx(linear_distance_m.min(), abs=bound_m)
    assert stats["mean_m"] == pytest.approx(linear_distance_m.mean(), abs=bound_m)
    assert stats["max_m"] == pytest.approx(linear_distance_m.max(), abs=bound_m)
    assert stats["min_m"] <= stats["mean_m"] <= stats["max_m"]
    assert abs(stats["mean_m"] - 200.0) < abs(stats["mean_m"] - 500.0)


def test_j2_changes_the_table_3_distances_by_less_than_its_drift_over_one_orbit():
    # Both satellites feel nearly the same J2 drift. What changes: the chief's argument of latitude
    # gains (dargp/dt + dM/dt - n) t and the perigee turns by dargp/dt t, moving the phase along a
    # relative ellipse whose slope is at most 2 a |d|; the differential rates (from di, de) shift
    # it by a * |difference of rates| * t.
    t = np.linspace(0.0, PAPER_TARGET.period_s, 500)
    d_2body = relative_pose_series(PAPER_TARGET, PAPER_IMAGING, t).distance_m
    d_j2 = relative_pose_series(PAPER_TARGET, PAPER_IMAGING, t, j2=True).distance_m
    _, roe_norm = linear_relative_position_lvlh_m(PAPER_TARGET, PAPER_IMAGING, t)
    a = PAPER_TARGET.semi_major_axis_m
    n = math.sqrt(MU_EARTH_M3_S2 / a**3)
    tgt = orbit.j2_secular_rates_rad_s(PAPER_TARGET)
    img = orbit.j2_secular_rates_rad_s(PAPER_IMAGING)
    phase_rate = abs(tgt[1] + tgt[2] - n) + abs(tgt[1])
    differential_rate = sum(abs(p - q) for p, q in zip(tgt, img, strict=True))
    bound_m = (2 * a * roe_norm * phase_rate + a * differential_rate) * t
    assert np.all(np.abs(d_j2 - d_2body) <= bound_m + 1e-9)
    assert np.max(np.abs(d_j2 - d_2body)) > 0.0  # J2 does act


# ----------------------------------------------------------------------------------------------
# Times and their validation
# ----------------------------------------------------------------------------------------------
def test_the_paper_fly_around_images_every_300_s_over_one_orbit():
    t = flyaround_times()
    assert len(t) == 20  # 5924.521 s / 300 s = 19.7: 0, 300, ..., 5700 s
    np.testing.assert_array_equal(t, 300.0 * np.arange(20))


def test_fly_around_includes_the_end_when_the_duration_is_a_multiple_of_the_interval():
    np.testing.assert_array_equal(flyaround_times(100.0, 300.0), [0.0, 100.0, 200.0, 300.0])


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"duration_s": 0.0}, "duration_s"),
        ({"duration_s": -5.0}, "duration_s"),
        ({"duration_s": float("nan")}, "duration_s"),
        ({"interval_s": 0.0}, "interval_s"),
        ({"interval_s": float("inf")}, "interval_s"),
    ],
)
def test_zero_or_invalid_fly_around_durations_and_intervals_raise(kwargs, named):
    with pytest.raises(OrbitError, match=named):
        flyaround_times(**kwargs)


@pytest.mark.parametrize(
    ("t_s", "message"),
    [([], "empty"), ([0.0, float("nan")], "finite"), ([[0.0, 1.0]], "one-dimensional")],
)
def test_relative_pose_series_rejects_empty_or_bad_times(t_s, message):
    with pytest.raises(OrbitError, match=message):
        relative_pose_series(PAPER_TARGET, PAPER_IMAGING, t_s)


def test_a_single_time_gives_a_single_pose():
    pose = relative_pose_series(PAPER_TARGET, PAPER_IMAGING, 0.0)
    assert pose.rotation.shape == (1, 3, 3) and pose.quaternion_wxyz.shape == (1, 4)


@pytest.mark.parametrize("n", [0, -3, 2.5, True])
def test_distance_stats_rejects_a_bad_sample_count(n):
    with pytest.raises(OrbitError, match="n must"):
        distance_stats(PAPER_TARGET, PAPER_IMAGING, n=n)


def test_the_orbit_modules_import_only_numpy_scipy_the_standard_library_and_each_other():
    """Every module of the orbits package: numpy, scipy, the standard library's dataclasses and
    math, and its own modules (the package's lazy exports: importlib and typing; the epoch and
    TLE parsing of a scene: datetime, SGP4 and the library's SceneError, simcore.errors)."""
    import ast
    from pathlib import Path

    allowed = {"__future__", "dataclasses", "math", "numpy", "scipy"}
    extra = {
        "__init__": {"importlib", "typing"},
        "epoch": {"datetime"},
        "tle": {"datetime", "sgp4"},
    }
    files = sorted(Path(orbit.__file__).parent.glob("*.py"))
    assert {f.stem for f in files} >= {"__init__", "elements", "propagation", "attitude"}
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        roots = {
            alias.name.split(".")[0]
            for n in ast.walk(tree)
            if isinstance(n, ast.Import)
            for alias in n.names
        }
        roots |= {
            n.module.split(".")[0]
            for n in ast.walk(tree)
            if isinstance(n, ast.ImportFrom) and n.level == 0 and n.module
        }
        assert roots <= allowed | extra.get(path.stem, set()), path.name
        outside = {
            (n.level, n.module)
            for n in ast.walk(tree)
            if isinstance(n, ast.ImportFrom) and n.level > 1
        }
        assert outside <= ({(2, "errors")} if path.stem in ("epoch", "tle") else set()), path.name
