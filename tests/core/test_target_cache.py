"""The on-disk target cache: keyed by content, rebuilt when corrupt, skipped when unwritable."""

from __future__ import annotations

import os

import numpy as np
import pytest
from support.mesh_files import write_plates

import simcore
from simcore import target as target_module
from simcore.scene import Target


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv(target_module.CACHE_ENV, str(folder))
    return folder / "targets"


def _entries(folder):
    return sorted(folder.glob("*.npz")) if folder.exists() else []


def _load(path):
    return simcore.load_target(Target(mesh=str(path), scale_m_per_unit=1.0))


def test_a_cached_target_is_the_same_target_as_one_read_from_its_file(tmp_path, cache):
    mesh = write_plates(tmp_path / "plates.obj", [(2.0, 0.0, 0.0), (1.0, 3.0, 30.0)])
    first = _load(mesh)  # read from the file, written to the cache
    assert len(_entries(cache)) == 1
    second = _load(mesh)  # read from the cache
    assert len(_entries(cache)) == 1
    np.testing.assert_array_equal(first.mesh.vertices, second.mesh.vertices)
    np.testing.assert_array_equal(first.mesh.faces, second.mesh.faces)
    np.testing.assert_array_equal(first.face_part, second.face_part)
    assert first.part_names == second.part_names


def test_the_cache_serves_the_built_in_target_without_reading_its_file(cache, monkeypatch):
    scene = simcore.load_scene()
    first = simcore.load_target(scene.target)

    def no_reading(path):
        raise AssertionError(f"{path} was read although it is cached")

    monkeypatch.setattr(target_module, "_read_parts", no_reading)
    second = simcore.load_target(scene.target)
    np.testing.assert_array_equal(first.mesh.triangles, second.mesh.triangles)
    assert first.part_materials == second.part_materials


def test_a_changed_file_gets_a_new_entry_never_the_stale_one(tmp_path, cache):
    mesh = tmp_path / "plate.obj"
    write_plates(mesh, [(2.0, 0.0, 0.0)])
    small = _load(mesh)
    write_plates(mesh, [(4.0, 0.0, 0.0)])
    large = _load(mesh)
    assert len(_entries(cache)) == 2
    assert large.mesh.extents[0] == pytest.approx(2 * small.mesh.extents[0])


@pytest.mark.parametrize("damage", ["truncated", "garbage", "inconsistent"])
def test_a_corrupt_entry_is_rebuilt_with_a_warning(tmp_path, cache, damage):
    mesh = write_plates(tmp_path / "plate.obj", [(2.0, 0.0, 0.0)])
    good = _load(mesh)
    (entry,) = _entries(cache)
    if damage == "truncated":
        entry.write_bytes(entry.read_bytes()[:100])
    elif damage == "garbage":
        entry.write_bytes(b"not an npz at all")
    else:  # a readable file whose faces point past the vertices
        with np.load(entry) as npz:
            arrays = dict(npz)
        arrays["faces"] = arrays["faces"] + 1000
        np.savez(entry, **arrays)
    with pytest.warns(UserWarning, match="corrupt"):
        again = _load(mesh)
    np.testing.assert_array_equal(good.mesh.vertices, again.mesh.vertices)
    with np.load(entry) as npz:  # rewritten whole
        np.testing.assert_array_equal(npz["faces"], good.mesh.faces)


def test_an_unwritable_cache_warns_and_the_run_goes_on(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("the cache folder cannot be made under a file")
    monkeypatch.setenv(target_module.CACHE_ENV, str(blocker / "cache"))
    mesh = write_plates(tmp_path / "plate.obj", [(2.0, 0.0, 0.0)])
    with pytest.warns(UserWarning, match="not writable"):
        model = _load(mesh)
    assert len(model.mesh.faces) == 12


def test_off_disables_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(target_module.CACHE_ENV, "off")
    assert target_module.cache_dir() is None
    mesh = write_plates(tmp_path / "plate.obj", [(2.0, 0.0, 0.0)])
    assert len(_load(mesh).mesh.faces) == 12


def test_the_cache_keeps_a_bounded_number_of_entries(tmp_path, cache, monkeypatch):
    monkeypatch.setattr(target_module, "CACHE_MAX_ENTRIES", 3)
    for i in range(5):
        _load(write_plates(tmp_path / f"plate{i}.obj", [(1.0 + i, 0.0, 0.0)]))
    assert len(_entries(cache)) == 3


def test_a_warm_pipeline_reads_a_mesh_overwritten_in_place(tmp_path, cache):
    mesh = tmp_path / "plate.obj"
    write_plates(mesh, [(2.0, 0.0, 0.0)])
    scene = simcore.with_overrides(
        simcore.Scene(),
        {"target.mesh": str(mesh), "target.scale_m_per_unit": 1.0, "pixels": 32},
    )
    pipeline = simcore.Pipeline()
    small = pipeline.run(scene).summary()["n_hit_pixels"]
    write_plates(mesh, [(4.0, 0.0, 0.0)])  # same path, another mesh
    os.utime(mesh, ns=(1, 1))  # whatever the clock's resolution, the file's stamp changes
    warm = pipeline.run(scene).summary()["n_hit_pixels"]
    fresh = simcore.Pipeline().run(scene).summary()["n_hit_pixels"]
    assert warm == fresh > small
