"""The Geiger-mode pile-up prediction (issue 25, item 3) against an independent first-photon
simulation: per pulse, the first of a Poisson process of N_s photoelectrons of Eq. 1's pulse
(drawn by inverting its cumulative intensity with scipy's inverse incomplete gamma function),
Gaussian jitter, TDC bins, and Coates' centroid over a fixed window, at 0.1, 1, 10 and 100
photoelectrons per pulse and 100, 1,000 and 10,000 pulses. Tolerances from the trial counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

from simcore.receivers import gm_pileup as gp

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
    t = gp.Timing(scale_s=S_S, jitter_s=JITTER_S, bin_s=BIN_S, dead_time_s=1.0, n_pulses=n_pulses)
    q, alpha = gp.expected_histogram(
        t,
        np.array([[T0_S]]),
        np.array([[pe]]),
        np.zeros(1),
        np.array([START]),
        LENGTH,
        np.ones(1),
    )
    pred = gp.coates_centroid(t, q, alpha, np.array([START]), np.zeros(1))
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
