"""The trade-off comparison: errors are zero against itself and grow for a cheaper model."""

import json

import numpy as np

import simcore
from simcore.cli.bench import tradeoff
from simcore.scene import PRESETS


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


def test_the_bench_writes_every_preset_at_every_attitude_and_its_plot(tmp_path, capsys):
    from simcore import cli

    assert (
        cli.main(["bench", "--tradeoff", "--quick", "--pixels", "16", "--out", str(tmp_path)]) == 0
    )
    fig = json.loads((tmp_path / "tradeoff.json").read_text())
    rows = fig["rows"]
    assert fig["pixels"] == 16
    assert sorted((r["preset"], r["pitch_deg"], r["azimuth_deg"]) for r in rows) == sorted(
        (p, a["pitch_deg"], a["azimuth_deg"]) for p in PRESETS for a in tradeoff.ATTITUDES
    )
    for r in rows:  # the contract, and where the time went
        assert r["time_s"] > 0 and r["hits_s"] > 0 and r["echo_s"] > 0
        assert np.isfinite([r["range_rmse_m"], r["point_count_diff_pct"]]).all()
        assert 0.0 <= r["refined_share"] <= 1.0
    assert all(r["range_rmse_m"] == 0 for r in rows if r["preset"] == "reference")
    assert (tmp_path / "tradeoff.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| interactive |" in capsys.readouterr().out


def test_an_invalid_array_size_is_refused_before_any_work(tmp_path, capsys):
    from simcore import cli

    out = tmp_path / "out"
    assert cli.main(["bench", "--tradeoff", "--pixels", "2000", "--out", str(out)]) == 2
    assert "detector.pixels = 2000 is out of range" in capsys.readouterr().err
    assert not out.exists()
