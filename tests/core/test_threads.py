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
from support.fork import in_forked_child

import simcore
from simcore import parallel

CASES = {
    "statistical": {"pixels": 64},
    "montecarlo": {"pixels": 32, "fidelity.noise_model": "montecarlo"},
    "interactive": {"pixels": 64, "preset": "interactive", "pitch_deg": 30.0},
    # 64 x 64 pixels x 150 pulses: the avalanches drawn in two chunks on the threads
    "geiger": {"pixels": 64, "receiver.kind": "gm_apd", "gm.pulses": 150},
    # by day, 96 x 96: the background in several pieces, the detection's stops and the cloud's
    # ground truth in the compiled kernels
    "daylight": {"pixels": 96, "sun.mode": "manual", "pitch_deg": 35.0, "tnr": 4.0},
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


def test_the_monte_carlo_gives_the_same_stops_at_1_2_and_3_threads():
    """The waveform Monte Carlo's noise comes from one stream per pixel (docs/physics.md#mc-noise-
    draw): the same seed gives the same stops on any number of threads, and (without the timing
    quantisation, whose draws follow the chunks) on any chunking of the array."""
    from support.mc_scene import RX, SCENE, SHAPE, E

    from simcore.receivers.lm_apd import montecarlo

    rng = np.random.default_rng(5)
    arrivals = 2.0 * rng.uniform(498.0, 502.0, size=(40, 1)) / 299_792_458.0
    i_pk = RX.peak_current_for_snr(8.0)  # SNR 8
    weights = np.full((40, 1), i_pk / (RX.responsivity_a_w * E * SHAPE.peak_w_per_j))

    def run(threads, max_bytes=1 << 20, resolution_s=None):
        extra = {} if resolution_s is None else {"resolution_s": resolution_s}
        return montecarlo.scene_gate(
            np.random.default_rng(11), SCENE, RX, arrivals, weights, tnr=3.0, gate_m=100.0,
            n_pixels_total=200, n_threads=threads, max_bytes=max_bytes, **extra,
        )  # fmt: skip

    one = run(1)
    assert one.n_false_alarms > 0 and one.detected.any()
    for threads in (2, 3):
        other = run(threads)
        for name in ("detected", "range_m", "n_stops", "false_alarm_pixel", "false_alarm_range_m"):
            np.testing.assert_array_equal(getattr(other, name), getattr(one, name), err_msg=name)
    exact = [run(t, max_bytes=b, resolution_s=0.0) for t, b in ((1, 1 << 20), (2, 1 << 18))]
    for name in ("detected", "range_m", "false_alarm_pixel", "false_alarm_range_m"):
        np.testing.assert_array_equal(getattr(exact[0], name), getattr(exact[1], name))


def test_a_process_forked_after_the_pool_ran_gets_a_pool_of_its_own():
    """The app's sessions are forked from a parent that computed their first frame on the
    pool's threads; threads do not survive a fork, so the child's first parallel call must make
    a new pool instead of waiting on the parent's (it waited for ever before)."""
    parallel.set_threads(2)
    try:
        assert parallel.map_threads(lambda x: x * x, [1, 2, 3]) == [1, 4, 9]  # the pool made
        answer = in_forked_child(lambda: parallel.map_threads(lambda x: x + 1, [1, 2, 3]))
        assert answer == [2, 3, 4]
    finally:
        parallel.set_threads(parallel.default_threads())
