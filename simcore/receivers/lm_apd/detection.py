"""Detection probability and false alarms (Eqs. 27-28), and drawing them for one flash.

The model: docs/physics.md#eq-27, docs/physics.md#eq-28, docs/physics.md#statistical-model.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from ... import parallel
from ...constants import C
from ...echo.features import compiled_kernel
from ..records import Outliers


def detection_probability(i_pk_a, threshold_a: float | np.ndarray, sigma_pk_a):
    """Eq. 27 (ours): P_d = 0.5 + 0.5 erf((i_pk - V_T) / (sqrt 2 sigma_pk)).

    The threshold V_T = TNR sigma_n is set on signal-free noise; the peak carries its own shot noise
    in sigma_pk. A single look at the peak.
    """
    i = np.asarray(i_pk_a, dtype=np.float64)
    s = np.asarray(sigma_pk_a, dtype=np.float64)
    return 0.5 * special.erfc(-(i - threshold_a) / (np.sqrt(2.0) * s))


def detection_probability_paper(snr, tnr: float | np.ndarray):
    """Eq. 27 as printed: 0.5 + 0.5 erf((SNR - TNR) / sqrt 2) (thermal noise only)."""
    return 0.5 * special.erfc(-(np.asarray(snr, dtype=np.float64) - tnr) / np.sqrt(2.0))


def rice_rate_hz(bandwidth_hz: float) -> float:
    """nu0 = sqrt(int f^2 |H|^2 df / int |H|^2 df) = sqrt(2/pi) B for the Gaussian band limit."""
    return np.sqrt(2.0 / np.pi) * bandwidth_hz


def false_alarms_per_pixel(
    tnr: float | np.ndarray, gate_m: float, bandwidth_hz: float
) -> np.ndarray:
    """Eq. 28 (ours, Rice): expected false triggers per pixel per pulse in a gate of R_gate,
    (2 R_gate / c) nu0 exp(-TNR^2 / 2)."""
    return 2.0 * gate_m / C * rice_rate_hz(bandwidth_hz) * np.exp(-(tnr**2) / 2.0)


def false_alarms_per_pixel_paper(
    tnr: float | np.ndarray, gate_m: float, df_hz: float
) -> np.ndarray:
    """Eq. 28 as printed: 2.2 (2 R_gate / c) df 0.5 erfc(TNR / sqrt 2)."""
    return 2.2 * (2.0 * gate_m / C) * df_hz * 0.5 * special.erfc(tnr / np.sqrt(2.0))


def draw_outliers(
    rng: np.random.Generator,
    n_pixels_total: int,
    n_false_per_pixel: float,
    gate_center_m: float,
    gate_m: float,
) -> Outliers:
    """Section 4 step 5: N_out ~ Poisson(N_pixels n_false); each on a uniform pixel, at a range
    uniform over the gate [R_st - R_gate/2, R_st + R_gate/2] clipped at 0."""
    n_out = rng.poisson(n_pixels_total * n_false_per_pixel)
    pixel = rng.integers(0, n_pixels_total, size=n_out)
    lo = max(0.0, gate_center_m - gate_m / 2.0)
    hi = gate_center_m + gate_m / 2.0
    return Outliers(pixel=pixel.astype(np.int64), range_m=rng.uniform(lo, hi, size=n_out))


def draw_outliers_per_pixel(
    rng: np.random.Generator, n_false_per_pixel, gate_lo_m: float, gate_hi_m: float
) -> Outliers:
    """Section 4 step 5 with each pixel's own rate (background light): N_i ~ Poisson(n_false_i)
    false alarms in pixel i, each at a range uniform over the gate [gate_lo_m, gate_hi_m].

    n_false_per_pixel : (N,) expected false alarms of each pixel (flat index) per flash
    """
    counts = rng.poisson(np.asarray(n_false_per_pixel, dtype=np.float64))
    pixel = np.repeat(np.arange(len(counts), dtype=np.int64), counts)
    return Outliers(pixel=pixel, range_m=rng.uniform(gate_lo_m, gate_hi_m, size=len(pixel)))


# ----------------------------------------------------------------------------------------------
# limited stops (docs/physics.md#limited-stops): at most K stops per pixel and pulse
# ----------------------------------------------------------------------------------------------
def echo_survival_probability(t_echo_s, rate_hz: float, max_stops: int, holdoff_s: float):
    """Probability that an echo arriving ``t_echo_s`` after the gate opens still finds the
    discriminator armed: fewer than K noise stops before it, and it not inside the dead time
    (the re-arm hold-off h) of the last one [1].

    Noise up-crossings are a Poisson process of rate nu (Eq. 28 per unit time); after a stop
    the next noise stop is h + Exp(nu) later, so the j-th noise stop is at j h + Gamma(j, nu)
    and the echo survives with probability

        sum_{j=0}^{K-1} Poisson(j; nu (t_e - j h))   (terms with t_e < j h are 0),

    exp(-nu t_e) for K = 1, the Poisson CDF P(N(t_e) < K) for h = 0.

    t_echo_s : (n,) echo time since the gate opened [s] (negative: before the gate, 1)
    rate_hz : nu [1/s]; max_stops : K; holdoff_s : h [s]
    """
    t = np.maximum(np.asarray(t_echo_s, dtype=np.float64), 0.0)
    if holdoff_s == 0.0:  # the Poisson CDF, from the regularised gamma function (exact tails)
        return special.gammaincc(int(max_stops), rate_hz * t)
    total = np.zeros_like(t)
    for j in range(int(max_stops)):
        free = t - j * holdoff_s
        if not (free >= 0.0).any():
            break
        total += np.where(free >= 0.0, _poisson_pmf(j, rate_hz * np.maximum(free, 0.0)), 0.0)
    return np.minimum(total, 1.0)


def _poisson_pmf(j: int, mean):
    """P(N = j) for N ~ Poisson(mean), mean (n,) >= 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        log_term = np.where(mean > 0, j * np.log(mean), 0.0 if j == 0 else -np.inf)
    return np.exp(log_term - mean - special.gammaln(j + 1))


# Fewer events than this are sorted into stops on one thread: ~17 ns an event (a 256 x 256
# frame's 15,600 events in 0.27 ms), well under the cost of waking a second thread on a busy machine
STOPS_SERIAL_BELOW = 65536


def limited_stops(pixel, range_m, max_stops: int, holdoff_m: float) -> np.ndarray:
    """Which events become stops when each pixel records at most ``max_stops`` per pulse and is
    dead for ``holdoff_m`` (as range, c h / 2) after each stop: (n,) bool.

    pixel : (n,) int -- flat pixel index of each event (noise up-crossing or echo)
    range_m : (n,) float -- its range [m] (time since emission, c t / 2)
    An event is a stop if it is at least ``holdoff_m`` after the pixel's previous stop and the
    pixel has fewer than ``max_stops`` stops before it. Events of one pixel are taken in time
    order; ties keep their input order.
    """
    pixel = np.asarray(pixel, dtype=np.int64)
    range_m = np.asarray(range_m, dtype=np.float64)
    n = len(pixel)
    accepted = np.zeros(n, dtype=bool)
    if n == 0:
        return accepted
    if compiled_kernel() is not None and np.isfinite(range_m).all():
        from . import kernel  # noqa: PLC0415  (numba: loaded with the echo kernel)

        # the same decisions, pixel by pixel on the frame's threads
        threads = parallel.threads_for(n, STOPS_SERIAL_BELOW)
        return kernel.limited_stops(pixel, range_m, max_stops, holdoff_m, threads)
    order = np.lexsort((np.arange(n), range_m, pixel))
    p_sorted = pixel[order]
    first = np.ones(n, dtype=bool)
    first[1:] = p_sorted[1:] != p_sorted[:-1]
    start = np.flatnonzero(first)
    group = np.cumsum(first) - 1  # compact pixel id of each sorted event
    rank = np.arange(n) - start[group]
    dead_until = np.full(len(start), -np.inf)
    count = np.zeros(len(start), dtype=np.int64)
    r_sorted = range_m[order]
    by_rank = np.argsort(rank, kind="stable")
    bounds = np.cumsum(np.bincount(rank))
    lo = 0
    for hi in bounds:  # one pass per rank: the k-th event of every pixel at once
        sel = by_rank[lo:hi]
        lo = hi
        g = group[sel]
        ok = (r_sorted[sel] >= dead_until[g]) & (count[g] < max_stops)
        sel, g = sel[ok], g[ok]
        accepted[order[sel]] = True
        dead_until[g] = r_sorted[sel] + holdoff_m
        count[g] += 1
    return accepted


def draw_limited_stops(
    rng: np.random.Generator,
    n_pixels_total: int,
    echo_pixel,
    echo_range_m,
    rate_per_m: float,
    gate_lo_m: float,
    gate_hi_m: float,
    max_stops: int,
    holdoff_m: float,
) -> tuple[np.ndarray, Outliers]:
    """One pulse of every pixel with at most ``max_stops`` stops, drawn stop by stop: memory
    and time O(pixels x K) whatever the false-alarm rate (docs/physics.md#limited-stops).

    From the gate's opening (or the end of the last stop's dead time) the next noise stop is an
    exponential wait of rate ``rate_per_m`` (Poisson up-crossings are memoryless); the echo, if
    it is still ahead, is the stop when it comes first; an echo inside a dead time is lost.

    echo_pixel : (n,) int -- flat pixel index of each lit pixel
    echo_range_m : (n,) float -- range of its echo if the echo crosses the threshold (drawn
        with P_d), NaN if not [m]
    rate_per_m : noise stops per metre of range (nu 2 / c) [1/m]: one for all pixels, or
        (n_pixels_total,) each pixel's own (background light)
    gate_lo_m, gate_hi_m : the gate [m]; holdoff_m : dead time after a stop, as range [m]
    Returns (n,) bool (the echo is a stop) and the false-alarm stops as Outliers.
    """
    echo_at = np.full(n_pixels_total, np.inf)
    r = np.asarray(echo_range_m, dtype=np.float64)
    has = np.isfinite(r) & (r >= gate_lo_m) & (r <= gate_hi_m)
    echo_at[np.asarray(echo_pixel)[has]] = r[has]
    echo_stop = np.zeros(n_pixels_total, dtype=bool)
    start = np.full(n_pixels_total, float(gate_lo_m))
    active = np.arange(n_pixels_total)
    out_pixel, out_range = [], []
    for _ in range(int(max_stops)):
        if not len(active):
            break
        t0 = start[active]
        lost = echo_at[active] < t0  # the echo fell into the last dead time
        echo_at[active[lost]] = np.inf
        if isinstance(rate_per_m, np.ndarray):  # each pixel its own rate
            rate = rate_per_m[active]
            with np.errstate(divide="ignore"):
                noise = t0 + rng.exponential(1.0, size=len(active)) / rate
        else:
            noise = (
                t0 + rng.exponential(1.0 / rate_per_m, size=len(active))
                if rate_per_m > 0
                else (np.full(len(active), np.inf))
            )
        is_echo = echo_at[active] <= noise
        stop = np.where(is_echo, echo_at[active], noise)
        inside = stop <= gate_hi_m
        echo_stop[active[is_echo & inside]] = True
        echo_at[active[is_echo]] = np.inf
        fa = inside & ~is_echo
        out_pixel.append(active[fa])
        out_range.append(stop[fa])
        start[active] = stop + holdoff_m
        active = active[inside]
    pix = np.concatenate(out_pixel) if out_pixel else np.zeros(0, np.int64)
    rng_m = np.concatenate(out_range) if out_range else np.zeros(0)
    return echo_stop[np.asarray(echo_pixel)], Outliers(pixel=pix.astype(np.int64), range_m=rng_m)


def _capped_stops(rate_per_m, length_m, cap: int, holdoff_m: float, first_delay_m: float = 0.0):
    """Expected noise stops of a renewal process capped at ``cap`` stops: the i-th stop (i >= 1)
    comes at first_delay + (i - 1) h + Gamma(i, rate) after the start, so it falls inside
    ``length_m`` with probability P(Gamma(i, rate) <= length - first_delay - (i - 1) h), the
    regularised lower incomplete gamma function. Broadcasts over its array arguments [1]."""
    rate = np.asarray(rate_per_m, dtype=np.float64)
    length = np.asarray(length_m, dtype=np.float64)
    total = np.zeros(np.broadcast(rate, length).shape)
    for i in range(1, int(cap) + 1):
        free = length - first_delay_m - (i - 1) * holdoff_m
        term = special.gammainc(i, rate * np.maximum(free, 0.0))
        total = total + np.where(free > 0.0, term, 0.0)
        if not np.any(term > 1e-16):  # every later term is smaller
            break
    return total


def expected_false_points(
    n_false_per_pixel,
    n_pixels_total: int,
    gate_lo_m: float,
    gate_hi_m: float,
    max_stops: int,
    holdoff_m: float,
    echo_pixel,
    echo_range_m,
    p_echo,
) -> float:
    """Expected false points in the cloud per flash: the noise stops that the at most K stops
    per pixel keep (docs/physics.md#false-points), not the noise crossings (Eq. 28) [1].

    Each pixel's noise crossings are a Poisson process of rate nu = n_false / T over the gate;
    after a stop the pixel is dead for h, so the i-th noise stop of a pixel without an echo falls
    in the gate with probability P(Gamma(i, nu) <= T - (i - 1) h), and its expected noise stops
    are the sum of that over i = 1..K. An echo that crosses the threshold (probability P_d) at
    t_e takes a stop if the pixel is still armed then, which happens with j < K noise stops
    before it with probability Poisson(j; nu (t_e - j h)); it then leaves K - j - 1 stops for the
    noise after t_e + h instead of K - j after t_e. With K = 1 this is the first-stop arithmetic:
    1 - exp(-nu T) in a pixel without an echo, P_d (1 - exp(-nu t_e)) + (1 - P_d)(1 - exp(-nu T))
    in a lit one.

    n_false_per_pixel : float, or (n_pixels_total,) each pixel's own -- expected noise
        crossings per pixel over the gate (Eq. 28) [1]
    gate_lo_m, gate_hi_m : the gate [m]; max_stops : K; holdoff_m : h as range, c h / 2 [m]
    echo_pixel : (n,) int -- flat index of each lit pixel
    echo_range_m : (n,) float -- its echo's (noise-free) range [m]; outside the gate: no echo
    p_echo : (n,) float -- probability that the echo crosses the threshold (Eq. 27) [1]
    """
    length_m = float(gate_hi_m - gate_lo_m)
    if length_m <= 0.0:
        return 0.0
    k = int(max_stops)
    n_false = np.asarray(n_false_per_pixel, dtype=np.float64)
    rate = n_false / length_m  # noise crossings per metre of range [1/m]
    per_pixel = _capped_stops(rate, length_m, k, holdoff_m)
    total = float(per_pixel.sum()) if n_false.ndim else float(per_pixel) * n_pixels_total
    pixel = np.asarray(echo_pixel, dtype=np.int64)
    r = np.asarray(echo_range_m, dtype=np.float64)
    p = np.broadcast_to(np.asarray(p_echo, dtype=np.float64), r.shape)
    inside = np.isfinite(r) & (r >= gate_lo_m) & (r <= gate_hi_m) & (p > 0)
    if not inside.any():
        return total
    nu = rate[pixel[inside]] if n_false.ndim else np.full(int(inside.sum()), float(rate))
    t_e, p = r[inside] - gate_lo_m, p[inside]
    after = length_m - t_e
    saved = np.zeros_like(t_e)
    for j in range(k):
        free = t_e - j * holdoff_m
        if not (free >= 0.0).any():
            break
        armed = np.where(free >= 0.0, _poisson_pmf(j, nu * np.maximum(free, 0.0)), 0.0)
        without = _capped_stops(nu, after, k - j, holdoff_m)
        with_echo = _capped_stops(nu, after, k - j - 1, holdoff_m, first_delay_m=holdoff_m)
        saved += armed * (without - with_echo)
    return total - float(np.sum(p * saved))


def draw_gross_errors(
    rng: np.random.Generator, range_m, range_true_m, drawn, p_gross, displacement_m
) -> np.ndarray:
    """The discriminator's gross errors (docs/physics.md#gross-errors): each drawn echo is one
    with probability ``p_gross``, its range then the true range plus a displacement drawn from
    ``displacement_m`` instead of the Gaussian jitter's. (n,) ranges out [m].

    range_m : (n,) the ranges with Eq. 24's noise [m]; range_true_m : (n,) noise-free [m]
    drawn : (n,) bool, the echo crossed the threshold; p_gross : (n,) [1]
    displacement_m : (q,) the gross errors to draw from (measured less true range) [m]
    Two numbers are drawn per echo whatever happens, so a draw does not shift the next ones.
    """
    n = len(range_m)
    u = rng.random(n)
    pick = rng.integers(0, max(len(displacement_m), 1), size=n)
    if not len(displacement_m):
        return np.asarray(range_m)
    gross = np.asarray(drawn, dtype=bool) & (u < np.asarray(p_gross))
    return np.where(gross, np.asarray(range_true_m) + np.asarray(displacement_m)[pick], range_m)
