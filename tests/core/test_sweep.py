"""Sweeps: the file format, checks before any work, Dask equals serial, resume, failures, CLI.

The shipped example (8 frames of 64 x 64 pixels) is the sweep of the cluster tests: a 2-worker
LocalCluster must give exactly the rows of a serial run (every column but ``frame_s``, the wall
time), and a sweep killed (SIGKILL) after three frames must finish on the next run without
redoing them.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest

import simcore
from simcore import io
from simcore.cli import CliError
from simcore.cli.sweep import add_parser
from simcore.sweep import (
    METRICS,
    TABLE_NAME,
    SweepError,
    build_sweep,
    frame_id,
    load_sweep,
    read_table,
    run_sweep,
    sweep_from_dict,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "assets" / "sweeps" / "example.toml"
FAST = {"pixels": 32, "fidelity.subrays": 1}
WALL_TIME = ["frame_s"]  # the only column that may differ between two runs of the same frames


@pytest.fixture(scope="module")
def example():
    return load_sweep(EXAMPLE)


@pytest.fixture(scope="module")
def serial_table(example, tmp_path_factory):
    """The example run in this process, without Dask: the reference rows."""
    out = tmp_path_factory.mktemp("serial")
    report = run_sweep(example, out, workers=0, clouds="ply", progress=False)
    assert report.n_failed == 0
    return report.table


def write_sweep(tmp_path, text: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ----------------------------------------------------------------------------------------------
# the file format
# ----------------------------------------------------------------------------------------------
def test_the_example_is_small_and_every_frame_is_valid(example):
    assert 1 <= len(example) <= 12
    assert all(f.scene.detector.pixels <= 64 for f in example.frames)
    assert example.name == "example" and example.clouds is None


def test_the_grid_is_the_cartesian_product_in_written_order_then_the_list():
    sweep = sweep_from_dict(
        {
            "set": FAST,
            "grid": {"pitch_deg": [0, 30], "distance_m": {"start": 300, "stop": 500, "num": 3}},
            "list": [{"tnr": 4.0}],
        }
    )
    varied = [(f.params.get("pitch_deg"), f.params.get("distance_m")) for f in sweep.frames]
    assert varied == [(0, 300.0), (0, 400.0), (0, 500.0), (30, 300.0), (30, 400.0)] + [
        (30, 500.0),
        (None, None),
    ]
    assert sweep.frames[-1].scene.timing.tnr == 4.0
    assert [f.index for f in sweep.frames] == list(range(7))


def test_a_step_range_includes_its_stop_and_reads_clean_decimals():
    sweep = build_sweep(fixed=FAST, grid={"tnr": {"start": 3.0, "stop": 3.3, "step": 0.1}})
    assert [f.params["tnr"] for f in sweep.frames] == [3.0, 3.1, 3.2, 3.3]


def test_section_tables_and_dotted_keys_mean_the_same(tmp_path):
    quoted = write_sweep(tmp_path, '[set]\n"fidelity.subrays" = 1\n[grid]\npixels = [32]\n')
    a = load_sweep(quoted).frames[0]
    dotted = write_sweep(tmp_path, "[set]\nfidelity.subrays = 1\n[grid]\npixels = [32]\n")
    b = load_sweep(dotted).frames[0]
    assert a.scene == b.scene and a.frame_id == b.frame_id
    assert a.scene.fidelity.subrays == 1


def test_a_relative_base_scene_is_read_next_to_the_sweep_file(tmp_path):
    (tmp_path / "near.toml").write_text("[pose]\ndistance_m = 777.0\n", encoding="utf-8")
    path = write_sweep(tmp_path, 'base = "near.toml"\n[grid]\npixels = [32]\n')
    assert load_sweep(path).frames[0].scene.pose.distance_m == 777.0


def test_the_frame_id_follows_the_resolved_scene():
    a = build_sweep(fixed=FAST, grid={"pitch_deg": [10]}).frames[0]
    b = build_sweep(fixed=FAST, grid={"pitch_deg": [10]}).frames[0]
    c = build_sweep(fixed={**FAST, "tnr": 4.0}, grid={"pitch_deg": [10]}).frames[0]
    assert a.frame_id == b.frame_id == frame_id(a.scene)
    assert len(a.frame_id) == 16 and c.frame_id != a.frame_id


# ----------------------------------------------------------------------------------------------
# bad input: one clear message before any work, nothing written
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[grid]\npich_deg = [0, 30]\n", "unknown scene key 'pich_deg'; did you mean pitch_deg"),
        ("[set]\nbogus = 1\n[grid]\npixels = [32]\n", "unknown scene key 'bogus'"),
        ("[grid]\npixels = [32]\n[[list]]\nlaser.nope = 1\n", "unknown scene key 'laser.nope'"),
        ("[grid]\n", "[grid] is empty"),
        ("[grid]\npitch_deg = []\n", "pitch_deg = []: an empty list gives no frames"),
        ('base = "paper"\n', "no frames"),
        ("[grid]\npitch_deg = [0, 200]\n", "frame 1 (pitch_deg=200): pose.pitch_deg = 200"),
        ("[grid]\npitch_deg = 30\n", "a single value belongs in [set]"),
        ("[set]\npixels = 32\n[grid]\npixels = [16, 32]\n", "'pixels' is both in [set]"),
        ("[grid]\npitch_deg = [0, 0]\n", "frames 0 and 1 are the same scene"),
        ("gird = 1\n[grid]\npixels = [32]\n", "unknown sweep key 'gird'"),
        ('base = "nowhere.toml"\n[grid]\npixels = [32]\n', "scene file not found: nowhere"),
        ('clouds = "xyz"\n[grid]\npixels = [32]\n', "clouds = 'xyz'; use ply or las"),
        (
            '[grid]\npixels = [32]\n[[list]]\n"target.mesh" = "/nonexistent/x.obj"\n',
            "frame 1 (target.mesh='/nonexistent/x.obj'): target.mesh: file not found",
        ),
        ("[grid]\npixels = {start = 8, stop = 16}\n", "a range is {start, stop, num}"),
    ],
)
def test_bad_sweep_files_name_the_problem_and_write_nothing(tmp_path, text, message):
    path = write_sweep(tmp_path, text)
    out = tmp_path / "out"
    with pytest.raises(SweepError) as err:
        lmapd_sweep(path, "--out", out, "--workers", "0")
    assert message in str(err.value) and "\n" not in str(err.value)
    assert str(path) in str(err.value)
    assert not out.exists()


def lmapd_sweep(*argv) -> int:
    """Run `lmapd sweep ARGV` through the parser that add_parser registers."""
    parser = argparse.ArgumentParser(prog="lmapd")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["sweep", *map(str, argv)])
    return args.func(args)


def test_an_unreachable_scheduler_is_named_before_any_work(tmp_path, example):
    address = f"tcp://127.0.0.1:{free_port()}"
    out = tmp_path / "out"
    with pytest.raises(SweepError, match=f"cannot reach the Dask scheduler at '{address}'"):
        run_sweep(example, out, scheduler=address, connect_timeout_s=1.0, progress=False)
    assert not out.exists()


def test_the_cli_refuses_workers_with_a_scheduler(tmp_path):
    with pytest.raises(CliError, match="with --scheduler give no --workers"):
        lmapd_sweep(EXAMPLE, "--out", tmp_path / "o", "--scheduler", "tcp://h:8786", "--workers", 2)
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------------------------
# running: Dask equals serial, clouds, the table
# ----------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_two_worker_cluster_gives_exactly_the_rows_of_a_serial_run(
    tmp_path, example, serial_table
):
    report = run_sweep(example, tmp_path, workers=2, clouds="ply", progress=False)
    assert (report.n_workers, report.n_run, report.n_failed) == (2, len(example), 0)
    assert report.table.drop(WALL_TIME).equals(serial_table.drop(WALL_TIME))
    assert read_table(tmp_path).equals(report.table)
    for row in report.rows():  # each frame's cloud is the one `simulate` gives for its scene
        frame = example.frames[row["index"]]
        cloud = io.read_cloud(tmp_path / row["cloud"])
        assert len(cloud) == row["n_points"]
        if row["index"] == 0:
            direct = simcore.simulate(frame.scene)
            np.testing.assert_array_equal(cloud.points, direct.points)


@pytest.mark.slow
def test_a_sweep_runs_on_a_running_scheduler_given_its_address(tmp_path):
    from distributed import LocalCluster

    sweep = build_sweep(fixed=FAST, grid={"pitch_deg": [0, 45]})
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        report = run_sweep(sweep, tmp_path, scheduler=cluster.scheduler_address, progress=False)
        assert (report.n_workers, report.n_run, report.n_failed) == (1, 2, 0)
        assert len(cluster.scheduler_info["workers"]) == 1  # the sweep closed only its client


def test_the_table_has_parameters_metrics_and_the_resolved_scene(serial_table, example):
    rows = serial_table.to_pylist()
    assert [r["index"] for r in rows] == list(range(len(example)))
    names = set(serial_table.column_names)
    assert {"frame_id", "status", "error", "frame_s", "cloud", "scene_toml"} <= names
    assert {m for m, _, _ in METRICS} <= names and set(example.keys) <= names
    front = rows[-2]  # the [[list]] frame that sets only pulse_energy_j
    assert front["pulse_energy_j"] == 1e-3 and front["pitch_deg"] == 0.0
    assert rows[0]["pulse_energy_j"] == 5e-3  # not set by the frame: its scene's value
    for row, frame in zip(rows, example.frames, strict=True):
        assert row["status"] == "ok" and row["error"] is None
        assert row["n_points"] == row["n_target_points"] + row["n_outliers"] > 0
        assert row["snr_p10"] <= row["snr_median"] <= row["snr_p90"]
        assert 0 < row["range_sigma_m_median"] <= row["range_sigma_m_p90"] < 1.0
        scene = simcore.scene.scene_from_dict(tomllib.loads(row["scene_toml"]))
        assert scene == frame.scene


def test_a_failed_frame_is_recorded_the_sweep_goes_on_and_the_next_run_retries_it(
    tmp_path, monkeypatch
):
    sweep = build_sweep(fixed=FAST, grid={"pitch_deg": [0, 30, 60]})
    original = simcore.Pipeline.run

    def flaky(self, scene):
        if scene.pose.pitch_deg == 30:
            raise RuntimeError("disk on fire")
        return original(self, scene)

    monkeypatch.setattr(simcore.Pipeline, "run", flaky)
    first = run_sweep(sweep, tmp_path, workers=0, progress=False)
    assert (first.n_run, first.n_failed) == (3, 1)
    rows = first.rows()
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert rows[1]["error"] == "RuntimeError: disk on fire" and rows[1]["n_points"] is None

    monkeypatch.setattr(simcore.Pipeline, "run", original)
    second = run_sweep(sweep, tmp_path, workers=0, progress=False)
    assert (second.n_skipped, second.n_run, second.n_failed) == (2, 1, 0)
    assert [r["status"] for r in second.rows()] == ["ok"] * 3


KILL_AFTER = 3  # frames the first run finishes before it is killed
KILLER = """
import os, signal, sys
import simcore.sweep as sw
import simcore.sweep.run as sweep_run

if __name__ == "__main__":
    original, done = sweep_run._record, []

    def record(*args):
        original(*args)
        done.append(1)
        if len(done) == {kill_after}:
            os.kill(os.getpid(), signal.SIGKILL)  # no clean-up: as kill -9 or a lost node

    sweep_run._record = record
    sw.run_sweep(sw.load_sweep(sys.argv[1]), sys.argv[2], workers=2, progress=False)
"""


@pytest.mark.slow
def test_a_killed_sweep_restarts_without_redoing_finished_frames(tmp_path, example, serial_table):
    script = tmp_path / "killer.py"
    script.write_text(KILLER.format(kill_after=KILL_AFTER), encoding="utf-8")
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, str(script), str(EXAMPLE), str(out)], capture_output=True, timeout=120
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    rows = sorted((out / "frames").glob("*.json"))
    assert len(rows) == KILL_AFTER and not (out / TABLE_NAME).exists()
    before = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in rows}

    report = run_sweep(example, out, workers=0, progress=False)
    assert (report.n_skipped, report.n_run, report.n_failed) == (KILL_AFTER, len(example) - 3, 0)
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in rows} == before
    ours = report.table.drop([*WALL_TIME, "cloud"])
    assert ours.equals(serial_table.drop([*WALL_TIME, "cloud"]))
    leftovers = [p for p in out.rglob("*") if p.name.endswith(".part")]
    assert leftovers == []


def test_the_cli_runs_a_sweep_and_prints_one_line(tmp_path, capsys):
    path = write_sweep(tmp_path, "[set]\npixels = 32\n[grid]\npitch_deg = [0, 45]\n")
    out = tmp_path / "out"
    assert lmapd_sweep(path, "--out", out, "--workers", 0, "--clouds", "las") == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("sweep s: 2 frames (2 run, 0 already done)") and TABLE_NAME in line
    manifest = json.loads((out / "sweep.json").read_text())
    assert [f["params"]["pitch_deg"] for f in manifest["frames"]] == [0, 45]
    assert os.path.isfile(out / TABLE_NAME)
    assert len(list((out / "clouds").glob("*.las"))) == 2
