"""The ``lmapd`` script ends simulate and keys without the interpreter's teardown: what they print
and write is all there, and the exit status is main()'s."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import simcore
from simcore.io import read_cloud

ROOT = Path(__file__).resolve().parents[2]


def lmapd(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "simcore.cli", *argv], capture_output=True, text=True, cwd=ROOT
    )


def test_simulate_prints_writes_and_exits_0(tmp_path):
    out, summary = tmp_path / "cloud.ply", tmp_path / "summary.json"
    done = lmapd("simulate", "--set", "pixels=16", "--out", str(out), "--summary", str(summary))
    assert done.returncode == 0, done.stderr
    assert "points" in done.stdout and str(out) in done.stdout  # flushed before the exit
    assert len(read_cloud(out)) > 0 and summary.stat().st_size > 0


def test_a_user_error_still_exits_2_with_its_message(tmp_path):
    done = lmapd("simulate", "--set", "pixels=0", "--out", str(tmp_path / "cloud.ply"))
    assert done.returncode == 2
    assert "detector.pixels" in done.stderr
    assert not any(tmp_path.iterdir())


def test_keys_prints_every_key():
    done = lmapd("keys")
    assert done.returncode == 0
    last_key = simcore.key_reference()[-1]["key"]  # the key reference's last key
    assert done.stdout.rstrip().splitlines()[-1].startswith(last_key)
