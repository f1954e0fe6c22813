"""What a Geiger-mode frame may cost, and the pixel's chance to be armed (issue 25).

Memory: a frame's avalanche records and the temporaries that time, sort and histogram them
(:func:`.events.simulate_frame`, :func:`.histogram.histogram`) peak at about
``BYTES_PER_EVENT`` bytes per recorded avalanche (measured: ``lmapd simulate`` at 64 x 64 px,
first-photon detection over a 1000 km gate, 1,000 and 4,000 pulses: 0.85 and 2.07 GB peak
resident, 101 bytes per avalanche between them). A frame whose expected avalanches would pass
``MAX_EVENT_BYTES`` is refused before any is drawn.

The armed probability (docs/physics.md#geiger-mode): a non-paralysable pixel re-armed at the
gate's opening and driven by a constant primary rate r records avalanches at renewal times
T_1 = E_1, T_{k+1} = T_k + d + E_{k+1} (E exponential of rate r). It is armed at t when its
last avalanche lies more than d before t: with S_k = k d + Gamma(k, r) the k-th re-arm time,
P(armed at t) = sum_k P(S_k <= t < S_k + E) = sum_{k=0}^{floor(t/d)} e^{-r u_k} (r u_k)^k / k!,
u_k = t - k d. For t < d this is e^{-r t} (first photon); far into the gate it tends to the
steady state 1 / (1 + r d).
"""

from __future__ import annotations

import numpy as np
from scipy import special

BYTES_PER_EVENT = 101  # [B] peak resident memory per recorded avalanche (module docstring)
MAX_EVENT_BYTES = 2 << 30  # [B] a frame's avalanche records and their temporaries at most
MAX_EVENTS = MAX_EVENT_BYTES // BYTES_PER_EVENT  # expected avalanches per frame at most
# the renewal count's spread (in avalanches) above which the re-arm phase has decohered and
# the steady state 1 / (1 + r d) stands for the sum
_DECOHERED_SPREAD = 30.0
_TERMS_PER_SPREAD = 8.0  # terms either side of the likeliest, in spreads (and 8 more)


def armed_probability(rate_hz, t_s, dead_time_s: float) -> np.ndarray:
    """(n,) chance that a pixel of constant primary rate ``rate_hz`` [1/s], re-armed at t = 0
    with dead time ``dead_time_s`` [s], is armed at ``t_s`` [s] (module docstring).

    The sum is taken over the terms within 8 spreads of the likeliest count (the renewal
    count's standard deviation sqrt(t / (r^2 (d + 1/r)^3)), and 8 terms more); where that
    spread passes 30 avalanches the steady state 1 / (1 + r d) is returned.
    """
    r = np.asarray(rate_hz, dtype=np.float64)
    t = np.broadcast_to(np.asarray(t_s, dtype=np.float64), r.shape)
    d = float(dead_time_s)
    out = np.ones(r.shape)
    live = (r > 0) & (t > 0)
    if d <= 0 or not live.any():
        return np.where(live, 1.0, out) if d <= 0 else out
    r, t = r[live], t[live]
    k_max = np.floor(t / d)
    mean_cycle = d + 1.0 / r
    likeliest = np.minimum(t / mean_cycle, k_max)
    spread = np.sqrt(t / (r * r * mean_cycle**3))
    p = 1.0 / (1.0 + r * d)
    near = spread <= _DECOHERED_SPREAD
    if near.any():
        p[near] = _renewal_sum(r[near], t[near], d, k_max[near], likeliest[near], spread[near])
    out[live] = p
    return out


def _renewal_sum(r, t, d, k_max, likeliest, spread) -> np.ndarray:
    """sum_k e^{-r u_k} (r u_k)^k / k! over k within the window around ``likeliest``."""
    reach = np.ceil(_TERMS_PER_SPREAD * spread + _TERMS_PER_SPREAD)
    k_lo = np.maximum(np.floor(likeliest) - reach, 0.0)
    n_terms = int(np.max(np.minimum(k_max, np.floor(likeliest) + reach) - k_lo)) + 1
    total = np.zeros(len(r))
    block = max(1, (1 << 22) // n_terms)  # 32 MB of terms at a time
    for lo in range(0, len(r), block):
        sl = slice(lo, lo + block)
        k = k_lo[sl, None] + np.arange(n_terms)[None, :]
        u = t[sl, None] - k * d
        ok = (k <= k_max[sl, None]) & (u >= 0)
        lam = r[sl, None] * np.where(ok, u, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            log_term = -lam + special.xlogy(k, lam) - special.gammaln(k + 1.0)
        total[sl] = np.sum(np.where(ok, np.exp(log_term), 0.0), axis=1)
    return np.minimum(total, 1.0)
