"""The command's front door (issue 29): ``--version`` from the package metadata, and a scene given
as ``--scene FILE`` as well as positionally (both at once must agree)."""

from __future__ import annotations

from importlib import metadata

import pytest

from simcore.cli import main

SMALL = ["--set", "pixels=16", "--set", "fidelity.subrays=1"]


def test_version_prints_the_installed_distributions_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.split() == ["lmapd", metadata.version("lmapd-sim")]


@pytest.mark.parametrize("form", [["paper"], ["--scene", "paper"]])
def test_a_scene_is_accepted_positionally_or_with_scene(form, tmp_path):
    summary = tmp_path / "summary.json"
    argv = ["simulate", *form, *SMALL, "--out", str(tmp_path / "c.ply"), "--summary", str(summary)]
    assert main(argv) == 0
    assert summary.exists()


def test_the_same_scene_twice_is_accepted(tmp_path):
    argv = ["simulate", "paper", "--scene", "paper", *SMALL, "--out", str(tmp_path / "c.ply")]
    assert main(argv) == 0


def test_two_different_scenes_are_refused_naming_both_forms(tmp_path, capsys):
    scene = tmp_path / "other.toml"
    scene.write_text('name = "other"\n', encoding="utf-8")
    argv = ["simulate", "paper", "--scene", str(scene), "--out", str(tmp_path / "c.ply")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "two scenes given" in err and "--scene SCENE" in err
    assert not (tmp_path / "c.ply").exists()


def test_a_missing_scene_file_given_with_scene_names_the_file(tmp_path, capsys):
    argv = ["simulate", "--scene", str(tmp_path / "nowhere.toml"), "--out", str(tmp_path / "c.ply")]
    assert main(argv) == 2
    assert "nowhere.toml" in capsys.readouterr().err
