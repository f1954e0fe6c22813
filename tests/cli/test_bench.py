"""`lmapd bench` machinery (not its timings: those are printed, never asserted)."""

import pytest

from simcore.cli.bench import stages as bench


def test_the_memory_probe_runs_in_a_fresh_process_and_reports_its_high_water_mark():
    base_mb, peak_mb = bench.peak_memory_mb(16, 1)
    assert 50 < base_mb <= peak_mb < 4096


def test_the_table_lists_every_configuration_and_the_rerun_figures():
    stages = {s: 0.001 for s in bench.STAGES}
    fig = {
        "mesh_load_s": 0.3,
        "bvh_build_s": 0.1,
        "frames": [{"pixels": 64, "subrays": 1, "frame_s": 0.004, "stages_s": stages}],
        "rerun_256_s": {"tnr": 0.001, "pulse_energy": 0.001},
        "memory_256x256x16_mb": {"after_imports": 400.0, "peak": 700.0},
    }
    text = bench.format_table(fig)
    assert "| 64 x 64 | 1 | 4.0 | - | - |" in text and "after a TNR change 1.0 ms" in text
    assert "700 MB" in text


def test_the_table_sets_each_frame_against_its_ray_cast():
    stages = {s: 0.001 for s in bench.STAGES}
    row = {"pixels": 256, "subrays": 4, "frame_s": 0.06, "stages_s": stages}
    row["frame_spread_s"] = {"median": 0.06, "min": 0.05, "max": 0.08}
    row["ray_cast_s"] = {"median": 0.03, "min": 0.02, "max": 0.04}
    row["ratio"] = {"median": 2.0, "min": 1.5, "max": 2.5}
    fig = {
        "mesh_load_s": 0.3,
        "bvh_build_s": 0.1,
        "frames": [row],
        "rerun_256_s": {"tnr": 0.001, "pulse_energy": 0.001},
        "memory_256x256x16_mb": {"after_imports": 400.0, "peak": 700.0},
        "repeats": 15,
        "load_average": {"before": 1.0, "after": 2.0},
    }
    text = bench.format_table(fig)
    assert "| 256 x 256 | 4 | 60.0 (50.0-80.0) | 30.0 (20.0-40.0) | 2.00 (1.50-2.50) |" in text
    assert "load average 1.00 before, 2.00 after" in text
    # the frame is the stages a pose change re-runs, the background among them
    assert bench.FRAME_STAGES == ("hits", "echo", "background", "receiver", "detection", "cloud")


def test_the_ray_cast_alone_casts_every_sub_ray_of_the_frame():
    from simcore import geometry
    from simcore.scene import load_scene, with_overrides
    from simcore.target import load_target

    scene = with_overrides(load_scene(), {"pixels": 16, "fidelity.subrays": 4})
    caster = geometry.RayCaster(load_target(scene.target))
    assert bench.ray_cast_s(caster, geometry.stage_rays(scene), scene) > 0


def test_the_kernel_bench_sets_each_figure_as_median_and_range_and_b_over_a_round_by_round():
    from simcore.cli.bench import kernel

    assert kernel.spread([0.010, 0.030, 0.020]) == "20 (10-30)"
    assert kernel.spread([1.5, 2.5, 2.0], 1, ".2f") == "2.00 (1.50-2.50)"
    assert kernel.ratios([1.0, 2.0], [3.0, 3.0]) == [3.0, 1.5]
    assert "LMAPD_NO_NUMBA" in kernel.BACKENDS["B numpy"]


def test_the_sweep_bench_grid_gives_the_frames_asked_for():
    from simcore.cli.bench import sweep

    tens = sweep.bench_sweep(20, 16)
    assert len(tens) == 20 and tens.frames[0].scene.detector.pixels == 16
    assert len({f.scene.pose.azimuth_deg for f in tens.frames}) == 10
    odd = sweep.bench_sweep(7, 16)  # not a multiple of ten: one azimuth, seven pitches
    assert len(odd) == 7 and len({f.scene.pose.azimuth_deg for f in odd.frames}) == 1
    assert sweep.echo_backend() in ("kernel", "numpy")


def test_the_sweep_bench_keeps_each_configurations_fastest_run():
    import numpy as np

    from simcore.cli.bench import sweep

    run = {"workers": 2, "backend": "kernel", "cluster_start_s": 1.0, "warm_up_s": 2.0}
    run["wall_s_all"] = [3.0, 2.0, 4.0]
    run["frame_s_all"] = [np.array([9.0]), np.array([0.1, 0.3]), np.array([9.0])]
    fig = sweep.figures(run)
    assert fig["wall_s"] == 2.0 and fig["wall_s_median"] == 3.0
    assert fig["frame_s_median"] == 0.2


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--kernel", "--sweep"], "--kernel and --sweep are separate benches"),
        (["--kernel", "--frames", "3"], "--frames is for --sweep"),
        (["--sweep", "--rounds", "2"], "--sweep takes no --rounds"),
        (["--sweep", "--before", "x"], "--sweep takes no --before"),
        (["--kernel", "--repeats", "0"], "--repeats 0: give at least 1"),
        (["--sweep", "--workers", "0"], "--workers 0"),
        (["--design", "--workers", "1", "2"], "one number of --workers"),
        (["--pixels", "64"], "the stage bench takes no --pixels"),
    ],
)
def test_each_bench_refuses_the_options_of_another_before_any_work(capsys, argv, message):
    from simcore import cli

    assert cli.main(["bench", *argv]) == 2
    assert message in capsys.readouterr().err
