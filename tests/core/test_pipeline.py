"""The staged pipeline: caching, reproducibility, the MRO scene, invariants of the scene space."""

import dataclasses

import numpy as np
import pytest
import threadpoolctl
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import simcore
from simcore.pipeline import STAGES

PIPE = simcore.Pipeline()  # shared: the MRO loads once for the module


def run(**quick):
    overrides = quick.pop("overrides", {})
    return PIPE.run(simcore.with_overrides(simcore.load_scene(), overrides, **quick))


def test_paper_scene_images_the_mro_with_plausible_figures():
    res = run(pixels=128)
    s = res.summary()
    assert s["n_hit_pixels"] > 2000
    assert 0.9 < s["p_detect_mean"] <= 1.0
    assert s["snr_median"] > 10
    assert 0.005 < s["range_sigma_m_median"] < 0.05
    target = ~res.attributes["is_outlier"]
    assert np.all(np.abs(res.attributes["range_m"][target] - 500.0) < 6.0)  # within the MRO's depth
    assert set(np.unique(res.attributes["material_id"][target])) <= {2, 3, 4}  # panel, coatings
    assert s["target"]["credit"].startswith("3D model: Courtesy NASA")


def test_a_tnr_change_reruns_only_detection_and_the_cloud():
    run(pixels=64, tnr=5.0)
    res = run(pixels=64, tnr=4.5)
    ran = {s for s in STAGES if res.timings_s[s] > 0}
    assert ran == {"detection", "cloud"}


@pytest.mark.parametrize(
    "change",
    [{"tnr": 4.5}, {"pulse_energy_j": 1e-3}, {"distance_m": 450.0}, {"pixels": 48}, {"seed": 7}],
)
def test_stages_to_run_names_exactly_the_stages_a_run_then_computes(change):
    pipe = simcore.Pipeline()
    base = simcore.with_overrides(simcore.load_scene(), pixels=64, tnr=5.0)
    assert pipe.stages_to_run(base) == list(STAGES)  # an empty cache: everything
    pipe.run(base)
    assert pipe.stages_to_run(base) == []
    scene = simcore.with_overrides(base, **change)
    predicted = pipe.stages_to_run(scene)
    timings = pipe.run(scene).timings_s
    ran = [s for s in STAGES if timings[s] > 0]
    assert predicted == ran and predicted  # nothing computed by the prediction itself


def test_a_pulse_energy_change_never_reruns_the_echoes():
    run(pixels=64)
    res = run(pixels=64, pulse_energy_j=1e-3)
    assert res.timings_s["echo"] == 0.0 and res.timings_s["hits"] == 0.0
    assert res.timings_s["receiver"] > 0.0


def test_a_material_change_reuses_the_ray_cast():
    run(pixels=64)
    res = run(pixels=64, overrides={"target.materials": {"foil": "lambertian"}})
    assert res.timings_s["hits"] == 0.0 and res.timings_s["echo"] > 0.0


def test_received_power_scales_linearly_with_pulse_energy():
    a = run(pixels=64, pulse_energy_j=5e-3)
    b = run(pixels=64, pulse_energy_j=1e-3)
    assert np.allclose(a.receiver.peak_power_w, 5 * b.receiver.peak_power_w, rtol=1e-12)


def test_the_same_seed_gives_the_same_cloud_and_another_seed_another():
    a = simcore.simulate(pixels=64, seed=11)
    b = simcore.simulate(pixels=64, seed=11)
    c = simcore.simulate(pixels=64, seed=12)
    assert np.array_equal(a.points, b.points)
    assert not (len(a.points) == len(c.points) and np.array_equal(a.points, c.points))


def test_noise_lies_along_each_pixels_line_of_sight():
    res = run(pixels=64)
    attrs = res.attributes
    u = res.rays.pixel_directions[attrs["row"] * 64 + attrs["col"]]
    assert np.allclose(res.points, u * attrs["range_m"][:, None], atol=1e-9)


def test_paper_conventions_run_end_to_end_and_change_the_result():
    ours = run(pixels=64)
    paper = run(pixels=64, overrides={"conventions": "paper"})
    assert np.all(np.isfinite(paper.points))
    assert paper.summary()["snr_median"] < ours.summary()["snr_median"]  # the 1/(4 pi) of Eq. 30


def test_a_target_too_faint_to_detect_gives_an_empty_cloud_not_an_error():
    res = run(pixels=256, distance_m=100_000.0, pulse_energy_j=1e-9, tnr=20.0)
    s = res.summary()
    assert s["n_hit_pixels"] > 0  # it is in view, a pixel or two wide ...
    assert s["n_points"] == 0  # ... but returns nothing detectable, and no outlier at TNR 20
    assert s["p_detect_mean"] < 1e-6
    assert res.points.shape == (0, 3)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    pitch=st.floats(-90, 90),
    azimuth=st.floats(-180, 180),
    distance=st.floats(20.0, 5000.0),
    pixels=st.integers(1, 40),
    energy=st.floats(1e-9, 10.0),
    tnr=st.floats(0.0, 20.0),
    subrays=st.sampled_from([1, 4]),
)
def test_any_valid_scene_gives_finite_points_inside_the_range_gate(
    pitch, azimuth, distance, pixels, energy, tnr, subrays
):
    res = run(
        pitch_deg=pitch,
        azimuth_deg=azimuth,
        distance_m=distance,
        pixels=pixels,
        pulse_energy_j=energy,
        tnr=max(tnr, 0.0),
        overrides={"fidelity.subrays": subrays, "timing.range_gate_m": 200.0},
    )
    assert np.all(np.isfinite(res.points))
    r = res.attributes["range_m"]
    assert np.all(r >= max(0.0, distance - 100.0) - 1e-9) and np.all(r <= distance + 100.0 + 1e-9)
    s = res.summary()
    for key in ("snr_median", "range_sigma_m_median", "p_detect_mean"):
        assert s[key] is None or np.isfinite(s[key])
    assert np.all(np.isfinite(res.receiver.snr)) and np.all(res.detection.p_detect >= 0)


def test_the_monte_carlo_noise_model_runs_in_the_pipeline_and_agrees_with_eq_27():
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 48})
    stat = PIPE.run(scene)
    mc = PIPE.run(simcore.with_overrides(scene, {"fidelity.noise_model": "montecarlo"}))
    assert mc.timings_s["echo"] == 0.0  # switching the noise model re-runs detection only
    assert np.all(np.isfinite(mc.points))
    n = len(mc.echo.pixel)
    expected = stat.detection.p_detect.sum()
    spread = 5 * np.sqrt(np.sum(stat.detection.p_detect * (1 - stat.detection.p_detect))) + 0.02 * n
    assert abs(mc.detection.detected.sum() - expected) <= spread  # Eq. 27 is single-look: 2 %
    r = mc.attributes["range_m"]
    assert np.all((r >= 0) & (r <= 1000.0))


def test_a_run_told_to_stop_raises_cancelled_and_keeps_what_it_finished():
    pipe = simcore.Pipeline()
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 16})
    asked = []

    def stop_after_hits():
        asked.append(1)
        return len(asked) > 3  # target, rays, hits run; echo is refused

    with pytest.raises(simcore.Cancelled, match="echo"):
        pipe.run(scene, should_stop=stop_after_hits)
    res = pipe.run(scene)
    assert res.timings_s["hits"] == 0.0 and res.timings_s["echo"] > 0.0


def test_a_frame_runs_with_blas_single_threaded_and_restores_it(plate_scene, monkeypatch):
    """OpenBLAS threads spin after each call and take the cores of the frame's own threads."""
    from simcore import pipeline

    def blas_threads():
        return [
            i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"
        ]

    before = blas_threads()
    assert before  # numpy's BLAS is loaded
    seen = []
    cloud = next(stage for stage in pipeline.CHAIN if stage.name == "cloud")
    spy = dataclasses.replace(
        cloud, compute=lambda *a: seen.append(blas_threads()) or cloud.compute(*a)
    )
    monkeypatch.setattr(pipeline, "CHAIN", tuple(spy if s is cloud else s for s in pipeline.CHAIN))
    simcore.Pipeline().run(plate_scene())
    assert seen and all(n == 1 for n in seen[0])
    assert blas_threads() == before
