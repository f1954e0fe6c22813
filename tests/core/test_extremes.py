"""Stability at the edges of the parameter space (docs/physics.md#numerical-care): no NaN or inf
ever reaches an output; what is invalid is refused with a clear message."""

import numpy as np
import pytest

import simcore
from simcore.pointcloud import GROUND_TRUTH
from simcore.scene import SceneError

PIPE = simcore.Pipeline()


def run(**overrides):
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 32, **overrides})
    return PIPE.run(scene)


def assert_finite(res):
    assert np.all(np.isfinite(res.points))
    false_alarm = np.asarray(res.attributes["is_outlier"], dtype=bool)
    for name, values in res.attributes.items():
        # a false alarm has no ground truth (NaN by design); every other value is finite
        truth = name in {n for n, _ in GROUND_TRUTH}
        rows = ~false_alarm if truth else slice(None)
        assert np.all(np.isfinite(values[rows].astype(float))), name
        if truth and values.dtype.kind == "f":
            assert np.all(np.isnan(values[false_alarm])), name
    for arr in (
        res.receiver.snr,
        res.detection.p_detect,
        res.detection.range_true_m,
        res.echo.features.peak_w_per_j,
    ):
        assert np.all(np.isfinite(arr))
    s = res.summary()
    for key in ("snr_median", "range_sigma_m_median", "p_detect_mean"):
        assert s[key] is None or np.isfinite(s[key])
    for key, value in s["quality"].items():  # the imaging-quality figures too
        if key != "parts":
            assert value is None or np.isfinite(value), key


@pytest.mark.parametrize("distance_m", [1.0, 5.0, 20.0, 500.0, 10_000.0, 100_000.0])
def test_distances_from_1_m_inside_the_target_to_100_km(distance_m):
    res = run(distance_m=distance_m)
    assert_finite(res)
    target = ~res.attributes["is_outlier"]
    # every target point lies within the target's reach of the lidar
    assert np.all(res.attributes["range_m"][target] < distance_m + res.target.radius_m + 1.0)


def test_a_lidar_inside_the_target_sees_its_inner_walls():
    res = run(distance_m=1.0, pixels=64)
    assert res.summary()["n_hit_pixels"] > 0
    assert_finite(res)


@pytest.mark.parametrize("energy_j", [1e-9, 1e-6, 1e-3, 1.0, 10.0])
def test_pulse_energy_from_1_nj_to_10_j(energy_j):
    res = run(pulse_energy_j=energy_j)
    assert_finite(res)
    if energy_j >= 1.0:  # Eq. 27 saturates; first stop: noise fires first at most 1 - e^-n_false
        survive_min = np.exp(-res.detection.n_false_per_pixel)
        assert res.summary()["p_detect_mean"] > 0.999 * survive_min


def test_a_saturation_ceiling_caps_the_snr():
    res = run(pulse_energy_j=10.0, **{"detector.snr_max": 50.0})
    assert res.receiver.snr.max() <= 50.0
    assert_finite(res)


@pytest.mark.parametrize("tnr", [0.5, 3.0, 10.0, 20.0])
def test_tnr_from_half_to_20(tnr):
    res = run(tnr=tnr, **{"timing.range_gate_m": 100.0})
    assert_finite(res)


def test_a_tnr_of_zero_over_a_long_gate_gives_one_stop_per_pixel_with_the_first_stop():
    res = run(tnr=0.0, pixels=256)  # 640 noise crossings per pixel: the first one is the stop
    assert_finite(res)
    assert res.summary()["n_points"] == 256**2
    assert np.bincount(res.attributes["row"] * 256 + res.attributes["col"]).max() == 1


def test_more_stops_than_the_simulator_draws_are_refused_with_the_reason():
    with pytest.raises(SceneError, match=r"timing.max_stops = 16 at timing.tnr = 0 gives"):
        run(tnr=0.0, pixels=1024, **{"timing.max_stops": 16})


def test_tnr_zero_on_a_short_gate_and_a_small_array_is_fine():
    res = run(tnr=0.0, pixels=8, **{"timing.range_gate_m": 10.0})
    assert_finite(res)
    assert res.summary()["n_outliers"] > 0


@pytest.mark.parametrize("pixels", [1, 2, 1024])
def test_one_to_1024_pixels_per_side(pixels):
    res = run(pixels=pixels, **{"fidelity.subrays": 1})
    assert_finite(res)
    assert res.summary()["n_pixels"] == pixels**2


@pytest.mark.parametrize("width_s", [0.1e-9, 1e-9, 20e-9, 100e-9])
def test_pulse_width_from_01_to_100_ns_with_an_adapting_time_step(width_s):
    res = run(**{"laser.pulse_width_s": width_s})
    assert res.echo.dt_s <= min(width_s / 10, 1 / (20 * 120e6)) * (1 + 1e-12)
    assert_finite(res)


def test_bias_approaching_breakdown_gives_a_huge_but_finite_gain():
    res = run(
        **{
            "detector.gain_from": "bias",
            "detector.bias_voltage_v": 399.999,
            "detector.breakdown_voltage_v": 400.0,
        }
    )
    assert res.receiver.model.gain > 1e4
    assert_finite(res)


@pytest.mark.parametrize("azimuth_deg", [89.0, 89.99, 90.0])
def test_plates_at_and_near_grazing_incidence(plate_scene, azimuth_deg):
    res = simcore.Pipeline().run(plate_scene(azimuth_deg=azimuth_deg, distance_m=100.0))
    assert_finite(res)
    assert np.all(res.echo.weights >= 0)


def test_a_target_outside_the_field_of_view_gives_an_empty_cloud_without_error():
    res = run(**{"pose.offset_x_m": 100.0, "tnr": 20.0})
    s = res.summary()
    assert s["n_hit_pixels"] == 0 and s["n_points"] == 0
    assert s["snr_median"] is None
    assert res.waveform(16, 16).t_s.size == 0


def test_a_target_larger_than_the_field_of_view_fills_it():
    res = run(distance_m=20.0, pixels=32, **{"fidelity.subrays": 1})
    assert res.summary()["n_hit_pixels"] > 0.8 * 32 * 32
    assert_finite(res)


@pytest.mark.parametrize(
    "overrides",
    [
        {"distance_m": 1.0},  # inside the target
        {"distance_m": 100_000.0},
        {"pixels": 1},
        {"pixels": 1024},
        {"laser.pulse_width_s": 1e-10},
        {"laser.pulse_width_s": 1e-7},
        {"pitch_deg": 89.9},  # panels edge-on
        {"pose.offset_x_m": 50.0},  # outside the field of view
        {"transmit.illumination": "square"},
        {"transmit.illumination": "gaussian"},
    ],
    ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()),
)
@pytest.mark.parametrize("preset", ["interactive", "balanced"])
def test_the_adaptive_presets_stay_finite_at_the_extremes(preset, overrides):
    """Corner probes, cell spreads, steep and beam-edge refinement at the edges of the space."""
    res = run(preset=preset, **overrides)
    assert_finite(res)
    assert np.all(np.isfinite(res.echo.arrivals_s)) and np.all(res.echo.weights >= 0)
