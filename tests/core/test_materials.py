"""Eq. 6, the four-parameter BRDF: closed forms, Table 1, stability at grazing incidence."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from simcore.materials import LIBRARY, brdf, material_brdf, read_material_map


def eq6(theta, A, B, m, s):
    c = np.cos(theta)
    return A / c**6 * np.exp(-(np.tan(theta) ** 2) / s**2) + B * c**m


@pytest.mark.parametrize("name", ["solar_panel", "coating_1", "coating_2", "ideal_specular"])
@pytest.mark.parametrize("theta_deg", [0.0, 5.0, 20.0, 45.0, 70.0])
def test_eq6_matches_its_closed_form_for_table1_materials(name, theta_deg):
    mat = LIBRARY[name]
    theta = np.radians(theta_deg)
    expected = eq6(theta, mat.A, mat.B, mat.m, mat.s)
    assert material_brdf(np.cos(theta), mat) == pytest.approx(expected, rel=1e-12)


def test_table1_values_are_the_papers():
    assert (LIBRARY["solar_panel"].A, LIBRARY["solar_panel"].B) == (0.5, 0.03)
    assert (LIBRARY["solar_panel"].m, LIBRARY["solar_panel"].s) == (4.0, 0.05)
    assert (LIBRARY["coating_1"].A, LIBRARY["coating_1"].s) == (0.55, 0.25)
    assert (LIBRARY["coating_2"].B, LIBRARY["coating_2"].m) == (0.04, 3.0)


def test_lambertian_is_albedo_over_pi_at_every_angle():
    cos = np.cos(np.radians([0, 30, 60, 89]))
    assert np.allclose(material_brdf(cos, LIBRARY["lambertian"]), 1 / np.pi)


def test_back_faces_reflect_nothing():
    assert np.all(material_brdf(np.array([-1.0, -0.3, 0.0]), LIBRARY["coating_2"]) == 0.0)


@given(
    cos=st.floats(-1.0, 1.0),
    A=st.floats(0.0, 10.0),
    B=st.floats(0.0, 10.0),
    m=st.floats(0.0, 10.0),
    s=st.floats(0.01, 2.0),
)
def test_brdf_is_finite_and_non_negative_everywhere(cos, A, B, m, s):
    rho = brdf(cos, A, B, m, s)
    assert np.isfinite(rho) and rho >= 0.0


def test_brdf_falls_smoothly_to_zero_at_grazing_incidence_even_for_s_001():
    cos = np.cos(np.radians(np.linspace(80.0, 90.0, 2001)))
    rho = brdf(cos, 0.5, 0.0, 0.0, 0.01)
    assert np.all(np.isfinite(rho)) and np.all(rho >= 0)
    assert rho[-1] == 0.0
    assert np.all(np.diff(rho) <= 0)  # monotone towards grazing: no blow-up of 1/cos^6


def test_float32_input_gives_no_nan_at_and_past_pi_over_2():
    cos = np.cos(np.linspace(1.55, 1.6, 101, dtype=np.float32))
    assert np.all(np.isfinite(brdf(cos, 0.65, 0.04, 3.0, 0.15)))
    assert np.all(brdf(cos, 0.65, 0.04, 3.0, 0.15) >= 0)


def test_material_map_rejects_an_unknown_material_naming_it(tmp_path):
    path = tmp_path / "map.toml"
    path.write_text('[materials]\nfoil = "unobtanium"\n')
    with pytest.raises(ValueError, match="unobtanium"):
        read_material_map(path)
