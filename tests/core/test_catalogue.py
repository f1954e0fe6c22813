"""The built-in targets: every spacecraft of the catalogue and every calibration shape loads, is
mapped to materials, sized as its README says and gives a sane cloud; sizes, parts and the rule
file for any mesh; bad names."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import simcore
from simcore.scene import SceneError, Target
from simcore.target import (
    TARGETS_DIR,
    TargetError,
    builtin_settings,
    builtin_targets,
    fov_fill_distance_m,
    load_target,
    parts_table,
)

SPACECRAFT = sorted(p.parent.name for p in TARGETS_DIR.glob("*/target.toml"))


def test_the_catalogue_holds_the_mro_and_at_least_five_more_spacecraft():
    assert "mro" in SPACECRAFT and len(SPACECRAFT) >= 6
    assert builtin_targets()[-4:] == ["plate", "sphere", "cube", "cylinder"]


@pytest.mark.parametrize("name", SPACECRAFT)
def test_a_catalogue_target_is_compact_credited_and_documented(name):
    folder = TARGETS_DIR / name
    settings = builtin_settings(name)
    mesh = folder / settings["mesh"]
    # the paper's MRO (5.5 MiB with its textures) predates the cap: its triangles, in their order,
    # are what the golden outputs were made from
    assert mesh.stat().st_size <= 5 * 2**20 or name == "mro"
    assert "NASA" in settings["credit"]
    readme = (folder / "README.md").read_text()
    assert "NASA" in readme and "endorsement" in readme
    sizes = {float(x) for x in re.findall(r"(\d+(?:\.\d+)?) m\b", readme)}
    assert settings["longest_extent_m"] in sizes  # the README cites the size the target has
    assert (folder / "thumbnail.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"KHR_draco_mesh_compression" not in mesh.read_bytes()[:200_000]


def test_all_assets_together_are_at_most_30_mb():
    assets = TARGETS_DIR.parent
    assert sum(f.stat().st_size for f in assets.rglob("*") if f.is_file()) <= 30 * 2**20


@pytest.mark.parametrize("name", SPACECRAFT)
def test_a_catalogue_target_has_its_published_size_and_materials_on_95_percent_of_its_area(name):
    model = load_target(Target(mesh=name))
    assert model.extents_m.max() == pytest.approx(builtin_settings(name)["longest_extent_m"])
    rows = parts_table(model)
    assert sum(r["area_share"] for r in rows) == pytest.approx(1.0)
    assert sum(r["area_share"] for r in rows if r["matched"]) >= 0.95


@pytest.mark.parametrize("name", builtin_targets())
def test_every_built_in_target_gives_a_sane_128_pixel_cloud_at_500_m(name):
    result = simcore.simulate(overrides={"target.mesh": name}, pixels=128, distance_m=500.0, seed=4)
    summary = result.summary()
    assert summary["n_target_points"] > 0
    assert np.isfinite(result.points).all()
    ranges = result.attributes["range_m"]
    gate = result.scene.timing.range_gate_m
    assert np.isfinite(ranges).all()
    assert (np.abs(ranges - 500.0) <= gate / 2).all()  # the gate is centred on the target
    assert [p["name"] for p in summary["target"]["parts"]] == list(result.target.part_names)


def test_an_unknown_name_lists_the_catalogue():
    with pytest.raises(TargetError) as error:
        load_target(Target(mesh="tdrz"))
    for name in builtin_targets():
        assert name in str(error.value)


def test_size_and_scale_together_are_refused_naming_both_keys():
    with pytest.raises(SceneError, match="target.size_m .* target.scale_m_per_unit"):
        simcore.scene.validate(
            simcore.with_overrides(
                simcore.Scene(), {"target.size_m": 3.0, "target.scale_m_per_unit": 1.0}
            )
        )


def write_box(path: Path, extents) -> str:
    trimesh.creation.box(extents=extents).export(path)
    return str(path)


def test_size_m_scales_the_longest_side(tmp_path):
    mesh = write_box(tmp_path / "box.stl", (4.0, 2.0, 1.0))
    model = load_target(Target(mesh=mesh, size_m=10.0))
    assert model.extents_m == pytest.approx([10.0, 5.0, 2.5])
    assert not model.notes


@pytest.mark.parametrize(("longest_units", "unit"), [(5000.0, "mm"), (350.0, "inch"), (0.05, "km")])
def test_a_mesh_of_implausible_size_warns_naming_the_likely_unit(tmp_path, longest_units, unit):
    mesh = write_box(tmp_path / "box.stl", (longest_units, longest_units / 2, longest_units / 4))
    with pytest.warns(UserWarning, match="target.size_m") as caught:
        load_target(Target(mesh=mesh))
    text = str(caught[0].message)
    assert (f"in {unit}, set target.scale_m_per_unit" in text) if unit else ("if the" not in text)


def test_a_plausible_size_gives_no_warning(tmp_path):
    mesh = write_box(tmp_path / "box.stl", (6.0, 3.0, 2.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_target(Target(mesh=mesh))


def test_the_field_of_view_is_filled_where_the_bounding_sphere_subtends_it():
    model = load_target(Target(mesh="sphere", size_m=4.0))
    distance_m = fov_fill_distance_m(model.radius_m, 0.03)
    assert np.degrees(2 * np.arcsin(model.radius_m / distance_m)) == pytest.approx(np.degrees(0.03))
    # at that distance, with the sphere's centre on the boresight, the cloud spans the array
    result = simcore.simulate(
        overrides={"target.mesh": "sphere", "target.size_m": 4.0, "fidelity.subrays": 1},
        pixels=64,
        distance_m=distance_m,
    )
    rows, cols = np.nonzero(result.hits.hit_pixel_mask.reshape(64, 64))
    assert cols.min() <= 1 and cols.max() >= 62 and rows.min() <= 1 and rows.max() >= 62


def test_a_transparent_part_is_not_seen_unless_the_threshold_is_zero():
    seen = load_target(Target(mesh="tdrs", alpha_threshold=0.0))
    hidden = load_target(Target(mesh="tdrs"))
    i = hidden.part_names.index("transparent")
    assert hidden.part_transparent[i] and not seen.part_transparent[i]
    assert i not in set(hidden.face_part.tolist()) and i in set(seen.face_part.tolist())
    assert len(seen.faces) - len(hidden.faces) == hidden.part_triangles[i]


def test_the_rule_file_maps_part_and_mesh_names_of_a_mesh_without_a_map(tmp_path):
    scene = trimesh.Scene()
    for name in ("Solar_Array_L", "MLI_blanket", "tex_01"):
        box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
        box.apply_translation((len(scene.geometry) * 3.0, 0, 0))
        box.visual = trimesh.visual.TextureVisuals(
            material=trimesh.visual.material.PBRMaterial(name=name)
        )
        scene.add_geometry(box, geom_name=name)
    path = tmp_path / "parts.glb"
    path.write_bytes(scene.export(file_type="glb"))
    rows = {r["name"]: r for r in parts_table(load_target(Target(mesh=str(path))))}
    assert rows["Solar_Array_L"]["material"] == "solar_panel" and rows["Solar_Array_L"]["matched"]
    assert rows["MLI_blanket"]["material"] == "coating_1"
    assert rows["tex_01"]["material"] == "coating_2" and not rows["tex_01"]["matched"]


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        (np.zeros((0, 3)), np.zeros((0, 3), int), "no triangles"),
        ([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], [[0, 1, 2]], "NaN or infinite"),
    ],
    ids=["no-triangles", "nan"],
)
def test_bad_meshes_give_one_clear_message_and_nothing_cached(tmp_path, vertices, faces, message):
    from simcore.cache import cache_dir

    (cache_dir() / "targets").mkdir(parents=True, exist_ok=True)
    path = tmp_path / "bad.ply"
    trimesh.Trimesh(np.array(vertices, float), np.array(faces), process=False).export(path)
    before = set((cache_dir() / "targets").glob("*.npz"))
    with pytest.raises(TargetError, match=message):
        load_target(Target(mesh=str(path)))
    assert set((cache_dir() / "targets").glob("*.npz")) == before


def test_a_sweep_takes_targets_by_name(tmp_path):
    from simcore.sweep import build_sweep, run_sweep

    sweep = build_sweep(fixed={"pixels": 32}, grid={"target.mesh": ["tdrs", "tess", "plate"]})
    report = run_sweep(sweep, tmp_path / "sweep", workers=0, progress=False)
    assert report.n_failed == 0
    assert report.table["target.mesh"].to_pylist() == ["tdrs", "tess", "plate"]
