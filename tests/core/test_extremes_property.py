"""Issue 25, stability at the extremes: seeded random combinations of the receiver, Sun,
background and timing keys, each inside its documented range, through ``simulate`` under a
memory limit. Each either runs or is refused before running with one message naming a key;
every point lies inside the range gate (none behind the sensor); no summary figure is NaN, inf
or hidden (None where the frame has lit pixels).

The work is bounded, not timed: 16-32 pixels per side, at most 100 Geiger-mode pulses, gates of
at most 2 km for the waveform Monte Carlo and Geiger mode (their cost grows with the gate), and
a fixed number of derandomized examples."""

from __future__ import annotations

import math
import resource
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import simcore
from simcore.receivers.gm_apd import limits as gm_limits
from simcore.scene import SceneError, with_overrides

MESHES = ("mro", "plate", "sphere", "cube")
# numpy's allocations of one frame at these sizes, besides a Geiger-mode frame's avalanche
# records (gm_limits.BYTES_PER_EVENT each, the estimate that refuses a frame past 2 GiB)
FRAME_BUDGET_BYTES = 512 << 20
HEADROOM_BYTES = 4 << 30  # address space the test process may grow by (the hard limit)
KEYS = {  # the keys a SceneError message may name (dotted sections and quick names)
    "laser.",
    "receive.",
    "detector.",
    "timing.",
    "target.",
    "pose.",
    "fidelity.",
    "sun.",
    "orbit.",
    "background.",
    "gm.",
    "pixels",
    "tnr",
    "distance_m",
}


def log_uniform(lo: float, hi: float):
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda x: 10.0**x)


@st.composite
def scenes(draw) -> dict:
    kind = draw(st.sampled_from(["lm_apd", "gm_apd"]))
    model = draw(st.sampled_from(["statistical", "montecarlo", "photon"]))
    costly = kind == "gm_apd" or model != "statistical"
    o = {
        "receiver.kind": kind,
        "fidelity.noise_model": model,
        "fidelity.subrays": 1,
        "pixels": draw(st.integers(16, 20 if costly else 32)),
        "seed": draw(st.integers(0, 2**32)),
        "target.mesh": draw(st.sampled_from(MESHES)),
        "distance_m": draw(log_uniform(0.3, 3e4)),
        "pitch_deg": draw(st.floats(-90.0, 90.0)),
        "pulse_energy_j": draw(log_uniform(1e-9, 1.0)),
        "tnr": draw(st.floats(0.0, 50.0)),
        "timing.range_gate_m": draw(log_uniform(1.0, 2000.0 if costly else 1e6)),
        "timing.gate_center_m": draw(st.one_of(st.just(0.0), log_uniform(1.0, 3e4))),
        "timing.max_stops": draw(st.integers(1, 16)),
        "timing.threshold_mode": draw(st.sampled_from(["global", "per_pixel"])),
        "timing.resolution_s": draw(st.sampled_from([0.0, 1e-11, 1e-10, 1e-9])),
        "sun.mode": draw(st.sampled_from(["none", "manual", "orbit"])),
        "sun.azimuth_deg": draw(st.floats(-360.0, 360.0)),
        "sun.elevation_deg": draw(st.floats(-90.0, 90.0)),
        "orbit.time_s": draw(st.floats(0.0, 1e5)),
        "receive.filter_width_m": draw(log_uniform(1e-11, 3e-7)),
        "background.earth": draw(st.booleans()),
        "background.earth_albedo": draw(st.floats(0.0, 1.0)),
    }
    if kind == "gm_apd":
        o |= {
            "gm.pulses": draw(st.integers(1, 100)),
            "gm.dark_count_rate_hz": draw(st.one_of(st.just(0.0), log_uniform(1.0, 1e9))),
            "gm.dead_time_s": draw(st.one_of(st.just(0.0), log_uniform(1e-10, 1.0))),
            "gm.jitter_s": draw(log_uniform(1e-12, 1e-6)),
            "gm.bin_s": draw(log_uniform(1e-12, 1e-8)),
            "gm.crosstalk": draw(st.floats(0.0, 0.5)),
            "gm.afterpulsing": draw(st.floats(0.0, 0.5)),
        }
    return o


def _address_space_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0


@pytest.fixture(scope="module")
def memory_limit():
    """The process's address space capped at its present size plus HEADROOM_BYTES while the
    examples run: an allocation past it is a MemoryError, a failed example (restored after)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = _address_space_bytes() + HEADROOM_BYTES
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield cap
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@pytest.fixture(scope="module")
def pipelines() -> dict[str, simcore.Pipeline]:
    """A pipeline per target, its target stage (the mesh and its BVH) built before the examples
    and untraced: the app too builds it once per target, and embreex copies a mesh into Embree
    element by element in Python, which tracemalloc slows some 25-fold (3.0 s against 0.13 s for
    the MRO's 124,062 triangles), most of this test's time when each example built its own."""
    pipes = {}
    for mesh in MESHES:
        pipes[mesh] = simcore.Pipeline()
        pipes[mesh].run(with_overrides(simcore.load_scene(), {"target.mesh": mesh, "pixels": 16}))
    return pipes


def _numbers(value, path="summary"):
    """Every number of a JSON-like value, with its path."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _numbers(v, f"{path}[{i}]")
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield path, value


def check_frame(scene, result) -> None:
    lo = max(0.0, scene.gate_center_m - scene.timing.range_gate_m / 2)
    hi = scene.gate_center_m + scene.timing.range_gate_m / 2
    points = np.asarray(result.cloud.points)
    assert np.all(np.isfinite(points))
    range_m = np.asarray(result.attributes["range_m"], dtype=float)
    assert np.all(range_m >= lo - 1e-9), f"a point before the gate: {range_m.min()} < {lo}"
    assert np.all(range_m <= hi + 1e-9), f"a point after the gate: {range_m.max()} > {hi}"
    assert np.all(points[:, 2] >= 0.0), "a point behind the sensor"
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), range_m, rtol=1e-9, atol=1e-9)
    s = result.summary()
    for path, v in _numbers({k: v for k, v in s.items() if k != "scene"}):
        assert math.isfinite(v), f"{path} = {v}"
    if s["n_lit_pixels"] > 0:
        for key in ("p_detect_mean", "snr_median"):
            assert s[key] is not None, f"{key} hidden with {s['n_lit_pixels']} lit pixels"
        assert 0.0 <= s["p_detect_mean"] <= 1.0
        assert s["snr_median"] >= 0.0
    if s["n_target_points"] > 0:
        assert s["range_sigma_m_median"] is not None
    assert s["n_target_points"] <= s["n_lit_pixels"]
    for line in s.get("warnings", []):
        assert isinstance(line, str) and line and "\n" not in line


@settings(
    max_examples=30,
    derandomize=True,
    deadline=None,
    phases=(Phase.explicit, Phase.generate),  # no shrinking: a failure costs one run
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(overrides=scenes())
def test_every_combination_runs_bounded_or_is_refused_with_one_message(
    memory_limit, pipelines, overrides
):
    try:
        scene = with_overrides(simcore.load_scene(), overrides)
    except SceneError as e:
        _assert_one_message(e)
        return
    pipe = pipelines[overrides["target.mesh"]]
    assert "target" not in pipe.stages_to_run(scene)  # built before the examples
    tracemalloc.start()
    try:
        result = pipe.run(scene)
    except SceneError as e:  # refused by an estimate (before the heavy allocation)
        _assert_one_message(e)
        return
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    events = getattr(result.receiver, "events", ())
    allowed = FRAME_BUDGET_BYTES + gm_limits.BYTES_PER_EVENT * len(events)
    assert peak <= allowed, f"{peak / 2**20:.0f} MiB for {overrides}"
    check_frame(scene, result)


def _assert_one_message(error: SceneError) -> None:
    text = str(error)
    assert text and "\n" not in text
    assert any(k in text for k in KEYS), text
