"""`lmapd bench` machinery (not its timings: those are printed, never asserted)."""

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
