"""The calibration targets against their closed forms (docs/physics.md#calibration-targets): a
plate at normal incidence returns the lidar equation of a resolved Lambertian plane (Eq. 30), a
sphere spreads its echo by the depth distribution of its lit cap."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import constants as sc

import simcore
from simcore import echo
from simcore.calibration import SPHERE_RINGS, shape_mesh


@pytest.mark.parametrize(
    ("shape", "area", "extents"),
    [
        ("plate", 1.0, (1, 1, 0)),
        ("cube", 6.0, (1, 1, 1)),
        ("sphere", np.pi, (1, 1, 1)),
        ("cylinder", 1.5 * np.pi, (1, 1, 1)),  # 2 pi r h + 2 pi r^2, r = 1/2, h = 1
    ],
)
def test_a_shape_has_unit_size_and_its_area(shape, area, extents):
    vertices, faces = shape_mesh(shape)
    assert np.ptp(vertices, axis=0) == pytest.approx(extents)
    tri = vertices[faces]
    got = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    # an inscribed n-gon has sin(2 pi / n) / (2 pi / n) = 1 - (2 pi / n)^2 / 6 of its circle's
    # area: once around a cylinder, twice (along and across the rings) over a sphere
    n = 2 * SPHERE_RINGS if shape == "sphere" else 128
    facets = {"plate": 0, "cube": 0, "cylinder": 1, "sphere": 2}[shape]
    tolerance = facets * (2 * np.pi / n) ** 2 / 6
    assert got == pytest.approx(area, rel=tolerance, abs=1e-12)


def lidar_equation_peak_w(scene, rho_per_sr, range_m, cos_theta):
    """Unfiltered peak power from a resolved Lambertian plane filling one pixel (Eq. 30 with the
    flat-top irradiance of Eq. 5): E rho cos (R ifov)^2 eta_r A_r / R^2."""
    p_max_w = echo.A_FWHM * scene.laser.pulse_energy_j / (np.e * scene.laser.pulse_width_s)
    aperture_m2 = np.pi * scene.receive.aperture_diameter_m**2 / 4
    theta = scene.illumination_angle_rad
    irradiance = scene.transmit.transmittance * p_max_w * 4 / (np.pi * theta**2 * range_m**2)
    footprint_m2 = (range_m * scene.ifov_rad) ** 2
    return (
        irradiance
        * rho_per_sr
        * cos_theta
        * footprint_m2
        * scene.receive.transmittance
        * aperture_m2
        / range_m**2
    )


def test_the_plate_at_normal_incidence_gives_the_lidar_equation():
    scene = simcore.with_overrides(
        simcore.Scene(),
        {
            "target.mesh": "plate",
            "target.size_m": 4.0,
            "target.materials": {"*": "lambertian"},
            "pixels": 64,
            "fidelity.subrays": 1,
            "distance_m": 300.0,
            "paper_forms": ["unfiltered_peak"],
        },
    )
    result = simcore.Pipeline().run(scene)
    n = result.pixels
    flat = (n // 2) * n + n // 2
    i = int(np.searchsorted(result.echo.pixel, flat))
    direction = result.rays.pixel_directions[flat]
    range_m = 300.0 / direction[2]  # the plate has no thickness: its face is at 300 m
    expected = lidar_equation_peak_w(scene, 1 / np.pi, range_m, cos_theta=direction[2])
    got = result.echo.features.peak_raw_w_per_j[i] * scene.laser.pulse_energy_j
    assert got == pytest.approx(expected, rel=1e-6)


def waveform_moments(t_s, power_w):
    weight = power_w / power_w.sum()
    mean = (t_s * weight).sum()
    return mean, ((t_s - mean) ** 2 * weight).sum()


def test_the_sphere_spreads_its_echo_by_its_cap_depth_distribution():
    """One pixel sees a Lambertian sphere of radius a whole. A ring at depth z = a (1 - u) (u the
    cosine of incidence) has area 2 pi a dz and returns B u^2 per unit area (the irradiance's u,
    the projected area's u), so the echo's delays are distributed as u^2 on [0, 1]:
    E[u] = 3/4, var(u) = 3/5 - 9/16 = 3/80, and the echo's variance grows by (2 a / c)^2 3/80
    over the emitted pulse's; its mean lies a/4 behind the sphere's front."""
    radius_m, distance_m = 5.0, 500.0
    fov_rad = 2.1 * radius_m / distance_m
    scene = simcore.with_overrides(
        simcore.Scene(),
        {
            "target.mesh": "sphere",
            "target.size_m": 2 * radius_m,
            "target.materials": {"*": "lambertian"},
            "pixels": 1,
            "fidelity.subrays": 32 * 32,
            "receive.fov_rad": fov_rad,
            "laser.divergence_rad": 30 * fov_rad,  # the flat-top beam lights the sphere evenly
            "distance_m": distance_m,
        },
    )
    w = simcore.Pipeline().run(scene).waveform(0, 0)
    mean_s, var_s2 = waveform_moments(w.t_s, w.filtered_w)
    pulse_mean_s, pulse_var_s2 = waveform_moments(w.emitted_t_s, w.emitted_w)
    expected_var_s2 = (2 * radius_m / sc.c) ** 2 * 3 / 80
    # 32 x 32 sub-rays across 2.1 radii sample the disc every h = 0.066 a; a grid quadrature of a
    # weight with a square-root edge (the limb) errs by about (h / a)^1.5 = 1.7 %
    tolerance = (2.1 / 32) ** 1.5
    assert var_s2 - pulse_var_s2 == pytest.approx(expected_var_s2, rel=tolerance)
    front_s = 2 * (distance_m - radius_m) / sc.c
    assert mean_s - pulse_mean_s - front_s == pytest.approx(2 * radius_m / 4 / sc.c, rel=tolerance)
