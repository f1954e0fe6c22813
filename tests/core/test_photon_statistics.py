"""Photon statistics of the LM-APD (``fidelity.noise_model = "photon"``): McIntyre's gain
distribution reproduces its mean gain M and the excess noise factor of Eq. 11,
F = k M + (1 - k)(2 - 1/M), within the sampling error of the draws; the photon-level noise keeps
the Gaussian model's variance; the pipeline runs with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import simcore
from simcore.receivers.lm_apd import apd
from simcore.receivers.lm_apd.montecarlo import photon


@pytest.mark.parametrize(("gain", "k"), [(73.0, 0.02), (20.0, 0.0), (10.0, 0.3), (150.0, 0.1)])
def test_mcintyre_pmf_is_normalised_with_mean_m_and_eq11_excess_noise(gain, k):
    n = np.arange(1, 2_000_001, dtype=np.float64)
    p = np.exp(photon.mcintyre_log_pmf(n, gain, k))
    assert p.sum() == pytest.approx(1.0, abs=1e-9)
    assert (n * p).sum() == pytest.approx(gain, rel=1e-8)
    f = (n * n * p).sum() / gain**2
    assert f == pytest.approx(apd.excess_noise_factor(gain, k), rel=1e-7)


def test_mcintyre_at_k_zero_is_the_geometric_law_of_one_carrier():
    n = np.arange(1, 50, dtype=np.float64)
    m = 12.0
    np.testing.assert_allclose(
        np.exp(photon.mcintyre_log_pmf(n, m, 0.0)), (1 / m) * (1 - 1 / m) ** (n - 1), rtol=1e-12
    )


@pytest.mark.parametrize(("gain", "k"), [(73.0, 0.02), (10.0, 0.3)])
def test_sampled_gains_reproduce_m_and_f_within_their_sampling_error(gain, k):
    size = 1_000_000
    g = photon.sample_gains(np.random.default_rng(7), size, gain, k)
    f = apd.excess_noise_factor(gain, k)
    # 5 standard errors of each sample mean (the second moment's from its own sample spread)
    assert abs(g.mean() - gain) < 5 * gain * math.sqrt(f - 1) / math.sqrt(size)
    g2 = g * g
    assert abs(g2.mean() - f * gain**2) < 5 * g2.std() / math.sqrt(size)


def test_the_sum_of_gains_has_the_mean_and_variance_of_n_draws():
    gain, k, trials = 73.0, 0.02, 200_000
    f = apd.excess_noise_factor(gain, k)
    for n in (3, 500):  # drawn one by one, and from the normal law
        s = photon.sum_of_gains(np.random.default_rng(n), np.full(trials, n), gain, k)
        var = n * gain**2 * (f - 1)
        assert abs(s.mean() - n * gain) < 5 * math.sqrt(var / trials)
        assert s.var() == pytest.approx(var, rel=5 * math.sqrt(2 / trials) * 3)


def test_photon_noise_keeps_the_gaussian_models_variance():
    """A quiet receiver (1 MOhm load, 10 nA bulk dark current) whose multiplied dark current
    dominates its noise: same variance as the Gaussian model's, and skewed."""
    scene = simcore.with_overrides(
        simcore.Scene(), {"detector.load_ohm": 1e6, "detector.dark_bulk_a": 1e-8}
    )
    rx = apd.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    noise = photon.PhotonNoise(scene.detector.excess_noise_k, scene.detector.dark_bulk_a)
    dt = 4e-10
    rng = np.random.default_rng(3)
    white = rng.standard_normal((400, 4000)) * noise.gaussian_sigma_a(rx, dt)
    noise.add_noise(rng, white, np.zeros_like(white), dt, rx)
    expected = rx.sigma_n_a**2 / (2 * dt * rx.bandwidth_hz)  # the Gaussian model's
    assert abs(white.mean()) < 5 * math.sqrt(expected / white.size)
    # the variance of 1.6e6 samples of a heavy-tailed law: 5 standard errors from the sample
    assert abs(white.var() - expected) < 5 * (white**2).std() / math.sqrt(white.size)
    skew = ((white - white.mean()) ** 3).mean() / white.std() ** 3
    assert skew > 0.5  # the multiplied dark current is skewed: the point of the model


def test_the_photon_noise_model_runs_through_the_pipeline():
    scene = simcore.with_overrides(
        simcore.Scene(), {"pixels": 24, "fidelity.noise_model": "photon"}
    )
    res = simcore.simulate(scene)
    assert res.summary()["n_target_points"] > 0.9 * res.summary()["n_lit_pixels"]


def test_poisson_counts_are_numpys_below_the_exact_limit_and_normal_past_it():
    """Below EXACT_POISSON: numpy's own draws, the same stream. Past it (numpy refuses means
    over about 9.2e18): the normal law's mean and variance within their sampling errors."""
    small = np.array([0.0, 0.5, 40.0, 1e6, photon.EXACT_POISSON])
    got = photon.poisson_counts(np.random.default_rng(7), small)
    np.testing.assert_array_equal(got, np.random.default_rng(7).poisson(small))
    trials = 20_000
    for mean in (1e16, 1e20, 1e30):
        counts = photon.poisson_counts(np.random.default_rng(1), np.full(trials, mean))
        assert counts.dtype == np.float64 and np.all(counts >= 0)
        assert abs(counts.mean() - mean) < 5 * math.sqrt(mean / trials)
        assert counts.var() == pytest.approx(mean, rel=5 * math.sqrt(2 / (trials - 1)))
    mixed = photon.poisson_counts(np.random.default_rng(2), np.array([3.0, 1e25]))
    assert mixed[0] == int(mixed[0]) and mixed[1] == pytest.approx(1e25, rel=1e-9)
