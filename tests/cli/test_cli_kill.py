"""``lmapd simulate`` killed with SIGKILL at random moments: the next run leaves no temporary
file, and no temporary file ever has a nested name (a temporary of a temporary).

The runs are forked from a process that has imported the simulator once (multiprocessing's
fork server), so that 20 kills cost seconds, not 20 interpreter starts; each run is
``simcore.cli.main(["simulate", ...])``, the function behind the ``lmapd`` command.
"""

from __future__ import annotations

import multiprocessing
import random
import time
from pathlib import Path

import pytest

from simcore import cli, io

pytestmark = pytest.mark.slow

N_KILLS = 10  # each a run of about a second under load: 10 keep the test near 20 s
# imported once by the fork server (a run then spends its time simulating, not importing)
PRELOAD = [
    "simcore.cli",
    "simcore.pipeline",
    "simcore.io",
    "simcore.echo.kernel",
    "simcore.receivers.lm_apd.receiver",
    "simcore.receivers.lm_apd.gross_errors",
]
WAIT_S = 120.0


def simulate_argv(folder: Path) -> list[str]:
    return [
        "simulate",
        "--set",
        "pixels=32",
        "--out",
        str(folder / "c.ply"),
        "--waveforms",
        str(folder / "w.npz"),
        "--summary",
        str(folder / "s.json"),
    ]


def parts(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".part" in p.name)


def test_atomic_writes_into_a_staged_temporary_never_nest_their_names(tmp_path, monkeypatch):
    staged = io.part_path(tmp_path / "w.json")
    made = []
    part_path = io.part_path
    monkeypatch.setattr(io, "part_path", lambda path: made.append(path) or part_path(path))
    io.write_json(staged, {"a": 1})  # written in place: its owner renames it
    io.write_json(tmp_path / "x.json", {"b": 2})  # a temporary of its own, renamed
    assert made == [tmp_path / "x.json"]
    assert parts(tmp_path) == [staged.name] and staged.read_text().startswith("{")
    assert io.is_part_path(staged) and not io.is_part_path(tmp_path / "w.json")
    assert not io.is_part_path(tmp_path / ".w.json.lmapd-x-1.part.json")


def test_the_next_run_after_random_kills_leaves_no_temporary_file(tmp_path):
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    argv = simulate_argv(tmp_path)

    def one_run(kill_after_s: float | None) -> int | None:
        proc = ctx.Process(target=cli.main, args=(argv,))
        proc.start()
        proc.join(kill_after_s if kill_after_s is not None else WAIT_S)
        if proc.is_alive():
            proc.kill()
            proc.join(WAIT_S)
        return proc.exitcode

    started = time.monotonic()
    assert one_run(None) == 0  # warm: the stage caches on disk, the fork server
    run_s = time.monotonic() - started
    started = time.monotonic()
    assert one_run(None) == 0
    run_s = min(run_s, time.monotonic() - started)
    rng = random.Random(28)
    seen: set[str] = set()
    n_left = 0
    for _ in range(N_KILLS):
        code = one_run(rng.uniform(0.05, 1.0) * run_s)
        left = parts(tmp_path)
        seen.update(left)
        n_left += code != 0 and bool(left)
    assert one_run(None) == 0
    assert parts(tmp_path) == []  # the next run removed every killed run's temporaries
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply", "s.json", "w.npz"]
    assert n_left > 0  # some kills landed while the outputs were being staged
    assert all(name.count(".lmapd-") == 1 for name in seen), seen  # never a nested name
