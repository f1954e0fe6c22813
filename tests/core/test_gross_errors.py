"""The discriminator's gross errors in the statistical model (docs/physics.md#gross-errors): its
plain range sd against the waveform Monte Carlo's at SNR 6, 19 and 70.

Both models run through ``lm_apd.detect`` on the same synthetic single-surface echoes (the
paper's receiver and pulse, TNR 5, first stop, a 10 m gate: about 1e-5 false alarms a pixel).
Tolerances: the issue's 10 % model tolerance plus three standard errors of the ratio of two
sample sds, each sigma sqrt((kurtosis - 1) / (4 n)) (the sampling spread of a standard deviation
of any distribution with that kurtosis, taken from the sample).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import constants as sc
from support.mc_scene import DT, K_ATT, RX, SHAPE, T_D, E

import simcore
from simcore import background, echo
from simcore.echo import EchoStage
from simcore.receivers.lm_apd import detection
from simcore.receivers.lm_apd import gross_errors as gross
from simcore.receivers.lm_apd import receiver as lm_apd

C = sc.c
SNRS = (6.0, 19.0, 70.0)
N_EACH = {6.0: 40_000, 19.0: 4_000, 70.0: 4_000}
PIXELS = 220  # 48,400 >= the echoes


def scene(noise_model: str):
    return simcore.with_overrides(
        simcore.Scene(),
        {
            "pixels": PIXELS,
            "fidelity.noise_model": noise_model,
            "timing.range_gate_m": 10.0,
            "timing.max_stops": 1,
            "seed": 4,
        },
    )


def synthetic_echoes(rng):
    """Single surfaces at SNR_na of SNRS, at uniform ranges 498-502 m (every sample phase)."""
    snr = np.concatenate([np.full(N_EACH[s], s) for s in SNRS])
    i_pk = RX.peak_current_for_snr(snr)
    weights = (i_pk / (RX.responsivity_a_w * E * SHAPE.peak_w_per_j))[:, None]
    arrivals = 2.0 * rng.uniform(498.0, 502.0, size=(len(snr), 1)) / C
    feats = echo.echo_features(SHAPE, arrivals, weights, DT, T_D, K_ATT)
    zeros = np.zeros(len(snr), dtype=np.int32)
    stage = EchoStage(
        model=None, shape=SHAPE, dt_s=DT, cfd_delay_s=T_D, pixel=np.arange(len(snr)),
        arrivals_s=arrivals, weights=weights, features=feats, material_id=zeros, facet_id=zeros,
    )  # fmt: skip
    return stage, snr


def sd_and_se(err):
    """The plain sd of the finite errors and its standard error, sd sqrt((kurtosis - 1) / 4n)."""
    e = err[np.isfinite(err)]
    sd = e.std()
    kurtosis = np.mean((e - e.mean()) ** 4) / sd**4
    return sd, sd * np.sqrt((kurtosis - 1.0) / (4.0 * len(e)))


@pytest.fixture(scope="module")
def errors():
    stage, snr = synthetic_echoes(np.random.default_rng(11))
    out = {}
    for model in ("statistical", "montecarlo"):
        s = scene(model)
        rx = lm_apd.respond(s, stage, background.dark(PIXELS))
        d = lm_apd.detect(s, stage, rx)
        out[model] = d.range_m - d.range_true_m
    return out, snr, d.range_sigma_m


@pytest.mark.parametrize("snr", SNRS)
def test_the_statistical_plain_range_sd_is_within_10_percent_of_the_monte_carlos(errors, snr):
    out, snr_of, sigma = errors
    sel = snr_of == snr
    sd_stat, se_stat = sd_and_se(out["statistical"][sel])
    sd_mc, se_mc = sd_and_se(out["montecarlo"][sel])
    ratio = sd_stat / sd_mc
    tol = 0.10 + 3.0 * ratio * np.hypot(se_stat / sd_stat, se_mc / sd_mc)
    assert ratio == pytest.approx(1.0, abs=tol), (snr, sd_stat, sd_mc)
    if snr == 6.0:
        # without its gross errors the statistical model is Eq. 24's Gaussian: outside
        eq24 = float(np.median(sigma[sel]))
        assert eq24 / sd_mc < 1.0 - tol


def test_gross_errors_are_drawn_only_at_low_snr_and_lie_where_the_discriminator_puts_them(errors):
    out, snr_of, sigma = errors
    far = np.abs(out["statistical"]) > gross.GROSS_SIGMAS * sigma
    assert far[snr_of == 6.0].mean() > 0.005  # about 1 %
    assert not far[snr_of >= 19.0].any()
    # early (the onset) and late (the trailing edge), within the detection window
    e = out["statistical"][far]
    assert (e < 0).mean() > 0.5 and e.min() > -0.8 and e.max() < 1.5


def test_the_gross_error_draw_leaves_the_other_draws_alone():
    rng = np.random.default_rng(1)
    r = np.array([100.0, 101.0, 102.0, 103.0])
    true = np.array([100.0, 101.0, 102.0, 103.5])
    drawn = np.array([True, True, False, True])
    out = detection.draw_gross_errors(rng, r, true, drawn, np.array([0.0, 1.0, 1.0, 1.0]), [-0.4])
    np.testing.assert_array_equal(out, [100.0, 100.6, 102.0, 103.1])
    same = detection.draw_gross_errors(rng, r, true, drawn, np.zeros(4), [-0.4])
    np.testing.assert_array_equal(same, r)


def test_the_table_is_empty_above_its_grid_and_covers_the_threshold():
    table = gross.gross_errors(
        RX, SHAPE.tau_s, SHAPE.a, simcore.Scene().detector.bandwidth_hz, DT, T_D, K_ATT, 5.0,
        simcore.Scene().timing.resolution_s, SHAPE.tau_s,
    )  # fmt: skip
    assert table.snr[0] <= 5.0 <= table.snr[-1]
    assert table.probability_at(np.array([table.snr_max + 0.5, np.inf, np.nan])).tolist() == [
        0.0,
        0.0,
        0.0,
    ]
    assert table.probability_at(np.array([6.0]))[0] > 0.0


def test_a_threshold_between_grid_points_interpolates_the_two_tables_around_it():
    args = (RX, SHAPE.tau_s, SHAPE.a, 120e6, DT, T_D, K_ATT)
    rest = (100e-12, 0.0)
    on_grid = gross.gross_errors_at(*args, 5.0, *rest)
    assert on_grid is gross.gross_errors(*args, 5.0, *rest)  # TNR 5: its own table
    below, above = gross.gross_errors(*args, 5.0, *rest), gross.gross_errors(*args, 5.5, *rest)
    mid = gross.gross_errors_at(*args, 5.2, *rest)
    snr = np.union1d(below.snr, above.snr)  # the interpolated table's own grid
    w = (5.2 - 5.0) / gross.TNR_STEP
    want = (1 - w) * below.probability_at(snr) + w * above.probability_at(snr)
    assert np.allclose(mid.probability_at(snr), want, rtol=1e-12, atol=0.0)
    assert mid.displacement_m is below.displacement_m  # the nearer table's
    # a drag across the cell asks for no table beyond its two ends
    misses = gross.gross_errors.cache_info().misses
    for tnr in (5.1, 5.2, 5.3, 5.4, 5.45):
        gross.gross_errors_at(*args, tnr, *rest)
    assert gross.gross_errors.cache_info().misses == misses
