"""The compiled, threaded steps of the detection and cloud stages make the numpy path's results
bit for bit (the thread counts are compared in tests/core/test_threads.py)."""

from __future__ import annotations

import numpy as np
import pytest

import simcore
from simcore import pointcloud
from simcore.receivers.lm_apd import detection


def test_the_compiled_limited_stops_make_the_numpy_paths_decisions(monkeypatch):
    rng = np.random.default_rng(4)
    n = 20_000
    pixel = rng.integers(0, 3000, size=n)
    pixel[:200] = 7  # one pixel with many events: the merge sort
    range_m = np.round(rng.uniform(400.0, 600.0, size=n), 1)  # ties in range
    for max_stops, holdoff_m in ((1, 0.0), (2, 1.5), (4, 0.3), (1000, 0.0)):
        compiled = detection.limited_stops(pixel, range_m, max_stops, holdoff_m)
        with monkeypatch.context() as m:
            m.setattr(detection, "compiled_kernel", lambda: None)
            numpy_path = detection.limited_stops(pixel, range_m, max_stops, holdoff_m)
        np.testing.assert_array_equal(compiled, numpy_path)
        assert 0 < compiled.sum() <= n


@pytest.mark.parametrize("pitch_deg", [0.0, 35.0])
def test_the_compiled_ground_truth_is_the_numpy_paths(monkeypatch, pitch_deg):
    """Mixed pixels (several surfaces) at an oblique pose, and false alarms, at TNR 4."""
    scene = simcore.with_overrides(
        simcore.Scene(),
        {"pixels": 96, "pitch_deg": pitch_deg, "azimuth_deg": -50.0, "tnr": 4.0, "seed": 9},
    )
    pipe = simcore.Pipeline()
    compiled = pipe.run(scene)
    monkeypatch.setattr(pointcloud, "_kernel", lambda: None)
    numpy_path = simcore.Pipeline().run(scene)
    names = ("part_id", "true_range_m", "range_error_m", "incidence_deg", "outlier")
    assert np.isfinite(compiled.attributes["true_range_m"]).sum() > 500
    for name in names:
        np.testing.assert_array_equal(
            compiled.attributes[name], numpy_path.attributes[name], err_msg=name
        )


def test_the_background_in_pieces_on_threads_is_the_whole_blocks(monkeypatch):
    """By day, 96 x 96 pixels in pieces of 4096 on two threads give the same light as whole
    blocks on one: the pieces' pixels are their own."""
    from simcore import background, parallel

    scene = simcore.with_overrides(simcore.Scene(), {"pixels": 96, "sun.mode": "manual"})
    before = parallel.threads()
    try:
        parallel.set_threads(2)
        pieces = simcore.Pipeline().run(scene).background
        monkeypatch.setattr(background, "CHUNK_PIXELS", 1 << 30)
        parallel.set_threads(1)
        whole = simcore.Pipeline().run(scene).background
    finally:
        parallel.set_threads(before)
    assert pieces.sunlit.any() and pieces.earth.any()
    for name in ("power_w", "sunlit", "earth", "target_power_w", "earth_power_w"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name), err_msg=name)


def test_a_map_inside_the_pools_threads_runs_serially_instead_of_waiting_forever():
    import threading

    from simcore import parallel

    before = parallel.threads()
    out: list = []
    try:
        parallel.set_threads(2)
        inner = lambda i: parallel.map_threads(lambda j: i * j, list(range(4)))  # noqa: E731
        worker = threading.Thread(
            target=lambda: out.append(parallel.map_threads(inner, list(range(4)))), daemon=True
        )
        worker.start()
        worker.join(timeout=60)
    finally:
        parallel.set_threads(before)
    assert out == [[[i * j for j in range(4)] for i in range(4)]]


def test_openmps_threads_sleep_after_a_region_unless_the_user_says_otherwise():
    import os
    import subprocess
    import sys

    code = "import os, simcore.echo.kernel; print(os.environ['OMP_WAIT_POLICY'])"
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    run = lambda e: subprocess.run(  # noqa: E731
        [sys.executable, "-c", code], env=e, capture_output=True, text=True, check=True
    ).stdout.strip()
    assert run(env) == "PASSIVE"
    assert run({**env, "OMP_WAIT_POLICY": "ACTIVE"}) == "ACTIVE"
