"""``lmapd atlas`` as a user runs it: the files it writes, one line per bad option, Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from simcore import atlas
from simcore.cli import atlas as atlas_cli
from simcore.cli import main


def test_the_commands_metric_names_are_the_libraries():
    assert atlas_cli.METRIC_NAMES == tuple(atlas.METRICS)


def test_an_atlas_writes_its_table_summary_map_and_scene_files(tmp_path, capsys):
    out = tmp_path / "atlas"
    args = ["atlas", "--set", "pixels=16", "--step-deg", "90", "--out", str(out), "--workers", "0"]
    assert main([*args, "--require", "n_target_points >= 1"]) == 0
    printed = capsys.readouterr().out
    assert "6 attitudes" in printed and "best: pitch" in printed and "% of the sphere" in printed
    names = {p.name for p in out.iterdir()}
    assert {
        "atlas.parquet",
        "atlas.json",
        "atlas.png",
        "best.toml",
        "worst.toml",
        "frames",
    } <= names
    summary = json.loads((out / "atlas.json").read_text())
    assert summary["complete"] is True and summary["grid"]["n_attitudes"] == 6
    assert summary["meets_requirements"]["share_of_grid_points"] == 1.0
    assert (out / "atlas.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the best attitude's scene file runs as a scene of its own
    assert main(["simulate", str(out / "best.toml"), "--out", str(tmp_path / "b.ply")]) == 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--step-deg", "0.5"], "must lie in [1, 90] deg"),
        (["--step-deg", "200"], "must lie in [1, 90] deg"),
        (["--require", "recall = 1"], "write a metric"),
        (["--set", "pixels=0"], "pixels"),
        (["--workers", "-1"], "--workers -1"),
    ],
)
def test_a_bad_option_is_one_line_and_writes_nothing(tmp_path, capsys, extra, message):
    out = tmp_path / "atlas"
    assert main(["atlas", "--set", "pixels=8", "--out", str(out), "--workers", "0", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err
    assert not out.exists()


def test_an_unknown_metric_is_refused_by_the_parser(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["atlas", "--out", str(tmp_path / "a"), "--metric", "beauty"])
    assert exc.value.code == 2 and "invalid choice: 'beauty'" in capsys.readouterr().err


def test_ctrl_c_keeps_the_attitudes_done_and_resume_finishes_them(tmp_path):
    out = tmp_path / "atlas"
    cmd = [sys.executable, "-m", "simcore.cli", "atlas", "--set", "pixels=16", "--step-deg", "45"]
    cmd += ["--out", str(out), "--workers", "0"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    frames = out / "frames"
    for _ in range(1200):  # until a few attitudes are done (at most 120 s)
        if frames.is_dir() and len(list(frames.glob("*.json"))) >= 3:
            break
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "--resume" in err and "Traceback" not in err
    done = len(list(frames.glob("*.json")))
    assert 3 <= done < 26
    table = atlas.read_atlas(out).to_pylist()
    assert sum(r["status"] == "ok" for r in table) == done
    assert main([*cmd[3:], "--resume"]) == 0
    assert all(r["status"] == "ok" for r in atlas.read_atlas(out).to_pylist())
