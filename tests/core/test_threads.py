"""Threads per frame (simcore.parallel): the cores this process may use by default, LMAPD_THREADS
and ``lmapd --threads`` set it, and results never depend on it: 1, 2 and 3 threads give the same
clouds and summaries, bit for bit, for each receiver and noise model."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import simcore
from simcore import parallel

CASES = {
    "statistical": {"pixels": 64},
    "montecarlo": {"pixels": 32, "fidelity.noise_model": "montecarlo"},
    "interactive": {"pixels": 64, "preset": "interactive", "pitch_deg": 30.0},
    "geiger": {"pixels": 32, "receiver.kind": "gm_apd"},
}


def frame(overrides: dict, threads: int):
    before = parallel.threads()
    parallel.set_threads(threads)
    try:
        result = simcore.Pipeline().run(simcore.with_overrides(simcore.Scene(), overrides))
    finally:
        parallel.set_threads(before)
    summary = result.summary(quality=False)
    summary.pop("timings_s")
    return result, json.dumps(summary, sort_keys=True, default=str)


@pytest.mark.parametrize("case", list(CASES))
def test_one_two_and_three_threads_give_the_same_cloud_and_summary(case):
    one, one_summary = frame(CASES[case], 1)
    for threads in (2, 3):
        other, other_summary = frame(CASES[case], threads)
        assert np.array_equal(other.points, one.points), threads
        for name, values in one.attributes.items():
            assert np.array_equal(other.attributes[name], values, equal_nan=True), (threads, name)
        assert other_summary == one_summary, threads


def run_python(code: str, **env) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return done.stdout.strip()


def test_the_default_is_the_cores_this_process_may_use_or_lmapd_threads():
    code = "import simcore.parallel as p; print(p.threads(), p.available_cores())"
    env = {k: v for k, v in os.environ.items() if k != parallel.THREADS_ENV}
    threads, cores = run_python(code, **env, **{parallel.THREADS_ENV: ""}).split()
    assert threads == cores == str(len(os.sched_getaffinity(0)))
    assert run_python(code, **{parallel.THREADS_ENV: "3"}).split()[0] == "3"
    # a setting that is not a whole number >= 1 is named in a warning, and the cores used
    assert run_python(code, **{parallel.THREADS_ENV: "many"}).split()[0] == cores


def test_lmapd_threads_sets_it_and_refuses_less_than_one(capsys):
    from simcore.cli import main

    before = parallel.threads()
    try:
        assert main(["keys", "--threads", "3"]) == 0
        assert parallel.threads() == 3
    finally:
        parallel.set_threads(before)
        os.environ.pop(parallel.THREADS_ENV, None)
    assert main(["keys", "--threads", "0"]) == 2
    assert "--threads 0" in capsys.readouterr().err
