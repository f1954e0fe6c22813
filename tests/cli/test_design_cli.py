"""``lmapd design``: a small study file through the command line, its outputs and exit status,
and its bad input refused with one line before any design runs."""

from __future__ import annotations

import pytest

from simcore.cli import main

STUDY = """
name = "cli"
seed = 4
trials = 3
confirm = 1
polish_steps = 1
[set]
pixels = 16
[envelope]
"pose.distance_m" = [500.0]
[variables]
"laser.pulse_energy_j" = {low = 1e-4, high = 1e-2, log = true}
[requirements]
n_target_points = ">= %s"
[objectives]
minimize = ["laser.pulse_energy_j"]
"""


def study_file(tmp_path, points: int = 20):
    path = tmp_path / "study.toml"
    path.write_text(STUDY % points)
    return str(path)


def test_a_study_runs_and_writes_its_outputs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["design", study_file(tmp_path), "--out", str(out), "--workers", "0"]) == 0
    text = capsys.readouterr().out
    assert "winner: laser.pulse_energy_j" in text and "stages reused" in text
    for name in ("trials.parquet", "front.csv", "best.toml", "report.md", "front.png"):
        assert (out / name).is_file(), name


def test_a_study_no_design_meets_exits_1_and_says_so(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["design", study_file(tmp_path, 10**6), "--out", str(out), "--workers", "0"]) == 1
    assert "no design meets every requirement" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "with --scheduler give no"),
        (["--workers", "-1"], "--workers -1"),
        (["--trials", "0"], "--trials 0"),
    ],
)
def test_bad_options_are_refused_with_one_line(tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    assert main(["design", study_file(tmp_path), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_an_unknown_figure_is_refused_before_any_design_runs(tmp_path, capsys):
    path = tmp_path / "study.toml"
    path.write_text((STUDY % 20).replace("n_target_points", "n_target_pts"))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out), "--workers", "0"]) == 2
    assert "'n_target_pts' is not a summary figure" in capsys.readouterr().err
    assert not out.exists()
