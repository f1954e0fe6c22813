"""The Geiger-mode receiver against closed forms (issue 17, item 4), each tolerance derived from
the trial count: per-pulse detection 1 - exp(-PDE N), the pile-up of the first-photon histogram
and Coates' correction of it, false events per gate with a non-paralysable dead time, the range
bias of the uncorrected histogram and its removal by the correction; and the receiver through the
pipeline (keys, stages, reproducibility, bad input)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

import simcore
from simcore import pointcloud
from simcore.constants import C, H
from simcore.receivers.gm_apd import detection as gm_detection
from simcore.receivers.gm_apd import events as gm_events
from simcore.receivers.gm_apd import histogram as gm_histogram
from simcore.receivers.gm_apd import response as gm_response

S_S = 5e-9 / 2.446386  # Gamma(2, s) scale of the default 5 ns pulse [s]


def one_surface(n_pixels, pe, t0_s=1e-6, rate_hz=0.0):
    """n pixels that see one surface at t0_s with pe photoelectrons per pulse."""
    return gm_events.PixelRates(
        rate_hz=np.full(n_pixels, float(rate_hz)),
        lit_pixel=np.arange(n_pixels),
        element_t_s=np.full((n_pixels, 1), t0_s),
        element_pe=np.full((n_pixels, 1), float(pe)),
        scale_s=S_S,
    )


def test_the_inverse_hazard_of_gamma2_inverts_its_cdf():
    x = np.array([1e-6, 1e-3, 0.1, 1.0, 3.0, 10.0, 50.0])
    y = x - np.log1p(x)  # 1 - G(x) = (1 + x) e^-x = e^-y
    np.testing.assert_allclose(-np.log1p(-gm_events.gamma2_cdf(x[:4])), y[:4], rtol=1e-12)
    np.testing.assert_allclose(gm_events.gamma2_inverse_hazard(y), x, rtol=1e-9)
    np.testing.assert_allclose(
        gm_events.inverse_hazard_fast(y), x, rtol=1e-6, atol=1e-6
    )  # < 2 fs at s = 2 ns


@pytest.mark.parametrize("photons", [0.5, 2.0, 6.0])
def test_per_pulse_detection_probability_is_one_minus_exp_of_minus_pde_n(photons):
    pde, n_pix, n_pulses = 0.35, 4000, 25
    det = gm_events.Detector(gate_s=4e-6, dead_time_s=1.0, jitter_s=1e-12, bin_s=250e-12)
    events = gm_events.simulate_frame(
        np.random.default_rng(1), one_surface(n_pix, pde * photons), det, 25
    )
    trials = n_pix * n_pulses
    p = 1.0 - math.exp(-pde * photons)
    assert len(events) == len(np.unique(events.pixel * n_pulses + events.pulse))  # one per pulse
    assert abs(len(events) / trials - p) < 5.0 * math.sqrt(p * (1 - p) / trials)


def gamma2_bin_rates(pe, t0_s, bin_s, n_bins):
    """Lambda_j: mean primary events of a Gamma(2, s) echo in each bin [j b, (j + 1) b)."""
    edges = np.arange(n_bins + 1) * bin_s
    return pe * np.diff(gm_events.gamma2_cdf((edges - t0_s) / S_S))


def test_the_piled_up_histogram_follows_coates_formula_and_the_correction_recovers_the_rate():
    pe, n_pix, n_pulses, bin_s, t0_s = 3.0, 2000, 50, 500e-12, 20e-9
    det = gm_events.Detector(gate_s=60e-9, dead_time_s=1.0, jitter_s=1e-13, bin_s=bin_s)
    events = gm_events.simulate_frame(
        np.random.default_rng(2), one_surface(n_pix, pe, t0_s), det, 50
    )
    trials = n_pix * n_pulses
    n_j = np.bincount(events.bin, minlength=det.n_bins).astype(float)
    lam = gamma2_bin_rates(pe, t0_s, bin_s, det.n_bins)
    before = np.r_[0.0, np.cumsum(lam)[:-1]]
    p_j = np.exp(-before) * -np.expm1(-lam)  # Coates: first event in bin j
    sd = np.sqrt(trials * p_j * (1 - p_j))
    z = special.ndtri(1 - 0.001 / (2 * det.n_bins))  # 0.1 % family-wise over the bins
    assert np.all(np.abs(n_j - trials * p_j) <= z * np.maximum(sd, 1.0))
    # the pile-up is real: the histogram's centroid is well before the rate's
    t = (np.arange(det.n_bins) + 0.5) * bin_s
    assert (n_j * t).sum() / n_j.sum() < (lam * t).sum() / lam.sum() - 0.3 * S_S
    # Coates' correction: Lambda_j = -ln(1 - n_j / (N - sum_{i<j} n_i)), delta-method sd
    armed = trials - np.r_[0.0, np.cumsum(n_j)[:-1]]
    ok = (n_j >= 30) & (armed - n_j >= 30)
    est = -np.log1p(-n_j[ok] / armed[ok])
    sd_est = np.sqrt(n_j[ok] / armed[ok] / (armed[ok] - n_j[ok]))
    assert ok.sum() >= 8
    assert np.all(np.abs(est - lam[ok]) <= z * sd_est)


@pytest.mark.parametrize(("rate_hz", "dead_s"), [(2e6, 300e-9), (5e5, 2e-6), (1e6, 1.0)])
def test_false_events_per_gate_follow_the_non_paralysable_dead_time(rate_hz, dead_s):
    """E N(T) = sum_k P(S_k <= T), S_k = (k - 1) d + Gamma(k, r): the k-th event after the gate
    opens; for d >= T it is 1 - exp(-r T), for d << T about r T / (1 + r d)."""
    gate_s, n_pix, n_pulses = 5e-6, 2000, 20
    rates = gm_events.PixelRates(
        rate_hz=np.full(n_pix, rate_hz),
        lit_pixel=np.zeros(0, np.int64),
        element_t_s=np.zeros((0, 1)),
        element_pe=np.zeros((0, 1)),
        scale_s=S_S,
    )
    det = gm_events.Detector(gate_s=gate_s, dead_time_s=dead_s, jitter_s=1e-12, bin_s=1e-9)
    # the bins cannot lose an event at the edges: jitter 1 ps, the gate a whole number of bins
    events = gm_events.simulate_frame(np.random.default_rng(3), rates, det, n_pulses)
    k = np.arange(1, 200)
    free = gate_s - (k - 1) * dead_s
    expected = float(
        np.sum(np.where(free > 0, special.gammainc(k, rate_hz * np.maximum(free, 0)), 0))
    )
    trials = n_pix * n_pulses
    # dead-time counts are under-dispersed (Var <= mean): sd of the mean <= sqrt(mean / trials)
    assert abs(len(events) / trials - expected) < 5.0 * math.sqrt(expected / trials)
    if dead_s >= gate_s:
        assert expected == pytest.approx(-math.expm1(-rate_hz * gate_s), rel=1e-12)
    else:
        steady = rate_hz * gate_s / (1 + rate_hz * dead_s)
        assert abs(expected - steady) < 1.0  # the start-up transient: less than one event


def window_estimates(pe, coates, n_pix=3000, n_pulses=60):
    """Centroid times of n_pix pixels of one surface at t0 over a fixed analysis window."""
    bin_s, t0_s, gate_s = 250e-12, 30e-9, 100e-9
    det = gm_events.Detector(gate_s=gate_s, dead_time_s=1.0, jitter_s=1e-13, bin_s=bin_s)
    rng = np.random.default_rng(4)
    events = gm_events.simulate_frame(rng, one_surface(n_pix, pe, t0_s), det, n_pulses)
    h = gm_histogram.histogram(events, det.n_bins, n_pulses)
    start = int((t0_s - 3 * S_S) / bin_s)
    length = int(16 * S_S / bin_s)
    est = gm_histogram.centroid_times(
        h,
        np.arange(n_pix),
        np.full(n_pix, start),
        length,
        bin_s,
        np.zeros(n_pix),
        det.n_bins,
        coates,
    )
    t_c = (np.arange(start, start + length) + 0.5) * bin_s
    return est.t_s, t0_s, t_c, det


@pytest.mark.parametrize("pe", [0.3, 1.0, 2.5])
def test_range_bias_of_the_raw_histogram_grows_with_signal_and_the_coates_correction_removes_it(
    pe,
):
    t_raw, t0_s, t_c, det = window_estimates(pe, coates=False)
    t_cor, *_ = window_estimates(pe, coates=True)
    edges = np.r_[t_c - 0.5 * det.bin_s, t_c[-1] + 0.5 * det.bin_s]
    lam = pe * np.diff(gm_events.gamma2_cdf((edges - t0_s) / S_S))
    p = np.exp(-np.r_[0.0, np.cumsum(lam)[:-1]]) * -np.expm1(-lam)  # from the window's start
    predicted_raw_s = (p * t_c).sum() / p.sum() - (t0_s + 2 * S_S)
    bias_raw = t_raw - (t0_s + 2 * S_S)
    bias_cor = t_cor - (t0_s + 2 * S_S)
    n = len(t_raw)
    tol_raw = 5 * np.std(bias_raw) / math.sqrt(n)
    tol_cor = 5 * np.std(bias_cor) / math.sqrt(n)
    # the raw centroid's bias is the piled-up distribution's (ratio-of-means, O(1/N) apart)
    assert abs(np.mean(bias_raw) - predicted_raw_s) < tol_raw + 0.01 * abs(predicted_raw_s)
    # the truncation of the window and bin centring leave < 2 ps; the correction removes the rest
    assert abs(np.mean(bias_cor)) < tol_cor + 2e-12
    if pe >= 1.0:
        assert predicted_raw_s < -0.2 * S_S  # the raw bias is large: tens of centimetres
        assert abs(np.mean(bias_cor)) < 0.1 * abs(predicted_raw_s)


# ----------------------------------------------------------------------------------------------
# the receiver in the pipeline
# ----------------------------------------------------------------------------------------------
GM = {"receiver.kind": "gm_apd", "pixels": 32, "timing.range_gate_m": 200.0}


def low_signal(plate_scene, pe_target=1.0, **more):
    """A plate scene whose pixels get about ``pe_target`` photoelectrons per pulse."""
    scene = plate_scene(size_m=12.0, **GM, **more)  # 25 x 25 of the 32 x 32 pixels
    res = simcore.simulate(scene)
    scale = pe_target / float(np.median(res.receiver.signal_pe))
    energy = scene.laser.pulse_energy_j * scale
    return simcore.with_overrides(scene, {"pulse_energy_j": energy})


def test_the_signal_photoelectrons_are_pde_times_the_echo_energy_over_h_nu(plate_scene):
    scene = plate_scene(**GM)
    res = simcore.simulate(scene)
    # the frame's pulses carry laser.pulse_energy_j less gm.attenuation_db (50 dB by default)
    assert scene.gm.attenuation_db == 50.0
    e_r = scene.laser.pulse_energy_j * 1e-5 * res.echo.weights.sum(axis=1)
    hv = H * C / scene.laser.wavelength_m
    np.testing.assert_allclose(res.receiver.signal_pe, scene.gm.pde * e_r / hv, rtol=1e-12)
    assert res.summary()["receiver_kind"] == "gm_apd"


def test_a_threshold_change_reruns_only_detection_and_a_frame_is_reproducible(plate_scene):
    scene = low_signal(plate_scene, 1.0)
    pipe = simcore.Pipeline()
    a = pipe.run(scene)
    b = pipe.run(simcore.with_overrides(scene, {"tnr": 3.0}))
    assert {s for s, t in b.timings_s.items() if t > 0} == {"detection", "cloud"}
    c = simcore.Pipeline().run(scene)
    np.testing.assert_array_equal(a.points, c.points)
    assert a.detection.detected.mean() > 0.9
    d = simcore.Pipeline().run(simcore.with_overrides(scene, {"seed": 5}))
    assert not np.array_equal(a.receiver.events.bin, d.receiver.events.bin)


def test_low_signal_ranges_are_unbiased_within_their_predicted_noise(plate_scene):
    scene = low_signal(plate_scene, 0.5, **{"gm.pulses": 200})
    res = simcore.simulate(scene)
    d = res.detection
    err = d.range_m[d.detected] - d.range_true_m[d.detected]
    assert d.detected.sum() > 500
    # mean error within 5 sigma of the mean; the spread within 30 % of the prediction
    sigma = np.median(d.range_sigma_m[d.detected])
    assert abs(err.mean()) < 5 * np.std(err) / math.sqrt(len(err)) + 1e-3
    assert 0.7 * sigma < np.std(err) < 1.3 * sigma
    assert set(res.attributes) >= {"counts", "signal_pe", "is_outlier", "snr"}


def test_background_power_raises_the_threshold_and_gives_outliers(plate_scene):
    scene = low_signal(plate_scene, 1.0)
    echo = simcore.simulate(scene).echo
    hv = H * C / scene.laser.wavelength_m
    rate = 20e6  # background photoelectrons per second per pixel
    power = np.full((32, 32), rate * hv / scene.gm.pde)
    rx = gm_response.respond(scene, echo, power)
    det = gm_detection.detect(scene, echo, rx)
    np.testing.assert_allclose(rx.rate_hz, rate + scene.gm.dark_count_rate_hz)
    quiet = gm_detection.detect(scene, echo, gm_response.respond(scene, echo, None))
    assert det.threshold_counts.min() > quiet.threshold_counts.max()
    # the union bound over the gate's windows caps each pixel's false-alarm probability: the
    # outliers are at most that many, plus 5 standard deviations of a Poisson count
    bound = det.n_false_per_pixel * 32 * 32
    assert len(det.outliers.pixel) <= bound + 5 * math.sqrt(max(bound, 1.0))


def test_the_first_photon_cloud_has_one_point_per_pixel_that_fired(plate_scene):
    scene = low_signal(plate_scene, 2.0)
    res = simcore.simulate(scene)
    cloud = pointcloud.first_photon_cloud(res)
    fired = np.unique(res.receiver.events.pixel[res.receiver.events.pulse == 0])
    assert len(cloud) == len(fired)
    p = 1 - math.exp(-float(np.median(res.receiver.signal_pe)))
    lit = len(res.echo.pixel)
    echo_points = int((~cloud.attributes["is_outlier"]).sum())
    assert abs(echo_points - p * lit) < 5 * math.sqrt(lit * p * (1 - p)) + 0.05 * lit


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("gm.pde", 0.0, r"gm.pde = 0.0 is out of range; valid range \(0, 1\]"),
        ("gm.pde", 1.2, "gm.pde = 1.2 is out of range"),
        ("gm.dark_count_rate_hz", -1.0, "gm.dark_count_rate_hz = -1.0 is out of range"),
        ("gm.dead_time_s", -1e-9, "gm.dead_time_s = -1e-09 is out of range"),
        ("gm.jitter_s", 0.0, r"gm.jitter_s = 0.0 is out of range; valid range \(0,"),
        ("gm.bin_s", 0.0, r"gm.bin_s = 0.0 is out of range; valid range \(0,"),
        ("gm.pulses", 0, r"gm.pulses = 0 is out of range; valid range \[1, 10000\]"),
        ("gm.pulses", 10**6, "gm.pulses = 1000000 is out of range"),
        ("gm.crosstalk", 0.9, "gm.crosstalk = 0.9 is out of range"),
    ],
)
def test_bad_geiger_mode_input_names_the_key(key, value, message):
    with pytest.raises(simcore.SceneError, match=message):
        simcore.with_overrides(simcore.Scene(), {key: value})


def test_a_frame_beyond_the_event_budget_is_refused_naming_the_key(plate_scene):
    # the full pulse (no attenuation): thousands of photoelectrons a pixel, each recorded
    more = {"gm.dead_time_s": 0.0, "gm.pulses": 10_000, "gm.attenuation_db": 0.0}
    scene = plate_scene(**GM, **more)
    with pytest.raises(simcore.SceneError, match="gm.dead_time_s = 0 s lets a pixel record"):
        simcore.simulate(scene)


def test_afterpulsing_and_crosstalk_add_their_own_events():
    n_pix, n_pulses = 32 * 32, 20
    rates = gm_events.PixelRates(
        rate_hz=np.full(n_pix, 1e6),
        lit_pixel=np.zeros(0, np.int64),
        element_t_s=np.zeros((0, 1)),
        element_pe=np.zeros((0, 1)),
        scale_s=S_S,
    )
    base = dict(gate_s=2e-6, dead_time_s=50e-9, jitter_s=1e-12, bin_s=1e-9)
    rng = np.random.default_rng(9)
    plain = gm_events.simulate_frame(rng, rates, gm_events.Detector(**base), n_pulses)
    ap = gm_events.simulate_frame(
        rng, rates, gm_events.Detector(**base, afterpulsing=0.2), n_pulses
    )
    ct = gm_events.simulate_frame(rng, rates, gm_events.Detector(**base, crosstalk=0.1), n_pulses)
    n_ap = int((ap.kind == gm_events.EVENT_AFTERPULSE).sum())
    n_own = int((ap.kind != gm_events.EVENT_AFTERPULSE).sum())
    # each avalanche afterpulses with p = 0.2 (unless the gate has closed): at most 0.2 per event
    assert 0.15 * (n_own + n_ap) < n_ap < 0.2 * (n_own + n_ap) + 4 * math.sqrt(n_ap)
    n_ct = int((ct.kind == gm_events.EVENT_CROSSTALK).sum())
    # p_ct per avalanche, less the edge pixels' missing neighbours and dead neighbours
    assert 0.07 * len(plain) < n_ct < 0.1 * len(plain) + 4 * math.sqrt(n_ct)


def test_the_threshold_count_holds_at_a_tnr_beyond_the_survival_functions_reach():
    """TNR 30 asks for a false-alarm probability of 1e-198 a frame: scipy's Poisson isf gives NaN
    below about 1e-30, the tail bound the exact count or one above it (checked where isf
    resolves)."""
    from scipy import stats

    from simcore.receivers.gm_apd.windows import (
        _tail_count,
        false_alarm_probability,
        threshold_counts,
    )

    k = threshold_counts(np.array([1e-9, 0.01, 2.0]), 100.0, false_alarm_probability(30.0))
    assert np.all(np.isfinite(k)) and np.all(np.diff(k) > 0)
    for mu in np.geomspace(1e-9, 50.0, 25):
        for q in (1e-3, 1e-8, 1e-16):
            exact = stats.poisson.isf(q, mu) + 1.0
            assert exact <= _tail_count(np.array([mu]), q)[0] <= exact + 1.0
