"""Eqs. 27-28: detection probability and false alarms; the outlier draw."""

import numpy as np
import pytest
from scipy import constants as sc
from scipy import special

from simcore.receivers.lm_apd import detection


def test_eq27_reduces_to_the_papers_form_when_thermal_noise_dominates():
    sigma_n = 0.2e-6
    i_pk = np.linspace(0, 10, 41) * sigma_n
    ours = detection.detection_probability(i_pk, 5 * sigma_n, sigma_n)  # no shot noise
    paper = detection.detection_probability_paper(i_pk / sigma_n, 5.0)
    assert np.allclose(ours, paper, atol=1e-12)
    assert paper[20] == pytest.approx(0.5)  # SNR = TNR


def test_eq27_shot_noise_at_the_peak_lowers_the_probability_above_threshold():
    p_thermal = detection.detection_probability(6e-6, 5e-6, 0.5e-6)
    p_shot = detection.detection_probability(6e-6, 5e-6, 0.9e-6)
    assert p_shot < p_thermal


def test_eq28_rice_rate_of_the_gaussian_band_limit_is_sqrt_2_over_pi_b():
    b = 120e6
    sigma = 1 / (4 * np.sqrt(np.pi) * b)
    f = np.linspace(0, 20 * b, 400001)
    h2 = np.exp(-4 * np.pi**2 * sigma**2 * f**2)
    nu0 = np.sqrt(np.trapezoid(f**2 * h2, f) / np.trapezoid(h2, f))
    assert detection.rice_rate_hz(b) == pytest.approx(nu0, rel=1e-6)


def test_eq28_false_alarms_closed_forms():
    ours = detection.false_alarms_per_pixel(5.0, 1000.0, 120e6)
    assert ours == pytest.approx(2000 / sc.c * np.sqrt(2 / np.pi) * 120e6 * np.exp(-12.5))
    paper = detection.false_alarms_per_pixel_paper(5.0, 1000.0, 12e6)
    assert paper == pytest.approx(2.2 * 2000 / sc.c * 12e6 * 0.5 * special.erfc(5 / np.sqrt(2)))


def test_outlier_count_is_poisson_with_the_expected_mean():
    rng = np.random.default_rng(7)
    lam, trials = 50.0, 4000
    counts = [
        len(detection.draw_outliers(rng, 1000, lam / 1000, 500.0, 1000.0).pixel)
        for _ in range(trials)
    ]
    # 5 standard errors: a false failure has probability ~6e-7 (and the seed fixes the draw)
    assert np.mean(counts) == pytest.approx(lam, abs=5 * np.sqrt(lam / trials))
    assert np.var(counts) == pytest.approx(lam, rel=5 * np.sqrt(2 / trials))


def test_outliers_lie_in_the_gate_clipped_at_zero():
    rng = np.random.default_rng(1)
    out = detection.draw_outliers(rng, 100, 50.0, 200.0, 1000.0)
    assert out.range_m.min() >= 0.0 and out.range_m.max() <= 700.0
    assert out.pixel.min() >= 0 and out.pixel.max() < 100
