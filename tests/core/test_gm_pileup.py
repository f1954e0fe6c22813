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
from simcore.receivers.gm_apd import selection as gm_selection

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
# detection's selection at a few counts: a pixel is a point only when its densest window holds
# its threshold, which keeps the realisations whose counts bunch (none in Eq. 1's late tail)
# ----------------------------------------------------------------------------------------------
WIDTH, PRE = 20, 13  # detect's peak window (FWHM with jitter) and the analysis window's lead
WINDOW = 115  # detect's analysis window: s and 4 jitters before the peak window, 12 s after
SPAN = 400  # bins simulated (the echo at bin 160, its tail cut at 60 s: probability 1e-24)
GATE = 10**6  # bins of the model's gate (the window never reaches its ends)


def detected_centroid_errors(rng, pe, n_pix, n_pulses, k_t):
    """(n_pix,) errors [s] of first-photon histograms read by the frame's estimator, and
    whether each is detected: per pulse the first of a Poisson process of ``pe``
    photoelectrons (a uniform bin phase), jitter, bins; the densest window of WIDTH bins from
    an occupied bin (the earliest on ties), detected at ``k_t`` counts; Coates' centroid over
    the analysis window from PRE bins before it, less 2 s (NaN where it holds nothing)."""
    t0 = 160 * BIN_S + rng.random(n_pix) * BIN_S
    e = rng.standard_exponential((n_pix, n_pulses))
    fired = e < pe
    x = special.gammaincinv(2.0, np.where(fired, e / pe, 0.5))
    t = t0[:, None] + S_S * x + JITTER_S * rng.standard_normal(x.shape)
    b = np.clip(np.floor(t / BIN_S).astype(np.int64), 0, SPAN - 1)
    rows = np.arange(n_pix)
    flat = (rows[:, None] * SPAN + b)[fired]
    h = np.bincount(flat, minlength=n_pix * SPAN).reshape(n_pix, SPAN).astype(float)
    cum = np.concatenate([np.zeros((n_pix, 1)), np.cumsum(h, axis=1)], axis=1)
    start = np.arange(SPAN - WIDTH + 1)
    in_w = np.where(h[:, start] > 0, cum[:, start + WIDTH] - cum[:, start], -1.0)
    peak = np.argmax(in_w, axis=1)
    detected = in_w[rows, peak] >= k_t
    cols = (peak - PRE)[:, None] + np.arange(WINDOW)[None, :]
    n = h[rows[:, None], cols]  # the echo lies far inside SPAN: no window leaves it
    armed = n_pulses - cum[rows, peak - PRE][:, None] - (np.cumsum(n, axis=1) - n)
    a = np.maximum(armed, 1.0)
    v = np.where(armed > 0, -np.log1p(-np.minimum(n, a - 0.5) / a), 0.0)
    total = v.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t_c = (v * (cols + 0.5) * BIN_S).sum(axis=1) / total
    return t_c - 2 * S_S - t0, detected


def predicted_pixel(pe, n_pulses, k_t):
    """The model's mean error of one such pixel over all realisations (the expected
    histogram's Coates centroid, over four bin phases), and the selection's shift of the
    detected pixels' mean and their median less that mean [s]."""
    t = gm_expected.Timing(
        scale_s=S_S, jitter_s=JITTER_S, bin_s=BIN_S, dead_time_s=1.0, n_pulses=n_pulses
    )
    bias, counts = [], []
    for phase in (0.125, 0.375, 0.625, 0.875):
        t0 = 160 * BIN_S + phase * BIN_S
        start, q, alpha = gm_expected.expected_windows(
            t, np.array([[t0]]), np.array([[pe]]), np.zeros(1), np.ones(1), WIDTH, PRE, WINDOW, GATE
        )
        c = gm_expected.coates_centroid(t, q, alpha, start, np.zeros(1), True, k_t)
        bias.append(c.t_s[0] - 2 * S_S - t0)
        counts.append(c.signal_counts[0])
    table = gm_selection.selection_table(S_S, JITTER_S, BIN_S, WIDTH, PRE, WINDOW, n_pulses, True)
    shift, median = gm_selection.selection_shifts(table, np.array([np.mean(counts)]), n_pulses, k_t)
    return float(np.mean(bias)), float(shift[0]), float(median[0])


@pytest.mark.parametrize(
    ("pe", "n_pulses", "k_t"),
    [(0.05, 100, 4), (0.1, 100, 4), (0.01, 1_000, 6)],  # 4.9, 9.5 and 10 counts a pixel
)
def test_detection_keeps_the_bunched_realisations_and_the_summary_predicts_their_errors(
    pe, n_pulses, k_t
):
    n_pix = 20_000 if n_pulses == 100 else 2_000
    err, det = detected_centroid_errors(np.random.default_rng(2503), pe, n_pix, n_pulses, k_t)
    ok = np.isfinite(err)
    err, det = err[ok], det[ok]
    m, m_det = len(err), int(det.sum())
    assert 0.3 * m < m_det < m  # the threshold drops some pixels and keeps most
    bias, shift, median = predicted_pixel(pe, n_pulses, k_t)
    mm = 2 * 1e-3 / C  # a millimetre of range [s]
    # over all realisations the expected histogram's centroid holds within 4 standard errors
    # and a few millimetres (its ratio of expectations and its window at the expected place:
    # +1.4 +- 0.3 mm measured at 0.1 pe over 300,000 pixels, +4.0 +- 0.7 at 0.05 pe)
    assert abs(err.mean() - bias) < 4 * err.std() / math.sqrt(m) + 5 * mm
    # the mechanism: the detected pixels' mean error sits early of all pixels', beyond 4
    # standard errors of the difference (from its influence function)
    p_det = m_det / m
    psi = det * (err - err[det].mean()) / p_det - (err - err.mean())
    assert err[det].mean() - err.mean() < -4 * psi.std() / math.sqrt(m)
    # and the table predicts the detected pixels' mean and median error (what gm.range_bias_m
    # reports): within 4 standard errors (a sample median's: 1.2533 sd / sqrt(n)) and a
    # millimetre (the table's own spread over seeds: 0.4 mm at 5 counts)
    se = err[det].std() / math.sqrt(m_det)
    assert abs(err[det].mean() - (bias + shift)) < 4 * se + mm
    assert abs(np.median(err[det]) - (bias + median)) < 4 * 1.2533 * se + mm


def test_the_selection_table_holds_the_closed_forms_of_a_raw_centroid():
    table = gm_selection.selection_table(S_S, JITTER_S, BIN_S, WIDTH, PRE, WINDOW, 100, False)
    # a window holds at least one of the m counts (it starts at one) and at most all of them,
    # so m counts never reach a threshold above m
    for m, r in enumerate(table.draws, start=1):
        assert np.all((table.peak[m - 1, :r] >= 1) & (table.peak[m - 1, :r] <= m))
    m = np.arange(1, len(table.draws) + 1)
    # the analysis window at its expected place holds the whole pulse (all but 4e-5 of it)
    assert np.all(table.den > m * (1 - 1e-3))
    # and the raw centroid of m counts there is unbiased whatever m (Eq. 1's mean delay 2 s,
    # bins centred over a uniform phase): within 4 standard errors, a count's sd
    # sqrt(2 s^2 + jitter^2 + bin^2 / 12) over sqrt(m draws)
    sd_one = math.sqrt(2 * S_S**2 + JITTER_S**2 + BIN_S**2 / 12)
    assert np.all(np.abs(table.num / table.den) < 4 * sd_one / np.sqrt(m * table.draws))
    # the median of a centroid of few counts of a pulse skewed late lies early of its mean
    _, median = gm_selection.selection_shifts(table, np.array([2.0, 9.5]), 100, 4.0)
    assert np.all(median < 0)
    # beyond MU_MAX the table stands aside: no shift, and the Cornish-Fisher median
    far_shift, far_median = gm_selection.selection_shifts(table, np.array([100.0]), 100, 4.0)
    assert far_shift[0] == 0.0 and np.isnan(far_median[0])


# ----------------------------------------------------------------------------------------------
# through the pipeline: the summary's figures against the ground truth
# ----------------------------------------------------------------------------------------------
GM = {"receiver.kind": "gm_apd", "pixels": 32, "timing.range_gate_m": 200.0}


def plate_at(plate_scene, pe, **more):
    """A 12 m plate (25 x 25 of the 32 x 32 pixels, or ``pixels``) whose pixels get about
    ``pe`` photoelectrons per pulse."""
    scene = plate_scene(size_m=12.0, **{**GM, **more})
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


def test_the_photon_starved_summary_gives_the_median_error_of_the_detected_points(plate_scene):
    # 0.1 pe a pulse, 100 pulses: about 10 counts a pixel, 3 % of the plate's pixels below the
    # threshold; what gm.range_bias_m predicts is the median of the points' errors
    scene = plate_at(plate_scene, 0.1, pixels=64)
    res = simcore.simulate(scene)
    d, s = res.detection, res.summary()
    err = d.range_m[d.detected] - d.range_true_m[d.detected]
    n, sd = len(err), float(np.std(err))
    assert n > 2000 and float(np.median(res.receiver.signal_pe)) == pytest.approx(0.1, rel=0.05)
    bias = s["gm.range_bias_m"]
    assert abs(bias - np.median(err)) < max(0.1 * abs(bias), 5e-3) + 4 * 1.2533 * sd / math.sqrt(n)
    # the selection and the skewness of a few counts put it early of the mean by about 0.1 sd
    assert -0.2 * sd < bias < -0.05 * sd


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
