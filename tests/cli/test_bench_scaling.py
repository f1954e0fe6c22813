"""`lmapd bench`'s thread scaling: the thread counts it compares, its table, and one small run
(figures printed by the bench, never asserted here)."""

import numpy as np

from simcore import parallel
from simcore.cli.bench import stages as bench
from simcore.pipeline import Pipeline
from simcore.scene import load_scene, with_overrides
from simcore.target import load_target


def test_thread_counts_double_up_to_the_cores_and_end_on_them():
    assert bench.thread_counts(1) == [1]
    assert bench.thread_counts(2) == [1, 2]
    assert bench.thread_counts(6) == [1, 2, 4, 6]
    assert bench.thread_counts(16) == [1, 2, 4, 8, 16]


def test_a_scaling_run_times_each_thread_count_and_its_ray_cast():
    from simcore import geometry

    scene = with_overrides(load_scene(), {"pixels": 8, "fidelity.subrays": 4})
    caster = geometry.RayCaster(load_target(scene.target))
    before = parallel.threads()
    rows = bench.scaling(Pipeline(), scene, [1, 2], 1, caster)
    assert parallel.threads() == before  # put back
    assert [r["threads"] for r in rows] == [1, 2]
    for r in rows:
        assert 0 < r["frame_s"]["min"] <= r["frame_s"]["median"] <= r["frame_s"]["max"]
        assert r["ray_cast_s"]["median"] > 0 and r["rays_per_s_per_core"] > 0
        assert r["first_hits_s"]["median"] > 0 and r["raw_embree_s"]["median"] > 0
        assert r["first_hits_over_raw"]["min"] > 0
    assert rows[0]["speedup"] == {"median": 1.0, "min": 1.0, "max": 1.0}
    text = "\n".join(bench.format_scaling([{"what": "8 x 8 x 4 frame", "rows": rows}]))
    assert "Scaling, 8 x 8 x 4 frame:" in text and "| 1 | " in text and "| 2 | " in text
    assert "| first hits (ms) | raw Embree (ms) | first hits / raw |" in text


def test_raw_embree_sees_the_rays_first_hits_casts():
    from simcore import geometry

    scene = with_overrides(load_scene(), {"pixels": 16, "fidelity.subrays": 4})
    caster = geometry.RayCaster(load_target(scene.target))
    rays = bench.cast_inputs(caster, geometry.stage_rays(scene), scene)
    range_m, face = caster.first_hits(rays.origin_t, rays.directions_t, rays.start_m)
    raw = caster.embree_hits(rays.starts32, rays.directions32)
    assert (face >= 0).any()
    assert np.array_equal(np.asarray(raw["primID"]), face)
    hit = face >= 0
    assert np.array_equal(rays.start_m + raw["tfar"][hit].astype(np.float64), range_m[hit])


def test_the_table_gives_the_threads_and_each_ray_casts_rays_per_second_per_core():
    stages = {s: 0.001 for s in bench.STAGES}
    row = {"pixels": 256, "subrays": 4, "frame_s": 0.06, "stages_s": stages}
    row["ray_cast_s"] = {"median": 0.025, "min": 0.02, "max": 0.04}
    row["ratio"] = {"median": 2.0, "min": 1.5, "max": 2.5}
    row["rays_per_s_per_core"] = 262_144 / 0.025 / 2
    fig = {
        "mesh_load_s": 0.3,
        "bvh_build_s": 0.1,
        "frames": [row],
        "rerun_256_s": {"tnr": 0.001, "pulse_energy": 0.001},
        "memory_256x256x16_mb": {"after_imports": 400.0, "peak": 700.0},
        "threads": 2,
        "machine": {"cpus": 2},
        "scaling": [
            {
                "what": "Monte Carlo",
                "rows": [
                    {"threads": t, "frame_s": {"median": 1 / t, "min": 1 / t, "max": 1 / t},
                     "speedup": {"median": t, "min": t, "max": t}}
                    for t in (1, 2)
                ],
            }
        ],
    }  # fmt: skip
    text = bench.format_table(fig)
    assert "Frames on 2 threads (2 CPUs this process may use)" in text
    assert "| 1.0 | 5.24 |" in text  # the cloud's 1.0 ms, then 5.24 Mrays/s per core
    assert "| 2 | 500.0 (500.0-500.0) | 2.00 (2.00-2.00) |" in text
