"""Eqs. 5, 29, 30: the lidar equation on plates, scaling with distance, conservation, double peaks
and spreading that come out of the geometry."""

import numpy as np
import pytest
import trimesh
from scipy import constants as sc

import simcore
from simcore import echo

HALF_THICKNESS_M = 0.5e-3  # the plates are 1 mm thick boxes: the lit face is 0.5 mm nearer


def centre_pixel_index(result):
    """Flat index in result.echo.pixel of the pixel nearest the boresight."""
    n = result.pixels
    flat = (n // 2) * n + n // 2
    return int(np.searchsorted(result.echo.pixel, flat)), flat


def lidar_equation_peak_w(scene, rho, range_m, cos_theta=1.0):
    """Unfiltered peak received power of a resolved Lambertian plate filling one pixel."""
    p_max = echo.A_FWHM * scene.laser.pulse_energy_j / (np.e * scene.laser.pulse_width_s)
    a_r = np.pi * scene.receive.aperture_diameter_m**2 / 4
    theta = scene.illumination_angle_rad
    irradiance = scene.transmit.transmittance * p_max * 4 / (np.pi * theta**2 * range_m**2)
    return (
        irradiance
        * rho
        * cos_theta
        * (range_m * scene.ifov_rad) ** 2
        * (scene.receive.transmittance * a_r / range_m**2)
    )


def test_eq30_lidar_equation_on_a_lambertian_plate_at_normal_incidence(plate_scene):
    scene = plate_scene(distance_m=300.0, paper_forms=["unfiltered_peak"])
    res = simcore.Pipeline().run(scene)
    i, flat = centre_pixel_index(res)
    d = res.rays.pixel_directions[flat]
    r = (300.0 - HALF_THICKNESS_M) / d[2]  # the centre pixel looks a hair off axis
    expected = lidar_equation_peak_w(scene, 1 / np.pi, r, cos_theta=d[2])
    got = res.echo.features.peak_raw_w_per_j[i] * scene.laser.pulse_energy_j
    assert got == pytest.approx(expected, rel=1e-6)


def test_band_limited_peak_of_a_plate_pixel_is_0857_of_the_unfiltered_one(plate_scene):
    res = simcore.Pipeline().run(plate_scene(distance_m=300.0, paper_forms=["unfiltered_peak"]))
    ratio = res.echo.features.peak_w_per_j / res.echo.features.peak_raw_w_per_j
    assert np.median(ratio) == pytest.approx(0.857, abs=1e-3)


def test_paper_eq30_is_4pi_lower_at_normal_incidence(plate_scene):
    ours = simcore.Pipeline().run(plate_scene(distance_m=300.0))
    paper = simcore.Pipeline().run(plate_scene(distance_m=300.0, paper_forms=["eq30_4pi"]))
    i, flat = centre_pixel_index(ours)
    cos = ours.rays.pixel_directions[flat][2]
    ratio = ours.receiver.peak_power_w[i] / paper.receiver.peak_power_w[i]
    assert ratio == pytest.approx(4 * np.pi * cos, rel=1e-9)


def test_received_power_of_a_resolved_plate_falls_as_one_over_r_squared(plate_scene):
    pipe = simcore.Pipeline()
    near = pipe.run(plate_scene(distance_m=200.0))
    far = pipe.run(plate_scene(distance_m=400.0))
    p_near = near.receiver.peak_power_w[centre_pixel_index(near)[0]]
    p_far = far.receiver.peak_power_w[centre_pixel_index(far)[0]]
    expected = ((400.0 - HALF_THICKNESS_M) / (200.0 - HALF_THICKNESS_M)) ** 2
    assert p_near / p_far == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("distance_m", [200.0, 400.0, 800.0])
def test_pixel_count_of_a_resolved_plate_falls_as_one_over_r_squared(plate_scene, distance_m):
    """A square of side L pixels, aligned with the grid, covers between (L-1)^2 and (L+1)^2
    pixel centres: with L = S / (R theta_ifov) that bounds the count at every distance.
    From 200 m on, the whole 4 m plate lies inside the 30 mrad illuminated disc. The receiver
    records every stop without dead time (K = 16, no hold-off): with the default first stop,
    noise before the echo masks about 1e-3 of the pixels at TNR 5 over the 1 km gate
    (tests/core/test_stops.py covers that)."""
    unlimited = {"timing.max_stops": 16, "timing.rearm_holdoff_fwhm": 0.0}
    scene = plate_scene(size_m=4.0, distance_m=distance_m, pixels=256, **unlimited)
    res = simcore.Pipeline().run(scene)
    pitch_m = distance_m * 2 * np.tan(scene.receive.fov_rad / 2) / 256
    side_px = 4.0 / pitch_m
    s = res.summary()
    assert (side_px - 1) ** 2 <= s["n_hit_pixels"] <= (side_px + 1) ** 2
    assert s["n_lit_pixels"] == s["n_hit_pixels"]
    assert s["p_detect_mean"] > 0.9999  # a bright plate: every lit pixel detected
    assert s["n_target_points"] == s["n_hit_pixels"]


def test_plate_corners_outside_the_illuminated_disc_get_no_light(plate_scene):
    """At 150 m the 30 mrad disc has a radius of 2.25 m: a 4 m plate's corners stay dark."""
    res = simcore.Pipeline().run(plate_scene(size_m=4.0, distance_m=150.0, pixels=128))
    s = res.summary()
    assert s["n_lit_pixels"] < s["n_hit_pixels"]
    lit = np.zeros(128 * 128, bool)
    lit[res.echo.pixel] = True
    dirs = res.rays.pixel_directions[lit]
    assert np.all(np.arccos(dirs[:, 2]) <= 0.015 + res.scene.ifov_rad)


def test_waveform_energy_equals_the_sum_of_element_energies(plate_scene):
    scene = plate_scene(distance_m=300.0, azimuth_deg=50.0, pixels=16, **{"fidelity.subrays": 16})
    res = simcore.Pipeline().run(scene)
    e = res.echo
    for i in (0, len(e.pixel) // 2, len(e.pixel) - 1):
        row, col = divmod(int(e.pixel[i]), res.pixels)
        wf = res.waveform(row, col)
        expected = scene.laser.pulse_energy_j * e.weights[i].sum()
        assert np.trapezoid(wf.power_w, wf.t_s) == pytest.approx(expected, rel=2e-3)
        assert np.trapezoid(wf.filtered_w, wf.t_s) == pytest.approx(expected, rel=2e-3)


def test_two_depths_in_one_pixel_give_a_double_peak(tmp_path):
    """Two plates 1.5 m apart in depth, the middle pixel row straddling their common edge."""
    a = trimesh.creation.box(extents=(2.0, 4.0, 1e-3))
    a.apply_translation((-1.0, 0.0, 0.0))
    b = trimesh.creation.box(extents=(2.0, 4.0, 1e-3))
    b.apply_translation((1.0, 0.0, 1.5))
    path = tmp_path / "step.obj"
    trimesh.util.concatenate([a, b]).export(path)
    scene = simcore.with_overrides(
        simcore.Scene(),
        {
            "target.mesh": str(path),
            "target.scale_m_per_unit": 1.0,
            "pixels": 65,
            "fidelity.subrays": 4,
            "distance_m": 200.0,
            "target.materials": {"*": "lambertian"},
        },
    )
    res = simcore.Pipeline().run(scene)
    wf = res.waveform(32, 32)
    y = wf.filtered_w
    peaks = np.flatnonzero((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:]) & (y[1:-1] > 0.2 * y.max())) + 1
    assert len(peaks) == 2
    separation = wf.t_s[peaks[1]] - wf.t_s[peaks[0]]
    dt = res.echo.dt_s
    assert separation == pytest.approx(2 * 1.5 / sc.c, abs=2 * dt)
    # a pixel well inside one plate has a single peak
    y1 = res.waveform(20, 32).filtered_w
    assert len(y1) > 0
    assert np.sum((y1[1:-1] > y1[:-2]) & (y1[1:-1] >= y1[2:])) == 1


def test_tilting_a_plate_spreads_the_echo_by_its_depth_extent(plate_scene):
    """The raw echo's variance in time is the pulse's plus the (weighted) variance of the element
    delays, which for a plate tilted by 60 deg follows from the plane and the sub-ray directions."""
    tilt = np.radians(60.0)
    scene = plate_scene(
        size_m=20.0, distance_m=500.0, azimuth_deg=60.0, pixels=16, **{"fidelity.subrays": 64}
    )
    res = simcore.Pipeline().run(scene)
    flat = 8 * 16 + 8
    wf = res.waveform(8, 8)
    # the plate plane: through (0, 0, R), normal tilted by 60 deg about the sensor y axis
    normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    dirs = res.rays.directions[flat]
    r = 500.0 * normal[2] / (dirs @ normal)
    delays = 2 * r / sc.c
    w = np.abs(dirs @ normal) / r**2  # Lambertian: rho cos(theta) / r^2 per sub-ray
    var_delays = np.average((delays - np.average(delays, weights=w)) ** 2, weights=w)
    t = np.arange(0, 200e-9, 1e-12)
    p0 = echo.pulse_power_w(t, 1.0, scene.laser.pulse_width_s)
    var_pulse = np.average((t - np.average(t, weights=p0)) ** 2, weights=p0)
    mean = np.average(wf.t_s, weights=wf.power_w)
    var_echo = np.average((wf.t_s - mean) ** 2, weights=wf.power_w)
    assert var_delays > var_pulse  # the tilt more than doubles the echo's variance
    assert var_echo == pytest.approx(var_pulse + var_delays, rel=0.01)
