"""The Geiger-mode first-photon (pile-up) correction (docs/physics.md#gm-pileup).

The correction (``gm.pileup_correction = "fit"``): the maximum-likelihood fit of each detected
pixel's first avalanches after the window opens (at most one per pulse: the first-photon
histogram, which the pulse-tagged avalanches give for any dead time) by the single-surface
model, two parameters, the echo's start t0 and its photoelectrons per pulse N_s (the jitter
after the dead time's arbitration, the background from its known rate): dead-time aware by
construction, as photon-counting processors' first-photon corrections are.

"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special

from .expected import Timing, _skew, inverse_count_mean


@lru_cache(maxsize=1)
def first_photon_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ln N grid, and the mean and variance (in units of s) of the first primary event's delay
    after the echo's start for a single surface of N photoelectrons per pulse, given one in
    the pulse: density N x e^-x e^(-N G(x)) / (1 - e^-N), G(x) = 1 - (1 + x) e^-x."""
    log_n = np.linspace(np.log(1e-4), np.log(1e7), 442)
    x = np.concatenate([np.geomspace(1e-7, 1e-2, 800), np.linspace(1e-2, 40.0, 8000)[1:]])
    big_g = -np.expm1(np.log1p(x) - x)
    n = np.exp(log_n)[:, None]
    surv = np.exp(-n * big_g[None, :])
    cdf = (1.0 - surv) / -np.expm1(-n)
    # moments by parts from the CDF (trapezoid over the non-uniform grid)
    dx = np.diff(x)
    tail = 1.0 - cdf
    mid = 0.5 * (tail[:, 1:] + tail[:, :-1])
    mean = x[0] + (mid * dx).sum(axis=1)
    xm = 0.5 * (x[1:] + x[:-1])
    second = x[0] ** 2 + (2.0 * xm * mid * dx).sum(axis=1)
    return log_n, mean, np.maximum(second - mean * mean, 0.0)


def first_photon_delay(signal_pe) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the first photon's delay [units of s] for ``signal_pe``."""
    log_n, mean, var = first_photon_table()
    ln = np.log(np.clip(np.asarray(signal_pe, dtype=np.float64), 1e-4, 1e7))
    return np.interp(ln, log_n, mean), np.interp(ln, log_n, var)


def signal_from_spread(var_delay) -> np.ndarray:
    """The photoelectrons per pulse whose first-photon delay has variance ``var_delay`` [s^2
    units of s]: the table inverted (the variance falls with N)."""
    log_n, _, var = first_photon_table()
    v = np.asarray(var_delay, dtype=np.float64)
    return np.exp(np.interp(-v, -var, log_n))


@dataclass(frozen=True, kw_only=True)
class FirstPhotonFit:
    """The first-photon model fitted to each pixel's first avalanches of its armed pulses.

    t0_s : (q,) the echo's start from the gate's opening [s] (NaN where no signal)
    signal_pe : (q,) its photoelectrons per pulse [1]
    saturated : (q,) bool, (nearly) every armed pulse fired: N_s from the spread
    n_first : (q,) signal first avalanches (background subtracted) [1]
    """

    t0_s: np.ndarray
    signal_pe: np.ndarray
    saturated: np.ndarray
    n_first: np.ndarray


def first_events_histogram(events, pixel, start_bin, length, n_pulses, dead_bins):
    """(q, length) first avalanche of each pulse in each pixel's window [start, start + length)
    and (q,) the pulses armed when it opens (no avalanche within the dead time before it)."""
    q = len(pixel)
    if q == 0:
        return np.zeros((0, length)), np.zeros(0)
    n_all = int(max(int(events.pixel.max()) + 1 if len(events) else 0, int(pixel.max()) + 1))
    row_of = np.full(n_all, -1, dtype=np.int64)
    row_of[pixel] = np.arange(q)
    row = row_of[events.pixel]
    sel = row >= 0
    row, b, pulse = row[sel], events.bin[sel].astype(np.int64), events.pulse[sel].astype(np.int64)
    rel = b - start_bin[row]
    # pulses dead when the window opens
    dead = (rel < 0) & (rel >= -dead_bins)
    dead_key = np.unique(row[dead] * n_pulses + pulse[dead])
    armed = n_pulses - np.bincount(dead_key // n_pulses, minlength=q)
    inside = (rel >= 0) & (rel < length)
    key = row[inside] * n_pulses + pulse[inside]
    keep = ~np.isin(key, dead_key)
    key, rel_in = key[keep], rel[inside][keep]
    # events are sorted by pixel, then bin: a pulse's first occurrence is its earliest
    _, first = np.unique(key, return_index=True)
    hist = np.zeros((q, length))
    np.add.at(hist, (key[first] // n_pulses, rel_in[first]), 1.0)
    return hist, armed.astype(np.float64)


def fit_first_photon(
    t: Timing,
    hist: np.ndarray,
    armed: np.ndarray,
    start_bin: np.ndarray,
    background_per_bin: np.ndarray,
) -> FirstPhotonFit:
    """Fit each pixel's first-avalanche histogram (q, L) of ``armed`` pulses (module
    docstring; docs/physics.md#gm-pileup):

    - the background: a pulse still armed at bin j fires on it with r b, so the signal's first
      avalanches are n_j - A_j r b (A_j the armed pulses left);
    - N_s from the share of armed pulses that fired, f = S / A_0: N_s = -ln(1 - f); where
      nearly all fired (A_0 - S < 3, no information left in the share) from the spread of
      the first avalanches instead, Var t = s^2 Var x(N_s) + sigma_j^2 + b^2 / 12;
    - t0 from their mean, t0 = mean t - s E x(N_s): the first photon's mean delay of the
      model (jitter and the bin are centred).
    """
    n_b = hist.shape[1]
    t_bin = (start_bin[:, None] + np.arange(n_b)[None, :] + 0.5) * t.bin_s
    a0 = np.maximum(armed, 1.0)
    left = a0[:, None] - np.concatenate(
        [np.zeros((len(hist), 1)), np.cumsum(hist, axis=1)[:, :-1]], axis=1
    )
    sig = np.maximum(hist - np.maximum(left, 0.0) * background_per_bin[:, None], 0.0)
    n_sig = sig.sum(axis=1)
    ok = n_sig > 0
    safe = np.where(ok, n_sig, 1.0)
    mean_t = (sig * t_bin).sum(axis=1) / safe
    var_t = (sig * (t_bin - mean_t[:, None]) ** 2).sum(axis=1) / np.maximum(safe - 1.0, 1.0)
    frac = np.minimum(n_sig / a0, 1.0 - 0.5 / a0)
    n_share = -np.log1p(-frac)
    saturated = a0 - n_sig < 3.0
    s2 = t.scale_s**2
    var_x = (var_t - t.jitter_s**2 - t.bin_s**2 / 12.0) / s2
    n_spread = signal_from_spread(np.maximum(var_x, 0.0))
    n_s = np.where(saturated, np.maximum(n_spread, n_share), n_share)
    mean_x, _ = first_photon_delay(n_s)
    t0 = mean_t - t.scale_s * mean_x
    return FirstPhotonFit(
        t0_s=np.where(ok, t0, np.nan),
        signal_pe=np.where(ok, n_s, np.nan),
        saturated=saturated & ok,
        n_first=n_sig,
    )


_Z_NODES_FIT = special.ndtri((np.arange(32) + 0.5) / 32)  # equal-probability normal nodes


def predict_fit(
    t: Timing, q: np.ndarray, alpha0: np.ndarray, start_bin: np.ndarray, min_counts=1.0
):
    """Expected t0, its sd and skewness of :func:`fit_first_photon` from the expected
    first-avalanche histogram (q : (n, L) per armed pulse, the first photon of each; alpha0 :
    (n,) the pulses armed when the window opens). t0 = mean t - s E x(N_s): the mean of
    S = N a0 sum q first avalanches spreads by Var t E[1/S | S >= k] (k: ``min_counts``), and
    the fitted N_s by its own law, carried through E x at
    32 equal-probability normal nodes (E x is bounded and bends where N_s is large, so not by
    its slope): ln N_s from the share with Var N_s = (e^N_s - 1) / A_0; where saturated, Var x
    from the spread with Var(Var t) = 2 (Var t)^2 / S (nearly Gaussian: the jitter), clipped
    at 0 (no limit on N_s) and at the share's N_s."""
    armed = t.n_pulses * alpha0
    hist = armed[:, None] * q
    fit = fit_first_photon(t, hist, armed, start_bin, np.zeros(len(q)))
    n_b = q.shape[1]
    t_bin = (start_bin[:, None] + np.arange(n_b)[None, :] + 0.5) * t.bin_s
    total = np.maximum(hist.sum(axis=1), 1e-300)
    mean_t = (hist * t_bin).sum(axis=1) / total
    var_t = (hist * (t_bin - mean_t[:, None]) ** 2).sum(axis=1) / total
    counts = np.maximum(total, 1.0)
    var_mean = var_t * inverse_count_mean(total, min_counts)
    a0 = np.maximum(armed, 1.0)
    n_s = np.clip(np.nan_to_num(fit.signal_pe, nan=1e-4), 1e-4, 1e7)
    z = _Z_NODES_FIT[None, :]
    # from the share
    sd_ln = np.sqrt(np.expm1(np.minimum(n_s, 50.0)) / (a0 * n_s * n_s))[:, None]
    n_share = np.exp(np.clip(np.log(n_s)[:, None] + z * sd_ln, np.log(1e-4), np.log(1e7)))
    # from the spread
    share_frac = np.minimum(total / a0, 1.0 - 0.5 / a0)
    n_floor = -np.log1p(-share_frac)[:, None]
    s2 = t.scale_s**2
    var_x = ((var_t - t.jitter_s**2 - t.bin_s**2 / 12.0) / s2)[:, None]
    sd_v = (np.sqrt(2.0 / counts) * var_t / s2)[:, None]
    n_spread = np.maximum(signal_from_spread(np.maximum(var_x + z * sd_v, 0.0)), n_floor)
    nodes = np.where(fit.saturated[:, None], n_spread, n_share)
    ex = first_photon_delay(nodes)[0]
    ex_fit = first_photon_delay(n_s)[0]
    t0 = fit.t0_s - t.scale_s * (ex.mean(axis=1) - ex_fit)
    sd = np.sqrt(var_mean + (t.scale_s * ex.std(axis=1)) ** 2)
    skew = _skew(hist, t_bin - mean_t[:, None], total) * np.sqrt(var_mean) / np.maximum(sd, 1e-300)
    return t0, sd, skew
