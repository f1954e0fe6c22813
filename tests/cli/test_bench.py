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
    assert "| 64 x 64 | 1 | 4.0 |" in text and "after a TNR change 1.0 ms" in text
    assert "700 MB" in text
