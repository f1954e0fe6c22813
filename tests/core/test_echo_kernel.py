"""The compiled echo kernel (simcore/echo/kernel.py) against the numpy path it replaces: the same
features on the golden scenes (1 um of range, 1e-9 of peak), the same sampled echoes, and the
numpy path with a one-line notice where numba is unavailable."""

import builtins
import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy import constants as sc

import simcore
from simcore import echo
from simcore.echo import features
from simcore.pipeline import Pipeline
from simcore.scene import load_scene, with_overrides

TAU = 5e-9
B = 120e6
RANGE_TOL_M = 1e-6
PEAK_RTOL = 1e-9

# the golden scenes (tests/cli/test_golden.py) and the presets' extremes
SCENES = {
    "paper": {},
    "oblique": {
        "preset": "interactive",
        "pixels": 128,
        "pitch_deg": 35.0,
        "azimuth_deg": -50.0,
        "distance_m": 300.0,
    },
    "grazing": {"preset": "balanced", "pixels": 128, "pitch_deg": 70.0},
    "subrays64": {"preset": "reference", "pixels": 96, "pitch_deg": 45.0, "azimuth_deg": 30.0},
}


def both(shape, arrivals, weights, dt, t_d=2.24e-9, k=0.5, raw=False):
    args = (shape, arrivals, weights, dt, t_d, k, raw)
    return echo.echo_features(*args, backend="kernel"), echo.echo_features(*args, backend="numpy")


def assert_same(a, b, raw=False):
    lit = b.peak_w_per_j > 0
    assert np.array_equal(a.peak_w_per_j > 0, lit)
    assert np.max(np.abs(a.t_half_s - b.t_half_s), initial=0.0) * sc.c / 2 < RANGE_TOL_M
    assert np.allclose(a.peak_w_per_j, b.peak_w_per_j, rtol=PEAK_RTOL, atol=0)
    assert np.allclose(a.cfd_slope_per_s, b.cfd_slope_per_s, rtol=1e-9, atol=0)
    assert np.allclose(a.cfd_shot_level, b.cfd_shot_level, rtol=1e-9, atol=1e-12)
    if raw:
        assert np.allclose(a.peak_raw_w_per_j, b.peak_raw_w_per_j, rtol=PEAK_RTOL, atol=0)


def test_kernel_gives_the_numpy_features_for_any_element_count_and_the_raw_peak():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    rng = np.random.default_rng(3)
    n, k = 3000, 12
    arrivals = 3.3e-6 + rng.uniform(0, 4e-9, (n, k)) * rng.uniform(0, 1, (n, 1))
    weights = rng.uniform(0, 1e-12, (n, k)) * (rng.random((n, k)) < rng.uniform(0, 1, (n, 1)))
    weights[:5] = 0.0  # pixels without light
    a, b = both(shape, arrivals, weights, dt, raw=True)
    assert_same(a, b, raw=True)
    assert np.array_equal(a.peak_w_per_j > 0, (weights > 0).any(axis=1))
    assert 1 < (weights > 0).sum(axis=1).max() and len(np.unique((weights > 0).sum(axis=1))) > 8


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SCENES))
def test_kernel_gives_todays_features_on_the_golden_scenes(name):
    """The echo stage (the kernel) against the numpy path on the same elements: every lit pixel
    within 1 um of range and 1e-9 of peak power."""
    scene = with_overrides(load_scene(), SCENES[name])
    e = Pipeline().run(scene).echo
    t_d, k = e.cfd_delay_s, scene.timing.cfd_fraction
    ref = echo.echo_features(e.shape, e.arrivals_s, e.weights, e.dt_s, t_d, k, backend="numpy")
    assert len(e.pixel) > 1000
    assert_same(e.features, ref)


def test_sampled_echoes_are_the_pulse_tables_interpolated_at_exact_delays():
    from simcore.echo import kernel

    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    rng = np.random.default_rng(8)
    n, k, length = 40, 5, 90
    arrivals = 1e-6 + rng.uniform(0, 3e-9, (n, k))
    weights = rng.uniform(0, 1, (n, k)) * (rng.random((n, k)) < 0.7)
    t_base = 1e-6 - 5e-9 + rng.uniform(0, dt, n)
    j0 = rng.integers(0, 20, n)
    for dtype, parallel in ((np.float64, True), (np.float32, False)):
        out = np.ones((n + 3, length), dtype=dtype)
        rows = rng.permutation(n + 3)[:n]
        kernel.sample_echoes(
            out, rows, np.zeros(n), t_base, j0, j0 + length, dt, arrivals, weights,
            shape.filtered, shape.filtered_slope, shape, scale=2.0, parallel=parallel,
        )  # fmt: skip
        t = t_base[:, None] + (j0[:, None] + np.arange(length)[None, :]) * dt
        y = np.einsum(
            "nlk,nk->nl", shape.filtered_at(t[:, :, None] - arrivals[:, None, :]), weights
        )
        want = np.ones((n + 3, length), dtype=dtype)
        want[rows] += (2.0 * y).astype(dtype)
        tol = 1e-14 if dtype == np.float64 else 1e-6
        assert np.allclose(out, want, rtol=tol, atol=0)


def test_invalid_elements_are_refused_before_the_kernel():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    good = np.full((2, 2), 3.3e-6), np.full((2, 2), 1e-12)
    for bad in (np.nan, np.inf):
        arrivals, weights = good[0].copy(), good[1].copy()
        arrivals[1, 0] = bad
        with pytest.raises(ValueError, match="arrivals_s"):
            echo.echo_features(shape, arrivals, weights, dt, 2.24e-9, 0.5)
        arrivals, weights = good[0].copy(), good[1].copy()
        weights[0, 1] = bad
        with pytest.raises(ValueError, match="weights"):
            echo.echo_features(shape, arrivals, weights, dt, 2.24e-9, 0.5)
    with pytest.raises(ValueError, match="backend"):
        echo.echo_features(shape, *good, dt, 2.24e-9, 0.5, backend="fortran")


@pytest.fixture
def fresh_loader(monkeypatch):
    """The kernel loader as in a new process (restored afterwards)."""
    monkeypatch.setattr(features, "_KERNEL", [])
    monkeypatch.setattr(features, "_NO_KERNEL", [""])
    monkeypatch.setattr(features, "_PRELOAD", [])


@pytest.mark.parametrize("how", ["env", "import"])
def test_without_numba_the_numpy_path_runs_with_a_one_line_notice(how, fresh_loader, monkeypatch):
    if how == "env":
        monkeypatch.setenv(features.NO_KERNEL_ENV, "1")
    else:
        real_import = builtins.__import__

        def no_numba(name, *args, **kwargs):
            if name == "numba" or name.startswith("numba."):
                raise ImportError("No module named 'numba'")
            return real_import(name, *args, **kwargs)

        monkeypatch.delitem(sys.modules, "simcore.echo.kernel", raising=False)
        monkeypatch.delattr(simcore.echo, "kernel", raising=False)
        monkeypatch.setattr(builtins, "__import__", no_numba)
    scene = with_overrides(load_scene(), {"pixels": 32})
    with pytest.warns(UserWarning, match="numpy path") as notes:
        result = simcore.simulate(scene)
    assert len([n for n in notes if "numpy path" in str(n.message)]) == 1
    assert "\n" not in str(notes[0].message)
    assert len(result.cloud) > 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per process
        assert features.compiled_kernel() is None
    with pytest.raises(RuntimeError, match="unavailable"):
        shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
        echo.echo_features(
            shape, np.ones((1, 1)), np.ones((1, 1)), 1e-10, 2e-9, 0.5, backend="kernel"
        )


def test_importing_simcore_does_not_load_numba():
    code = "import sys, simcore; simcore.load_scene(); print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
