"""The Geiger-mode pile-up prediction (issue 25, item 3) against an independent first-photon
simulation: per pulse, the first of a Poisson process of N_s photoelectrons of Eq. 1's pulse
(drawn by inverting its cumulative intensity with scipy's inverse incomplete gamma function),
Gaussian jitter, TDC bins, and Coates' centroid over a fixed window, at 0.1, 1, 10 and 100
photoelectrons per pulse and 100, 1,000 and 10,000 pulses; then through the pipeline, the
summary's bias and scatter against the points' errors from the true (energy-weighted) range,
with and without the first-photon fit, the photon-starved default frame, the CLI's warning and
``lmapd compare``'s bias. Tolerances from the trial counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

import simcore
from simcore.cli import main
from simcore.compare import compare
from simcore.constants import C
from simcore.receivers.gm_apd import expected as gm_expected

S_S = 5e-9 / 2.446386  # Gamma(2, s) scale of the default 5 ns pulse [s]
BIN_S, JITTER_S, T0_S = 250e-12, 200e-12, 10e-9
START, LENGTH = int((T0_S - 3 * S_S) / BIN_S), int(16 * S_S / BIN_S)
TOTAL_PULSES = 1_000_000  # pixels x pulses per case


def first_photon_centroids(rng, pe, n_pix, n_pulses):
    """(n_pix,) Coates centroids [s] of first-photon histograms simulated pulse by pulse."""
    e = rng.standard_exponential((n_pix, n_pulses))
    fired = e < pe  # the Poisson process reaches E within the pulse
    x = special.gammaincinv(2.0, np.where(fired, e / pe, 0.5))  # pe G(x) = E
    t = T0_S + S_S * x + JITTER_S * rng.standard_normal(x.shape)
    b = np.floor(t / BIN_S).astype(np.int64) - START
    ok = fired & (b >= 0) & (b < LENGTH)
    rows = np.broadcast_to(np.arange(n_pix)[:, None], b.shape)
    n = np.zeros((n_pix, LENGTH))
    np.add.at(n, (rows[ok], b[ok]), 1.0)
    # a pulse whose first photon falls before the window cannot fire in it
    early = (fired & (b < 0)).sum(axis=1)
    armed = (
        n_pulses
        - early[:, None]
        - np.concatenate([np.zeros((n_pix, 1)), np.cumsum(n, axis=1)[:, :-1]], axis=1)
    )
    a = np.maximum(armed, 1.0)
    v = np.where(armed > 0, -np.log1p(-np.minimum(n, a - 0.5) / a), 0.0)
    t_c = (START + np.arange(LENGTH) + 0.5) * BIN_S
    total = v.sum(axis=1)
    keep = total > 0
    return ((v * t_c).sum(axis=1) / np.where(keep, total, 1.0))[keep]


@pytest.mark.parametrize("n_pulses", [100, 1_000, 10_000])
@pytest.mark.parametrize("pe", [0.1, 1.0, 10.0, 100.0])
def test_the_predicted_coates_bias_and_sd_match_a_first_photon_simulation(pe, n_pulses):
    n_pix = TOTAL_PULSES // n_pulses
    t = gm_expected.Timing(
        scale_s=S_S, jitter_s=JITTER_S, bin_s=BIN_S, dead_time_s=1.0, n_pulses=n_pulses
    )
    q, alpha = gm_expected.expected_histogram(
        t,
        np.array([[T0_S]]),
        np.array([[pe]]),
        np.zeros(1),
        np.array([START]),
        LENGTH,
        np.ones(1),
    )
    pred = gm_expected.coates_centroid(t, q, alpha, np.array([START]), np.zeros(1))
    bias_pred = pred.t_s[0] - 2 * S_S - T0_S
    sd_pred = pred.sd_s[0]
    tc = first_photon_centroids(np.random.default_rng(int(pe * 10) + n_pulses), pe, n_pix, n_pulses)
    bias = tc.mean() - 2 * S_S - T0_S
    sd = tc.std()
    m = len(tc)
    assert m > 0.9 * n_pix
    se = sd / math.sqrt(m)
    # the bias: within 4 standard errors of the mean, plus 5 % of it (the prediction's own
    # approximations: the ratio of expectations, interpolated tables)
    assert abs(bias - bias_pred) < 4 * se + 0.05 * abs(bias_pred) + 1e-12
    # the pile-up is there: at 10 pe and more the bias is tens of centimetres in range
    if pe >= 10:
        assert bias_pred * 0.5 * 3e8 < -0.03
    # the sd: within 4 standard errors of a sample sd (sd / sqrt(2 m)) plus 10 %, or 5 mm
    tol = 4 * sd / math.sqrt(2 * m) + max(0.1 * sd, 2 * 5e-3 / 3e8)
    assert abs(sd_pred - sd) < tol


# ----------------------------------------------------------------------------------------------
# through the pipeline: the summary's figures against the ground truth
# ----------------------------------------------------------------------------------------------
GM = {"receiver.kind": "gm_apd", "pixels": 32, "timing.range_gate_m": 200.0}


def plate_at(plate_scene, pe, **more):
    """A 12 m plate (25 x 25 of the 32 x 32 pixels) whose pixels get about ``pe``
    photoelectrons per pulse."""
    scene = plate_scene(size_m=12.0, **GM, **more)
    res = simcore.simulate(scene)
    scale = pe / float(np.median(res.receiver.signal_pe))
    return simcore.with_overrides(scene, {"pulse_energy_j": scene.laser.pulse_energy_j * scale})


@pytest.mark.parametrize("correction", ["none", "fit"])
@pytest.mark.parametrize("pe", [0.3, 10.0, 1000.0])
def test_the_summary_gives_the_bias_and_scatter_the_points_have(plate_scene, pe, correction):
    scene = plate_at(plate_scene, pe, **{"gm.pileup_correction": correction})
    res = simcore.simulate(scene)
    d, s = res.detection, res.summary()
    err = d.range_m[d.detected] - d.range_true_m[d.detected]
    n = len(err)
    assert n > 500
    sd = float(np.std(err))
    # the truth formula: the noise-free energy-weighted range of each pixel's echo elements
    w, a = np.asarray(res.echo.weights), np.asarray(res.echo.arrivals_s)
    truth = 0.5 * C * (w * a).sum(axis=1) / w.sum(axis=1)
    np.testing.assert_allclose(d.range_true_m, truth, rtol=1e-12)
    assert s["gm.range_error_median_m"] == pytest.approx(float(np.median(err)), abs=1e-12)
    # predicted against measured: within 10 % or 5 mm, plus 4 standard errors of the sample
    bias, sigma = s["gm.range_bias_m"], s["gm.range_sigma_m"]
    assert abs(bias - err.mean()) < max(0.1 * abs(bias), 5e-3) + 4 * sd / math.sqrt(n)
    assert abs(sigma - sd) < max(0.1 * sd, 5e-3) + 4 * sd / math.sqrt(2 * n)
    assert s["range_sigma_m_median"] == pytest.approx(
        float(np.median(d.range_sigma_m[d.detected])), rel=1e-12
    )
    piled = [line for line in s["warnings"] if "piled up" in line]
    if pe >= 10:
        assert s["gm.saturated_pixel_fraction"] > 0.9 and len(piled) == 1
    else:
        assert s["gm.saturated_pixel_fraction"] < 0.5 and not piled
    if correction == "none" and pe >= 10:
        assert bias < -0.15  # the piled-up centroid ranges early, and the summary says so
    if correction == "fit":  # the first-photon fit leaves millimetres at any flux
        assert abs(err.mean()) < 5e-3 + 4 * sd / math.sqrt(n)


def test_the_default_geiger_mode_frame_of_the_paper_scene_is_photon_starved_and_unbiased():
    scene = simcore.with_overrides(simcore.Scene(), {"receiver.kind": "gm_apd"})
    res = simcore.simulate(scene)
    d, s = res.detection, res.summary()
    err = d.range_m[d.detected] - d.range_true_m[d.detected]
    assert len(err) > 5000
    assert abs(np.median(err)) < 0.02 and abs(s["gm.range_bias_m"]) < 0.02
    assert np.median(res.receiver.signal_pe) < 1.0
    assert s["gm.saturated_pixel_fraction"] < 0.5
    assert not [line for line in s["warnings"] if "piled up" in line]
    assert s["gm.frame_pulse_energy_j"] == pytest.approx(scene.laser.pulse_energy_j * 1e-5)


def test_simulate_prints_the_pile_up_warning_and_compare_calls_the_bias_bias(
    plate_scene, tmp_path, capsys
):
    argv = ["simulate", "--set", "receiver.kind=gm_apd", "--set", "pixels=32"]
    argv += ["--set", "gm.attenuation_db=0", "--out", str(tmp_path / "c.ply")]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len([ln for ln in lines if ln.startswith("warning: Geiger mode:")]) == 1
    assert len([ln for ln in lines if ln.startswith("Geiger mode: range bias")]) == 1
    base = plate_scene(size_m=12.0, **GM, **{"gm.attenuation_db": 0.0})
    rows = compare(base, distances_m=(500.0,), energies_j=(5e-3,))
    gm = next(r for r in rows if r.receiver == "gm_apd")
    # piled up: the error is a bias several times its spread, as predicted
    assert gm.range_bias_m < -0.3 and abs(gm.range_bias_m) > 5 * gm.range_sd_m
    assert abs(gm.predicted_bias_m - gm.range_bias_m) < 0.1 * abs(gm.range_bias_m)


def test_a_frame_without_lit_pixels_has_no_geiger_mode_figures():
    # 16 x 16 pixels at 10 km: the target falls between the pixels' rays
    scene = simcore.with_overrides(
        simcore.Scene(), {"receiver.kind": "gm_apd", "pixels": 16, "distance_m": 10_000.0}
    )
    s = simcore.simulate(scene).summary()
    assert s["n_lit_pixels"] == 0
    assert s["gm.range_bias_m"] is None and s["gm.range_sigma_m"] is None
    assert s["gm.saturated_pixel_fraction"] == 0.0
    assert not [line for line in s["warnings"] if "piled up" in line]
