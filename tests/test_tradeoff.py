"""The trade-off comparison: errors are zero against itself and grow for a cheaper model."""

import numpy as np

import simcore
from simcore import tradeoff


def test_a_run_compared_with_itself_has_no_error():
    res = simcore.simulate(pixels=32, preset="balanced")
    out = tradeoff.compare(res, res, np.random.default_rng(0))
    assert out["range_rmse_m"] == 0.0 and out["point_count_diff_pct"] == 0.0
    assert out["waveform_l2"] < 1e-12  # the same echoes, summed in another order


def test_one_sub_ray_without_refinement_is_further_from_the_reference_than_interactive():
    pipe = simcore.Pipeline()
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 64, "pitch_deg": 30.0})
    ref = pipe.run(simcore.with_overrides(scene, preset="reference"))
    rng = np.random.default_rng(0)
    plain = tradeoff.compare(
        pipe.run(simcore.with_overrides(scene, {"fidelity.subrays": 1})), ref, rng
    )
    adaptive = tradeoff.compare(
        pipe.run(simcore.with_overrides(scene, preset="interactive")), ref, rng
    )
    assert adaptive["range_rmse_m"] < plain["range_rmse_m"]
    assert abs(adaptive["point_count_diff_pct"]) < abs(plain["point_count_diff_pct"])
    assert adaptive["refined_pixels"] > 0 and plain["refined_pixels"] == 0
