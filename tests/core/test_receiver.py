"""Eqs. 7-18: responsivity, gain, noise and SNR, against closed forms and the spec's figures."""

import numpy as np
import pytest
from scipy import constants as sc

import simcore
from simcore.receivers.lm_apd.apd import (
    excess_noise_factor,
    friis_noise_factor,
    miller_gain,
    receiver_model,
    unity_gain_responsivity_a_w,
)
from simcore.scene import SceneError

PAPER = simcore.Scene()


def test_eq13_thermal_noise_is_0199_microamps_at_298k_120mhz_50ohm():
    rx = receiver_model(PAPER.detector, PAPER.amplifiers, PAPER.laser.wavelength_m)
    assert rx.thermal_noise_a == pytest.approx(0.199e-6, abs=0.0005e-6)
    assert rx.thermal_noise_a == pytest.approx(np.sqrt(4 * sc.k * 298.15 * 120e6 / 50), rel=1e-12)


def test_eq17_friis_chain_of_table4_is_10515():
    f = friis_noise_factor((1.05, 1.15, 1.15), (100, 100, 100))
    assert f == pytest.approx(1.05 + 0.15 / 100 + 0.15 / 100**2, rel=1e-14)
    assert f == pytest.approx(1.0515, abs=5e-5)  # the spec's rounded figure


def test_sigma_n_is_0204_microamps_for_the_defaults():
    rx = receiver_model(PAPER.detector, PAPER.amplifiers, PAPER.laser.wavelength_m)
    assert rx.sigma_n_a == pytest.approx(0.204e-6, abs=0.001e-6)


def test_eq8_gain_follows_from_25_a_per_w_and_the_quantum_efficiency():
    r0 = unity_gain_responsivity_a_w(0.4, 1064e-9)
    assert r0 == pytest.approx(0.4 * sc.e * 1064e-9 / (sc.h * sc.c))
    rx = receiver_model(PAPER.detector, PAPER.amplifiers, PAPER.laser.wavelength_m)
    assert rx.responsivity_a_w == pytest.approx(25.0)
    assert rx.gain == pytest.approx(25.0 / r0)


def test_eq9_miller_gain_and_its_refusal_at_breakdown():
    assert miller_gain(200.0, 400.0, 2.0) == pytest.approx(1 / (1 - 0.25))
    assert miller_gain(399.9, 400.0, 2.0) == pytest.approx(1 / (1 - (399.9 / 400) ** 2))
    with pytest.raises(SceneError, match="breakdown"):
        miller_gain(400.0, 400.0, 2.0)


def test_bias_at_or_above_breakdown_is_refused_by_the_scene():
    with pytest.raises(SceneError, match="bias_voltage_v"):
        simcore.with_overrides(
            PAPER, {"detector.gain_from": "bias", "detector.bias_voltage_v": 400.0}
        )


def test_eq11_mcintyre_limits():
    assert excess_noise_factor(1.0, 0.02) == pytest.approx(1.0)
    assert excess_noise_factor(100.0, 0.0) == pytest.approx(2 - 1 / 100)
    assert excess_noise_factor(100.0, 1.0) == pytest.approx(100.0)


def test_eq14_eq18_snr_from_its_noise_terms():
    rx = receiver_model(PAPER.detector, PAPER.amplifiers, PAPER.laser.wavelength_m)
    i = 5e-6
    shot = np.sqrt(2 * sc.e * 120e6 * i * rx.gain * rx.excess_noise)
    snr_apd = i / np.sqrt(shot**2 + rx.dark_noise_a**2 + rx.thermal_noise_a**2)
    assert rx.snr(i) == pytest.approx(snr_apd / np.sqrt(1.051515), rel=1e-12)


def test_eq12_dark_noise_multiplies_only_the_bulk_current():
    d = simcore.with_overrides(PAPER, {"detector.dark_bulk_a": 0.0}).detector
    rx = receiver_model(d, PAPER.amplifiers, 1064e-9)
    assert rx.dark_noise_a == pytest.approx(np.sqrt(2 * sc.e * 1e-9 * 120e6))
