"""``lmapd bench --startup``: fresh processes time their own phases (the machinery is tested here,
never the timings: they are printed, not asserted)."""

from __future__ import annotations

import json

import pytest

from simcore import cli
from simcore.cli.bench import startup

PHASE_KEYS = [key for key, _ in startup.PHASES]
DETAIL_KEYS = [key for key, _ in startup.DETAILS]
TOTAL_KEYS = [key for key, _ in startup.TOTALS]
FLOOR_KEYS = [key for key, _ in startup.FLOORS]


def test_quick_runs_two_fresh_processes_and_prints_every_phase(tmp_path, capsys):
    out = tmp_path / "startup.json"
    assert cli.main(["bench", "--startup", "--quick", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    for _, label in (*startup.PHASES, *startup.DETAILS, *startup.TOTALS, *startup.FLOORS):
        assert f"| {label} | " in printed
    fig = json.loads(out.read_text())
    assert fig["processes"] == 2 and fig["pixels"] == 32 and len(fig["runs"]) == 2
    for run in fig["runs"]:
        assert set(run) == {*PHASE_KEYS, *DETAIL_KEYS, *TOTAL_KEYS, "n_points"}
        assert run["n_points"] > 0
        # each process times itself; the parent's wall clock holds all of its phases (the warm
        # frame after them is taken out of it); the kernel wait is part of the first frame
        assert sum(run[k] for k in PHASE_KEYS) < run["process_s"]
        assert 0 <= run["kernel_wait_s"] <= run["first_frame_s"] and run["warm_frame_s"] > 0
    for stat in ("median_s", "min_s", "max_s"):
        assert set(fig[stat]) == {*PHASE_KEYS, *DETAIL_KEYS, *TOTAL_KEYS}
        assert set(fig["floors"][stat]) == set(FLOOR_KEYS)
    for key in PHASE_KEYS:
        assert fig["min_s"][key] <= fig["median_s"][key] <= fig["max_s"][key]
    assert len(fig["floors"]["runs"]) == 2
    assert all(run[k] > 0 for run in fig["floors"]["runs"] for k in FLOOR_KEYS)


def test_the_table_gives_the_median_and_the_range_in_ms():
    runs = [
        {**dict.fromkeys([*PHASE_KEYS, *DETAIL_KEYS, *TOTAL_KEYS], 0.1), "import_s": t}
        for t in (0.3, 0.5, 0.4)
    ]
    fig = {"processes": 3, "pixels": 256, **startup.summary(runs)}
    fig["cold_run"] = {**runs[0], "target_load_s": 0.6}
    fig["runs"] = [{**runs[0], "first_frame_s": 0.3, "warm_frame_s": 0.1}]
    fig["floors"] = startup.summary([dict.fromkeys(FLOOR_KEYS, 0.02)], FLOOR_KEYS)
    text = startup.format_table(fig)
    assert "| import (CLI, imaging chain) | 400 (300-500) |" in text
    assert "| import numba | 20 (20-20) |" in text
    assert "First frame / warm frame, process by process: 3.00 (3.00-3.00)" in text
    assert "| BVH build | 100 (100-100) |" in text
    assert "median (min-max) of 3 processes" in text and "(256 x 256)" in text
    assert "target load 600 ms" in text


@pytest.mark.parametrize(
    ("extra", "message"),
    [(["--tradeoff"], "one at a time"), (["--pixels", "64"], "no --pixels"), (["--out", "x"], "")],
)
def test_startup_takes_no_other_bench_options(capsys, extra, message):
    assert cli.main(["bench", "--startup", *extra]) == 2
    assert message in capsys.readouterr().err
