"""``lmapd targets`` and ``lmapd target-info``, and the summary's ``target.parts``."""

from __future__ import annotations

import json

import pytest

from simcore.cli import main
from simcore.target import builtin_targets


def test_targets_prints_one_line_per_built_in_target_beginning_with_its_name(capsys):
    assert main(["targets"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == builtin_targets()
    assert all("NASA" in line for line in lines if line.split()[0] in ("tdrs", "tess", "mro"))


def test_target_info_lists_the_parts_with_triangles_area_material_and_transparency(capsys):
    assert main(["target-info", "tdrs"]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in out.splitlines()[4:]}
    assert rows["solar_cells"][3] == "solar_panel" and rows["transparent"][-1] == "yes"
    assert "fills the 0.03 rad field of view at" in out


def test_target_info_json_and_a_size(capsys):
    assert main(["target-info", "cube", "--set", "target.size_m=3", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["extents_m"] == pytest.approx([3.0, 3.0, 3.0])
    assert info["parts"] == [
        {
            "name": "cube",
            "triangles": 12,
            "area_share": 1.0,
            "material": "lambertian",
            "transparent": False,
            "matched": True,
        }
    ]


def test_an_unknown_target_lists_the_catalogue_and_exits_2(capsys):
    assert main(["target-info", "voyager"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and all(name in err for name in builtin_targets())


def test_the_summary_lists_the_parts(tmp_path):
    out, summary = tmp_path / "cloud.ply", tmp_path / "summary.json"
    argv = ["simulate", "--set", "target.mesh=tess", "--set", "pixels=32"]
    assert main([*argv, "--out", str(out), "--summary", str(summary)]) == 0
    parts = json.loads(summary.read_text())["target"]["parts"]
    assert {p["name"]: p["material"] for p in parts}["solar_cells"] == "solar_panel"
    assert sum(p["area_share"] for p in parts) == pytest.approx(1.0)
    assert set(parts[0]) == {"name", "material", "area_share", "transparent"}
