"""The atlas: imaging quality over every view direction (simcore.atlas), against closed forms
(solid angles, view directions, projected areas) and invariants (a sphere's flat map, a cube's
symmetry), and reproduced frame by frame by the single-frame path."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import simcore
from simcore import atlas as atlas_mod
from simcore import quality
from simcore.atlas import AtlasError, attitude_grid, build_atlas, read_atlas, run_atlas
from simcore.atlas.frame import attitude_row
from simcore.scene import Scene, load_scene, with_overrides

# a calibration shape filling part of a small array, lit evenly (every pixel on it detected)
SHAPE_SCENE = {
    "pose.distance_m": 20.0,
    "receive.fov_rad": 0.12,
    "transmit.illumination": "flat_top",
    "laser.divergence_rad": 0.12,
    "transmit.beam_expansion_ratio": 1.0,
}


def shape_scene(mesh: str, size_m: float, pixels: int) -> Scene:
    return with_overrides(
        Scene(),
        {**SHAPE_SCENE, "target.mesh": mesh, "target.size_m": size_m, "detector.pixels": pixels},
    )


def rows_of(report) -> list[dict]:
    return report.table.to_pylist()


def view(row) -> np.ndarray:
    return np.array([row["view_x"], row["view_y"], row["view_z"]])


def test_the_grid_covers_the_sphere_once_with_solid_angles_adding_up_to_four_pi():
    grid = attitude_grid(10.0)
    attitudes = grid.attitudes()
    assert len(attitudes) == len(grid) == 17 * 36 + 2
    assert attitudes.count((-90.0, 0.0)) == 1 and attitudes.count((90.0, 0.0)) == 1
    assert len(set(attitudes)) == len(attitudes)
    total_sr = sum(grid.solid_angle_sr(p) for p, _ in attitudes)
    assert total_sr == pytest.approx(4 * math.pi, rel=1e-12)
    # a pole's cap of half a row: 2 pi (1 - cos 5 deg)
    assert grid.solid_angle_sr(90.0) == pytest.approx(2 * math.pi * (1 - math.cos(math.radians(5))))


def test_a_step_that_does_not_divide_180_is_rounded_to_one_that_does():
    grid = attitude_grid(7.0)
    assert grid.pitch_step_deg == pytest.approx(
        180 / 26
    ) and grid.azimuth_step_deg == pytest.approx(360 / 51)
    assert sum(grid.solid_angle_sr(p) for p, _ in grid.attitudes()) == pytest.approx(4 * math.pi)


@pytest.mark.parametrize("step", [0.5, 91.0, math.nan, math.inf, -10.0])
def test_a_grid_step_outside_its_range_is_refused(step):
    with pytest.raises(AtlasError, match="step"):
        attitude_grid(step)


def test_a_sphere_looks_the_same_from_everywhere(tmp_path):
    scene = shape_scene("sphere", 2.0, 32)
    report = run_atlas(
        build_atlas(scene, 45.0), tmp_path / "a", workers=0, progress=False, figure=False
    )
    rows = rows_of(report)
    assert all(r["status"] == "ok" for r in rows) and len(rows) == 26
    # the view directions are the grid's: against the front view, cos(pitch) cos(azimuth); against
    # the top (pitch 90), sin(pitch); unit vectors
    front = view(next(r for r in rows if r["pitch_deg"] == 0 and r["azimuth_deg"] == 0))
    top = view(next(r for r in rows if r["pitch_deg"] == 90))
    for r in rows:
        p, a = math.radians(r["pitch_deg"]), math.radians(r["azimuth_deg"])
        assert np.linalg.norm(view(r)) == pytest.approx(1.0, abs=1e-12)
        assert view(r) @ front == pytest.approx(math.cos(p) * math.cos(a), abs=1e-9)
        assert view(r) @ top == pytest.approx(math.sin(p), abs=1e-9)
    # the same disc from every side: points within the pixel quantisation of the 96-ring mesh's
    # rim (a pixel per rim step, about 2 pi r_px), recall within 4 binomial sd of its mean
    n = np.array([r["n_target_points"] for r in rows], dtype=float)
    rim_px = 2 * math.pi * math.sqrt(n.mean() / math.pi)
    assert n.max() - n.min() <= max(2.0, 0.05 * rim_px)
    recall = np.array([r["quality.recall"] for r in rows])
    seen = quality.SURFACE_SAMPLES * np.array([r["seen_area_m2"] for r in rows]) / (4 * math.pi)
    sd = np.sqrt(recall.mean() * (1 - recall.mean()) / seen.min())
    assert np.all(np.abs(recall - recall.mean()) <= 4 * sd + 1e-12)
    assert min(r["quality.precision"] for r in rows) > 0.99


def test_a_plates_points_follow_its_projected_area_and_vanish_edge_on(tmp_path):
    side_m, pixels = 1.0, 40
    scene = shape_scene("plate", side_m, pixels)
    report = run_atlas(
        build_atlas(scene, 30.0), tmp_path / "p", workers=0, progress=False, figure=False
    )
    rows = rows_of(report)
    face_on = next(r for r in rows if r["pitch_deg"] == 0 and r["azimuth_deg"] == 0)
    n0 = face_on["n_target_points"]
    # the plate face-on: (side / pixel footprint)^2 pixels, footprint = D fov / n
    footprint_m = 20.0 * 0.12 / pixels
    assert n0 == pytest.approx((side_m / footprint_m) ** 2, abs=4 * side_m / footprint_m)
    for r in rows:
        p, a = math.radians(r["pitch_deg"]), math.radians(r["azimuth_deg"])
        cos_view = abs(math.cos(p) * math.cos(a))  # the normal . the line of sight
        perimeter_px = 4 * side_m / footprint_m  # a pixel per boundary pixel, at most
        assert abs(r["n_target_points"] - n0 * cos_view) <= perimeter_px + 1, r
        if cos_view < 1e-9:  # edge-on: nothing, and no figure made of nothing
            assert r["n_target_points"] == 0 and r["quality.precision"] is None


def test_a_cubes_map_has_the_cubes_symmetry(tmp_path):
    scene = shape_scene("cube", 1.0, 32)
    report = run_atlas(
        build_atlas(scene, 45.0), tmp_path / "c", workers=0, progress=False, figure=False
    )
    by = {(r["pitch_deg"], r["azimuth_deg"]): r for r in rows_of(report)}
    area_m2 = 6.0  # the cube's surface, which the recall's samples are spread over
    for (p, a), r in by.items():
        if abs(p) == 90:
            continue
        turned = by[
            (p, (a + 90.0) % 360.0)
        ]  # a quarter turn about the vertical axis: the same cube
        mirrored = by[(-p, a)]  # its mirror image in the horizontal plane
        for other in (turned, mirrored):
            # the same picture but for the facets' diagonals: the same pixels hit and points
            assert abs(other["n_hit_pixels"] - r["n_hit_pixels"]) <= 2
            assert abs(other["n_target_points"] - r["n_target_points"]) <= 2
            # the seen area and the recall from other samples: binomial proportions of the
            # samples that land on the seen side, 4 sd of their difference
            n_seen = quality.SURFACE_SAMPLES * r["seen_area_m2"] / area_m2
            share = r["seen_area_m2"] / area_m2
            sd_area_m2 = area_m2 * math.sqrt(2 * share * (1 - share) / quality.SURFACE_SAMPLES)
            assert abs(other["seen_area_m2"] - r["seen_area_m2"]) <= 4 * sd_area_m2
            rec = r["quality.recall"]
            assert abs(other["quality.recall"] - rec) <= 4 * math.sqrt(2 * rec * (1 - rec) / n_seen)
    # from a pole the cube shows one face, as face-on from the front
    assert abs(by[(90.0, 0.0)]["n_hit_pixels"] - by[(0.0, 0.0)]["n_hit_pixels"]) <= 2


def test_the_mros_rows_are_what_simulate_gives_at_the_same_attitude(tmp_path):
    scene = with_overrides(load_scene("paper"), pixels=32)
    out = tmp_path / "mro"
    report = run_atlas(build_atlas(scene, 90.0), out, workers=0, progress=False, figure=False)
    rows = rows_of(report)
    assert len(rows) == 6 and all(r["status"] == "ok" for r in rows)
    for r in rows[1:3]:  # a fresh pipeline per frame: nothing carried from the atlas's
        frame = simcore.simulate(scene, pitch_deg=r["pitch_deg"], azimuth_deg=r["azimuth_deg"])
        expected = attitude_row(frame)
        assert {k: r[k] for k in expected} == expected
    summary = json.loads((out / "atlas.json").read_text())
    for which in ("best", "worst"):
        chosen = summary[which]
        again = simcore.simulate(load_scene(out / f"{which}.toml"))
        assert again.quality["f_score"] == rows[chosen["index"]]["quality.f_score"]
        assert again.scene.pose.pitch_deg == chosen["pitch_deg"]
    # the best is the largest F-score, the median weighs each point by its solid angle
    f = np.array([r["quality.f_score"] for r in rows])
    assert summary["best"]["value"] == f.max() and summary["worst"]["value"] == f.min()
    w = np.array([r["solid_angle_sr"] for r in rows])
    assert summary["median"] == atlas_mod.weighted_median(f, w)


def test_an_interrupted_atlas_resumes_to_the_table_of_one_run(tmp_path, monkeypatch):
    scene = with_overrides(load_scene("paper"), pixels=16)
    atlas = build_atlas(scene, 90.0, requirements=("recall >= 0.01",))
    whole = run_atlas(atlas, tmp_path / "whole", workers=0, progress=False, figure=False)
    real = atlas_mod.run.run_attitude
    calls = []

    def interrupted(scene, pipeline, want_cloud=False):
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(scene, pipeline, want_cloud)

    monkeypatch.setattr(atlas_mod.run, "run_attitude", interrupted)
    out = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        run_atlas(atlas, out, workers=0, progress=False, figure=False)
    partial = read_atlas(out).to_pylist()
    assert [r["status"] for r in partial] == ["ok"] * 3 + ["pending"] * 3
    assert json.loads((out / "atlas.json").read_text())["complete"] is False
    assert not (out / "best.toml").exists()
    with pytest.raises(AtlasError, match="--resume"):  # not over it by accident
        run_atlas(atlas, out, workers=0, progress=False, figure=False)
    monkeypatch.setattr(atlas_mod.run, "run_attitude", real)
    resumed = run_atlas(atlas, out, resume=True, workers=0, progress=False, figure=False)
    assert resumed.n_skipped == 3 and resumed.n_run == 3
    drop = {"frame_s"}
    strip = [{k: v for k, v in r.items() if k not in drop} for r in resumed.table.to_pylist()]
    assert strip == [{k: v for k, v in r.items() if k not in drop} for r in whole.table.to_pylist()]
    assert resumed.summary == whole.summary
    other = build_atlas(scene, 45.0)
    with pytest.raises(AtlasError, match="another atlas"):
        run_atlas(other, out, resume=True, workers=0, progress=False, figure=False)


def test_an_atlas_on_dask_workers_gives_the_table_of_one_process(tmp_path):
    scene = with_overrides(load_scene("paper"), pixels=16)
    atlas = build_atlas(scene, 90.0)
    here = run_atlas(atlas, tmp_path / "here", workers=0, progress=False, figure=False)
    there = run_atlas(atlas, tmp_path / "there", workers=1, progress=False, figure=False)
    assert there.n_workers == 1
    drop = {"frame_s"}
    assert [{k: v for k, v in r.items() if k not in drop} for r in there.table.to_pylist()] == [
        {k: v for k, v in r.items() if k not in drop} for r in here.table.to_pylist()
    ]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"metric": "sharpness"}, "unknown; choose from"),
        ({"requirements": ("recall > 0.5",)}, "write a metric"),
        ({"requirements": ("colour >= 1",)}, "unknown metric 'colour'"),
        ({"step_deg": 0.1}, "step"),
    ],
)
def test_bad_atlas_options_are_refused_by_name_before_anything_runs(tmp_path, kwargs, message):
    with pytest.raises(AtlasError, match=message):
        build_atlas(with_overrides(load_scene("paper"), pixels=8), **kwargs)
    assert not any(tmp_path.iterdir())


def test_an_attitude_fixed_by_a_quaternion_is_refused():
    scene = with_overrides(load_scene("paper"), {"pose.quaternion_wxyz": [1.0, 0.0, 0.0, 0.0]})
    with pytest.raises(AtlasError, match="quaternion"):
        build_atlas(scene, 45.0)


def test_an_unwritable_folder_is_refused_in_one_line_with_nothing_run(tmp_path):
    atlas = build_atlas(with_overrides(load_scene("paper"), pixels=8), 90.0)
    with pytest.raises(AtlasError, match="cannot write there"):
        run_atlas(atlas, "/proc/lmapd-atlas", workers=0, progress=False)
    a_file = tmp_path / "f"
    a_file.write_text("x")
    with pytest.raises(AtlasError, match="is a file"):
        run_atlas(atlas, a_file, workers=0, progress=False)


def test_the_recalls_samples_are_drawn_once_per_mesh_and_seed_and_change_no_figure():
    scene = with_overrides(load_scene("paper"), pixels=16)
    result = simcore.simulate(scene)
    model = result.target
    first = quality.mesh_samples(model, scene.seed)
    assert quality.mesh_samples(model, scene.seed)[0] is first[0]
    rng = np.random.default_rng([scene.seed, 7411])
    fresh = quality.seen_surface(
        result.caster,
        result.hits.pose,
        scene.receive.fov_rad,
        np.arange(len(model.faces)),
        quality.SURFACE_SAMPLES,
        rng,
    )
    cached = quality.seen_samples(result.caster, result.hits.pose, scene.receive.fov_rad, *first)
    assert np.array_equal(fresh.points_t, cached.points_t) and np.array_equal(
        fresh.seen, cached.seen
    )
    assert not first[0].flags.writeable


def test_a_live_map_refines_nested_grids_running_only_the_new_attitudes():
    from simcore.atlas import map_levels
    from simcore.stage import Cancelled

    scene = with_overrides(load_scene("paper"), pixels=8)
    levels = list(map_levels(scene, (90.0, 45.0)))
    assert [len(lv.rows) for lv in levels] == [6, 26] and [lv.n_run for lv in levels] == [6, 20]
    coarse, fine = levels
    assert all(fine.rows[a] == row for a, row in coarse.rows.items())
    asked = []

    def stop():
        asked.append(1)
        return len(asked) > 3

    with pytest.raises(Cancelled):
        list(map_levels(scene, (90.0, 45.0), should_stop=stop))
    with pytest.raises(AtlasError, match="half"):
        next(map_levels(scene, (90.0, 30.0)))
