"""Eqs. 1, 19, 25, 26, 31: pulse shape, band limit, timing marks and range errors."""

import numpy as np
import pytest
from scipy import constants as sc

from simcore import echo
from simcore.receivers.lm_apd import timing

TAU = 5e-9
B = 120e6


def fwhm_s(t, p):
    above = t[p >= 0.5 * p.max()]
    return above[-1] - above[0]


def test_eq1_tau_is_the_fwhm_with_our_constant_and_0699_tau_with_the_papers():
    t = np.arange(0, 60e-9, 1e-13)
    assert fwhm_s(t, echo.pulse_power_w(t, 1.0, TAU, echo.A_FWHM)) == pytest.approx(TAU, rel=1e-4)
    assert fwhm_s(t, echo.pulse_power_w(t, 1.0, TAU, echo.A_PAPER)) == pytest.approx(
        0.699 * TAU, rel=1e-3
    )


def test_eq1_pulse_energy_is_e_tau_pmax_over_a():
    t = np.arange(0, 200e-9, 1e-12)
    p = echo.pulse_power_w(t, 5e-3, TAU)
    assert np.trapezoid(p, t) == pytest.approx(5e-3, rel=1e-6)
    assert p.max() == pytest.approx(echo.A_FWHM * 5e-3 / (np.e * TAU), rel=1e-6)


def test_band_limit_sigma_gives_the_noise_bandwidth():
    sigma = echo.band_limit_sigma_s(B)
    assert sigma == pytest.approx(1.175e-9, abs=0.001e-9)
    f = np.linspace(0, 20 * B, 400001)
    h2 = np.exp(-4 * np.pi**2 * sigma**2 * f**2)  # |H(f)|^2 of a unit-area Gaussian
    assert np.trapezoid(h2, f) == pytest.approx(B, rel=1e-6)


def test_closed_form_band_limited_pulse_matches_a_numerical_convolution():
    sigma = echo.band_limit_sigma_s(B)
    dt = 2e-12
    t = np.arange(-30e-9, 90e-9, dt)
    g_t = np.arange(-10 * sigma, 10 * sigma + dt / 2, dt)
    g = np.exp(-0.5 * (g_t / sigma) ** 2)
    numeric = np.convolve(echo.pulse_power_w(t, 1.0, TAU), g / g.sum(), mode="same")
    closed = echo.filtered_pulse_w(t, 1.0, TAU, echo.A_FWHM, sigma)
    # the discrete convolution itself is accurate to O(dt/tau) at the pulse onset kink
    assert np.max(np.abs(numeric - closed)) < 1e-3 * closed.max()


def test_band_limited_peak_is_0857_of_the_unfiltered_peak_and_keeps_the_energy():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    raw_peak = echo.A_FWHM / (np.e * TAU)
    assert shape.peak_w_per_j / raw_peak == pytest.approx(0.857, abs=5e-4)
    assert np.trapezoid(shape.filtered, dx=shape.step_s) == pytest.approx(1.0, rel=1e-6)


def test_eq19_default_cfd_delay_is_224_ns():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    assert timing.cfd_delay_s(shape) == pytest.approx(2.24e-9, abs=0.005e-9)


def test_noise_autocorrelation_is_that_of_white_noise_through_the_band_limit():
    """rho_n(lag) = int h(t) h(t + lag) dt / int h^2: 0.404 at the default 2.24 ns delay
    (PHYSICS.md prints 0.49 next to this same formula; the formula is what holds)."""
    sigma = echo.band_limit_sigma_s(B)
    t = np.arange(-12 * sigma, 12 * sigma, 1e-12)
    h = np.exp(-0.5 * (t / sigma) ** 2)
    for lag_s in (0.5e-9, 2.236e-9, 4e-9):
        shifted = np.exp(-0.5 * ((t + lag_s) / sigma) ** 2)
        numeric = np.sum(h * shifted) / np.sum(h * h)
        assert timing.noise_autocorrelation(lag_s, sigma) == pytest.approx(numeric, rel=1e-9)
    assert timing.noise_autocorrelation(2.236e-9, sigma) == pytest.approx(0.404, abs=0.001)


def test_eq26_quantisation_sigma_is_612_mm_at_100_ps():
    assert timing.sigma_quantisation_m(100e-12) == pytest.approx(6.12e-3, abs=0.005e-3)
    # start and stop each uniform over T_t: var = 2 T^2/12 in time, times (c/2)^2
    assert timing.sigma_quantisation_m(100e-12) == pytest.approx(
        sc.c / 2 * np.sqrt(2 * (100e-12) ** 2 / 12), rel=1e-12
    )


def test_eq25_cfd_sigma_from_its_closed_form():
    snr, slope, k, t_d, sig = 20.0, 2.5e8, 0.5, 2.24e-9, 1.175e-9
    rho = np.exp(-(t_d**2) / (4 * sig**2))
    expected = sc.c / 2 * np.sqrt(1 + k**2 - 2 * k * rho) / (snr * slope)
    assert timing.sigma_cfd_m(snr, slope, k, t_d, sig) == pytest.approx(expected, rel=1e-12)
    assert timing.sigma_cfd_m(0.0, slope, k, t_d, sig) == np.inf


def test_eq25_paper_form_is_c_tau_r_sqrt_1_k2_over_snr_1_k():
    got = timing.sigma_cfd_paper_m(10.0, 0.5, 2e-9)
    assert got == pytest.approx(sc.c * 2e-9 * np.sqrt(1.25) / (10 * 0.5), rel=1e-12)


@pytest.mark.parametrize("elements", [1, 2, 3])
def test_single_return_echo_timing_is_exact_whatever_the_grid_phase(elements):
    """Eq. 31: a single return at distance r gives R = r, to well below a millimetre, wherever
    its arrival falls between the samples: as one element (the pulse's own features, shifted), as
    two coincident halves (the two-element table) and as three thirds (sampled on the pixel's
    grid and refined)."""
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    r = 500.0 + np.linspace(0, 0.2, 41)  # sweeps the arrival over about one sample
    arrivals = np.repeat((2 * r / sc.c)[:, None], elements, axis=1)
    weights = np.full((41, elements), 1e-12 / elements)
    feats = echo.echo_features(shape, arrivals, weights, dt, 2.24e-9, 0.5)
    ranges = timing.range_from_half_max_m(feats.t_half_s, shape.t_half_s)
    assert np.max(np.abs(ranges - r)) < 1e-5
    assert np.allclose(feats.peak_w_per_j, 1e-12 * shape.peak_w_per_j, rtol=1e-6)


def test_a_one_element_echo_has_the_features_of_the_same_echo_sampled_and_refined():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    t = 3.3e-6 + np.linspace(0, dt, 7)[:, None]
    one = echo.echo_features(
        shape, np.hstack([t, t, t]), np.hstack([np.ones_like(t), 0 * t, 0 * t]), dt, 2.24e-9, 0.3
    )
    three = echo.echo_features(
        shape, np.hstack([t, t, t]), np.full((7, 3), 1 / 3), dt, 2.24e-9, 0.3
    )
    assert np.allclose(one.t_half_s, three.t_half_s, rtol=0, atol=1e-14)  # 1.5 um of range
    assert np.allclose(one.peak_w_per_j, three.peak_w_per_j, rtol=1e-9)
    assert np.allclose(one.cfd_slope_per_s, three.cfd_slope_per_s, rtol=1e-6)


def test_split_elements_adds_each_cells_spread_and_keeps_energy_and_mean():
    rng = np.random.default_rng(5)
    n, k = 50, 4
    arrivals = 3.3e-6 + rng.uniform(0, 1e-9, (n, k))
    weights = rng.uniform(0, 1e-12, (n, k)) * (rng.random((n, k)) < 0.8)
    spread = rng.uniform(0, 3e-10, n) * (rng.random(n) < 0.7)
    t, w = echo.split_elements(arrivals, weights, spread)
    assert t.shape == (n, 2 * k)
    total = weights.sum(axis=1)
    mean = (weights * arrivals).sum(axis=1) / np.where(total > 0, total, 1)
    var = (weights * (arrivals - mean[:, None]) ** 2).sum(axis=1)
    assert np.allclose(w.sum(axis=1), total, rtol=1e-12)
    assert np.allclose((w * t).sum(axis=1), (weights * arrivals).sum(axis=1), rtol=1e-12)
    added = (w * (t - mean[:, None]) ** 2).sum(axis=1) - var
    assert np.allclose(added, total * spread**2, rtol=1e-6, atol=1e-40)
    none = spread == 0  # no spread: each element stays whole, its twin has no weight
    assert np.array_equal((w[none] > 0).sum(axis=1), (weights[none] > 0).sum(axis=1))


def test_merged_elements_keep_each_pixels_energy_mean_delay_spread_and_skew():
    rng = np.random.default_rng(7)
    n, k = 200, 64
    arrivals = 3.3e-6 + rng.uniform(0, 4e-9, (n, k)) * (rng.random((n, 1)) < 0.5)
    arrivals += rng.choice([0.0, 2e-8], (n, k))  # two surfaces 3 m apart in some pixels
    weights = rng.uniform(0, 1e-12, (n, k)) * (rng.random((n, k)) < 0.8)
    window = 0.7e-9
    t, w = echo.merge_elements(arrivals, weights, window)
    assert t.shape[1] < k and np.all(w >= 0)
    t0 = arrivals.min(axis=1, keepdims=True)
    for p in range(4):
        before = (weights * ((arrivals - t0) / window) ** p).sum(axis=1)
        after = (w * ((t - t0) / window) ** p).sum(axis=1)
        assert np.allclose(after, before, rtol=1e-9, atol=1e-24), p
    has = weights > 0
    lo = np.where(has, arrivals, np.inf).min(axis=1)
    hi = np.where(has, arrivals, -np.inf).max(axis=1)
    used = w > 0
    assert np.all((t >= lo[:, None] - 1e-18) | ~used) and np.all((t <= hi[:, None] + 1e-18) | ~used)


def test_merging_within_a_quarter_rise_time_moves_the_range_by_far_less_than_a_millimetre():
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    rng = np.random.default_rng(3)
    n, k = 300, 64
    # tilted planes (up to 30 cm of relief in a pixel) and steps of 0-2 m
    relief = rng.uniform(0, 0.3, (n, 1)) * rng.uniform(0, 1, (n, k))
    step = rng.uniform(0, 2.0, (n, 1)) * (rng.random((n, k)) < rng.uniform(0, 1, (n, 1)))
    arrivals = 2 * (500.0 + relief + step) / sc.c
    weights = rng.uniform(0.5, 1.0, (n, k)) * 1e-12
    window = 0.25 * timing.rise_time_10_90_s(shape)
    full = echo.echo_features(shape, arrivals, weights, dt, 2.24e-9, 0.5)
    merged = echo.echo_features(
        shape, *echo.merge_elements(arrivals, weights, window), dt, 2.24e-9, 0.5
    )
    range_err = np.abs(merged.t_half_s - full.t_half_s) * sc.c / 2
    assert np.max(range_err) < 5e-4 and np.median(range_err) < 1e-5  # 0.5 mm, 10 um
    assert np.allclose(merged.peak_w_per_j, full.peak_w_per_j, rtol=1e-3)


def test_cfd_slope_of_a_single_pulse_is_the_half_max_slope():
    """With k = 0.5 and the default delay the CFD fires at the peak: ds/dt = y_n'(t_half)."""
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    dt = echo.default_time_step_s(TAU, B)
    t_d = timing.cfd_delay_s(shape)
    feats = echo.echo_features(shape, np.array([[3e-6]]), np.array([[1.0]]), dt, t_d, 0.5)
    h = 1e-12
    slope = (shape.filtered_at(shape.t_half_s + h) - shape.filtered_at(shape.t_half_s - h)) / (
        2 * h
    )
    assert feats.cfd_slope_per_s[0] == pytest.approx(slope / shape.peak_w_per_j, rel=1e-3)


def test_paper_eq25_with_the_band_limited_rise_time_is_24x_ours_even_with_c_over_2():
    """PHYSICS.md: the paper's form is 2.4x too pessimistic even with c/2 (so 4.8x with its c)."""
    shape = echo.pulse_shape(TAU, echo.A_FWHM, B)
    t_d = timing.cfd_delay_s(shape)
    dt = echo.default_time_step_s(TAU, B)
    feats = echo.echo_features(shape, np.array([[3e-6]]), np.array([[1.0]]), dt, t_d, 0.5)
    ours = timing.sigma_cfd_m(10.0, feats.cfd_slope_per_s[0], 0.5, t_d, shape.sigma_h_s)
    paper = timing.sigma_cfd_paper_m(10.0, 0.5, timing.rise_time_10_90_s(shape))
    assert timing.rise_time_10_90_s(shape) == pytest.approx(2.76e-9, abs=0.01e-9)
    assert paper / 2 / ours == pytest.approx(2.4, abs=0.05)


def test_merging_and_splitting_no_pixels_gives_no_pixels():
    t, w = echo.merge_elements(np.zeros((0, 4)), np.zeros((0, 4)), 1e-9)
    assert t.shape[0] == w.shape[0] == 0
    t, w = echo.split_elements(np.zeros((0, 4)), np.zeros((0, 4)), np.zeros(0))
    assert t.shape == w.shape == (0, 8)
