"""Laser pulse, band limit and per-pixel echo waveforms (Eqs. 1, 4, 5, 29, 30).

The band-limited pulse p_B = h_B * P0 (Gaussian impulse response of the detector + amplifiers
convolved with the Q-switched pulse of Eq. 1) has a closed form, an exponentially modified Gaussian.
It is tabulated once per pulse at a few picoseconds and interpolated, so every echo
y(t) = sum_k w_k p_B(t - t_k) is evaluated at exact delays, never snapped to the time grid.

All waveforms here are per joule of pulse energy: the received power scales linearly with the
energy, so a pulse-energy change never re-runs this stage.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from scipy import constants as sc
from scipy import optimize, special

from . import parallel

C = sc.c  # speed of light [m/s]
A_FWHM = 2.446386  # Eq. 1 constant for which tau is the FWHM (ours)
A_PAPER = 3.5  # Eq. 1 constant printed in the paper (FWHM = 0.699 tau)
_TABLE_SIZE = 1 << 15


def pulse_power_w(t_s, energy_j: float, tau_s: float, a: float = A_FWHM):
    """Eq. 1: P0(t) = Pmax (a t / tau) exp(1 - a t / tau) for t >= 0, with Pmax = a E / (e tau)."""
    t = np.asarray(t_s, dtype=np.float64)
    x = np.maximum(a * t / tau_s, 0.0)
    p_max = a * energy_j / (np.e * tau_s)
    return np.where(t >= 0, p_max * x * np.exp(1.0 - x), 0.0)


def band_limit_sigma_s(bandwidth_hz: float) -> float:
    """sigma_h of the Gaussian impulse response whose noise-equivalent bandwidth is B:
    B = integral |H|^2 df = 1 / (4 sqrt(pi) sigma_h)."""
    return 1.0 / (4.0 * np.sqrt(np.pi) * bandwidth_hz)


def filtered_pulse_w(t_s, energy_j: float, tau_s: float, a: float, sigma_s: float):
    """(h_B * P0)(t) in closed form [W]: P0 of Eq. 1 through a unit-area Gaussian of std sigma.

    With lam = a / tau and mu = t - lam sigma^2,
    h_B * P0 = Pmax e lam exp(-lam t + lam^2 sigma^2 / 2) [mu Phi(mu/sigma) + sigma phi(mu/sigma)],
    evaluated as exp(-t^2 / (2 sigma^2)) [mu erfcx(-mu/(sigma sqrt 2)) / 2 + sigma / sqrt(2 pi)]
    where mu <= 0, so that it never overflows.
    """
    t = np.asarray(t_s, dtype=np.float64)
    lam = a / tau_s
    p_max = a * energy_j / (np.e * tau_s)
    mu = t - lam * sigma_s**2
    out = np.empty_like(t)
    neg = mu <= 0
    tn, mn = t[neg], mu[neg]
    out[neg] = np.exp(-(tn**2) / (2 * sigma_s**2)) * (
        0.5 * mn * special.erfcx(-mn / (sigma_s * np.sqrt(2))) + sigma_s / np.sqrt(2 * np.pi)
    )
    tp, mp = t[~neg], mu[~neg]
    z = mp / sigma_s
    out[~neg] = np.exp(-lam * tp + 0.5 * (lam * sigma_s) ** 2) * (
        mp * special.ndtr(z) + sigma_s * np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)
    )
    return p_max * np.e * lam * out


@dataclass(frozen=True)
class PulseShape:
    """The emitted pulse and its band-limited copy, tabulated per joule.

    Times are relative to the pulse start (t = 0 of Eq. 1). ``t_half_s`` and ``t_peak_s`` are the
    half-maximum (rising edge) and peak times of the band-limited reference pulse y0.
    """

    tau_s: float
    a: float
    sigma_h_s: float
    t0_s: float  # first table time
    step_s: float  # table step
    filtered: np.ndarray  # (N,) W/J
    raw: np.ndarray  # (N,) W/J
    t_half_s: float
    t_peak_s: float
    peak_w_per_j: float
    t_start_s: float  # before this the band-limited pulse is < 1e-5 of its peak
    t_end_s: float  # after this it is < 1e-4 of its peak
    filtered_slope: np.ndarray  # (N,) next-sample differences of the tables, for the lookup
    raw_slope: np.ndarray

    def lookup(self, table: np.ndarray, t_s):
        """Linear interpolation of ``filtered`` or ``raw`` at times t. Both tables are ~0 at their
        ends (< 1e-10 of the peak), so times outside them clamp to an end value."""
        slopes = self._slopes[id(table)]
        shape = np.shape(t_s)
        x = np.array(t_s, dtype=np.float64, ndmin=1)  # a copy, worked on in place
        x -= self.t0_s
        x *= 1.0 / self.step_s
        np.clip(x, 0.0, len(table) - 2, out=x)
        i = x.astype(np.int32)
        x -= i  # the fraction
        x *= slopes[i]
        x += table[i]
        return x.reshape(shape)

    @property
    def _slopes(self) -> dict[int, np.ndarray]:
        return {id(self.filtered): self.filtered_slope, id(self.raw): self.raw_slope}

    def rising_time_s(self, fraction: float) -> float:
        """Time on the rising edge where the band-limited pulse is ``fraction`` of its peak."""
        t = self.t0_s + self.step_s * np.arange(len(self.filtered))
        rising = t <= self.t_peak_s
        level = fraction * self.peak_w_per_j
        return float(np.interp(level, self.filtered[rising], t[rising]))

    @cached_property
    def rise_time_10_90_s(self) -> float:
        """10-90 % rise time of the band-limited pulse (see timing.rise_time_10_90_s)."""
        return self.rising_time_s(0.9) - self.rising_time_s(0.1)

    def filtered_at(self, t_s):
        return self.lookup(self.filtered, t_s)

    def raw_at(self, t_s):
        return self.lookup(self.raw, t_s)


@lru_cache(maxsize=16)
def pulse_shape(tau_s: float, a: float, bandwidth_hz: float) -> PulseShape:
    """Tabulate P0 and h_B * P0 (per joule) and find the reference pulse's timing marks."""
    sigma = band_limit_sigma_s(bandwidth_hz)
    lam = a / tau_s
    t0 = -9.0 * sigma
    t1 = 30.0 / lam + 9.0 * sigma  # x e^(1-x) < 1e-11 beyond x = 30
    t = np.linspace(t0, t1, _TABLE_SIZE)
    filt = filtered_pulse_w(t, 1.0, tau_s, a, sigma)
    raw = pulse_power_w(t, 1.0, tau_s, a)
    i_pk = int(np.argmax(filt))
    f = lambda x: -filtered_pulse_w(np.array([x]), 1.0, tau_s, a, sigma)[0]  # noqa: E731
    res = optimize.minimize_scalar(f, bracket=(t[i_pk - 1], t[i_pk], t[i_pk + 1]), tol=1e-12)
    t_pk, peak = float(res.x), float(-res.fun)
    half = lambda x: filtered_pulse_w(np.array([x]), 1.0, tau_s, a, sigma)[0] - 0.5 * peak  # noqa: E731
    t_half = optimize.brentq(half, t0, t_pk, xtol=1e-16, rtol=1e-14)
    start = t[np.argmax(filt > 1e-5 * peak)]
    end = t[len(t) - 1 - np.argmax(filt[::-1] > 1e-4 * peak)]
    slopes = [np.diff(arr, append=arr[-1]) for arr in (filt, raw)]
    for arr in (filt, raw, *slopes):
        arr.setflags(write=False)
    return PulseShape(
        tau_s, a, sigma, t0, float(t[1] - t[0]), filt, raw, t_half, t_pk, peak, start, end, *slopes
    )


def default_time_step_s(tau_s: float, bandwidth_hz: float) -> float:
    """Section 5: dt <= min(tau / 10, 1 / (20 B))."""
    return min(tau_s / 10.0, 1.0 / (20.0 * bandwidth_hz))


# ----------------------------------------------------------------------------------------------
# illumination and element weights
# ----------------------------------------------------------------------------------------------
def illumination_gain(directions, theta_ill_rad: float, model: str):
    """Irradiance per transmitted watt at unit range, E_in r^2 / (eta_t P0)   [1/sr].

    flat_top (Eq. 5): 4 / (pi theta^2) inside the cone of full angle theta, else 0.
    square: 1 / theta^2 where |x/z|, |y/z| <= tan(theta/2).
    gaussian (Eq. 4): 8 / (pi theta^2) exp(-8 alpha^2 / theta^2), theta the full 1/e^2 angle.

    directions : (..., 3) unit vectors in the sensor frame.
    """
    d = np.asarray(directions)
    cos_a = np.clip(d[..., 2], -1.0, 1.0)
    if model == "flat_top":
        lit = cos_a >= np.cos(theta_ill_rad / 2.0)
        return np.where(lit, 4.0 / (np.pi * theta_ill_rad**2), 0.0)
    if model == "square":
        t = np.tan(theta_ill_rad / 2.0)
        lit = (np.abs(d[..., 0]) <= t * d[..., 2]) & (np.abs(d[..., 1]) <= t * d[..., 2])
        return np.where(lit, 1.0 / theta_ill_rad**2, 0.0)
    if model == "gaussian":
        alpha = np.arccos(cos_a)
        return 8.0 / (np.pi * theta_ill_rad**2) * np.exp(-8.0 * alpha**2 / theta_ill_rad**2)
    raise ValueError(f"unknown illumination model {model!r}")


def element_weights(
    range_m,
    cos_theta,
    rho,
    illum_gain,
    *,
    aperture_area_m2,
    eta_t,
    eta_r,
    ifov_rad,
    subrays,
    paper_4pi=False,
):
    """Eq. 30 weights w_k (dimensionless) of each sub-ray: P_r(t) = sum_k w_k P0(t - t_k).

    w_k = eta_r A_r eta_t G_k rho_k cos(theta_k) dA_k / r_k^4, dA_k = (r_k theta_ifov)^2 / K, where
    G_k is the illumination gain (4 / (pi theta_ill^2) for the flat top). With ``paper_4pi`` the
    paper's literal form: an extra 1/(4 pi) and no cos(theta).
    All inputs broadcast; misses carry range inf and give 0.
    """
    r = np.asarray(range_m)
    finite = np.isfinite(r) & (r > 0)
    r_safe = np.where(finite, r, 1.0)
    geom = eta_r * aperture_area_m2 * eta_t * ifov_rad**2 / subrays / r_safe**2
    w = geom * illum_gain * rho
    if paper_4pi:
        w = w / (4.0 * np.pi)
    else:
        w = w * cos_theta
    return np.where(finite, w, 0.0)


# ----------------------------------------------------------------------------------------------
# echo features: peak, half-maximum time, CFD slope
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EchoFeatures:
    """Per-pixel features of the noise-free band-limited echo y (per joule).

    peak_w_per_j : (n,) peak of y [W/J]
    t_half_s : (n,) first time y reaches half its peak (Eq. 31), absolute since emission [s]
    cfd_slope_per_s : (n,) |ds/dt| of the normalised CFD signal s = y_n(t - t_d) - k y_n(t) at its
        firing time (Eq. 25) [1/s]
    peak_raw_w_per_j : (n,) peak of the unfiltered echo P_r (paper's Eq. 14 form), or None
    """

    peak_w_per_j: np.ndarray
    t_half_s: np.ndarray
    cfd_slope_per_s: np.ndarray
    peak_raw_w_per_j: np.ndarray | None


def _eval_exact(shape: PulseShape, table, arrivals, weights, t):
    """y(t) = sum_k w_k p(t - t_k) at one time per pixel. arrivals, weights: (n, K); t: (n,)."""
    return np.einsum("nk,nk->n", weights, shape.lookup(table, t[:, None] - arrivals))


def _refined_peak(shape, table, arrivals, weights, grid, y, dt):
    """Peak of each row of y: best sample, parabolic vertex, exact value there."""
    rows = np.arange(len(y))
    j = np.clip(np.argmax(y, axis=1), 1, y.shape[1] - 2)
    y0, y1, y2 = y[rows, j - 1], y[rows, j], y[rows, j + 1]
    den = y0 - 2 * y1 + y2
    off = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    t_v = grid[rows, j] + np.clip(off, -1, 1) * dt
    # one more parabolic step on exact values, a quarter sample either side
    h = dt / 4
    e0, e1, e2 = (_eval_exact(shape, table, arrivals, weights, t_v + s * h) for s in (-1, 0, 1))
    den = e0 - 2 * e1 + e2
    off = np.where(den < 0, 0.5 * (e0 - e2) / np.where(den < 0, den, -1.0), 0.0)
    t_v = t_v + np.clip(off, -1, 1) * h
    return np.maximum(_eval_exact(shape, table, arrivals, weights, t_v), np.maximum(e1, y1))


def _features_chunk(shape, arrivals, weights, t_first, n_samples, dt, t_d, t_begin, k_att, raw):
    n = len(arrivals)
    grid = t_first[:, None] + t_begin + dt * np.arange(n_samples)[None, :]  # (n, L)
    y = np.einsum("nlk,nk->nl", shape.filtered_at(grid[:, :, None] - arrivals[:, None, :]), weights)
    rows = np.arange(n)

    peak = _refined_peak(shape, shape.filtered, arrivals, weights, grid, y, dt)

    # half-maximum crossing: bracket on the grid, then regula falsi on exact values
    half = 0.5 * peak
    jh = np.argmax(y >= half[:, None], axis=1)
    jh = np.maximum(jh, 1)
    ta, tb = grid[rows, jh - 1], grid[rows, jh]
    fa, fb = y[rows, jh - 1] - half, y[rows, jh] - half
    for _ in range(4):
        tm = ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0)
        tm = np.clip(tm, ta, tb)
        fm = _eval_exact(shape, shape.filtered, arrivals, weights, tm) - half
        left = fm < 0
        ta, fa = np.where(left, tm, ta), np.where(left, fm, fa)
        tb, fb = np.where(left, tb, tm), np.where(left, fb, fm)
    t_half = ta - fa * (tb - ta) / np.where(fb != fa, fb - fa, 1.0)

    # CFD signal on the grid: y(t - t_d) by a fractional shift of the samples
    shift = t_d / dt
    ns, frac = int(np.floor(shift)), shift - np.floor(shift)
    yd = np.zeros_like(y)
    if ns < n_samples:
        yd[:, ns:] += (1.0 - frac) * y[:, : n_samples - ns]
    if ns + 1 < n_samples:
        yd[:, ns + 1 :] += frac * y[:, : n_samples - ns - 1]
    s = (yd - k_att * y) / np.where(peak > 0, peak, 1.0)[:, None]
    # first local maximum of y after the half-max crossing, then the firing window of Eq. 19
    is_max = np.zeros_like(y, dtype=bool)
    is_max[:, 1:-1] = (y[:, 1:-1] >= y[:, :-2]) & (y[:, 1:-1] > y[:, 2:])
    after = np.arange(n_samples)[None, :] >= jh[:, None]
    jpk = np.argmax(is_max & after, axis=1)
    jpk = np.where((is_max & after).any(axis=1), jpk, n_samples - 1)
    t_pk1 = grid[rows, jpk]
    up = np.zeros_like(y, dtype=bool)
    up[:, 1:] = (s[:, :-1] < 0) & (s[:, 1:] >= 0)
    window = (grid >= (t_half - t_d)[:, None]) & (grid <= (t_pk1 + t_d + dt)[:, None])
    cand = up & window
    last = np.maximum(n_samples - 1 - np.argmax(cand[:, ::-1], axis=1), 1)
    found = cand.any(axis=1)
    norm = np.where(peak > 0, peak, 1.0)
    exact = lambda t: _eval_exact(shape, shape.filtered, arrivals, weights, t)  # noqa: E731
    cfd = lambda t: (exact(t - t_d) - k_att * exact(t)) / norm  # noqa: E731
    # the crossing: linear on the grid, then secant steps on the exact CFD signal
    sa, sb = s[rows, last - 1], s[rows, last]
    ta, tb = grid[rows, last - 1], grid[rows, last]
    for _ in range(3):
        tm = np.clip(ta - sa * (tb - ta) / np.where(sb != sa, sb - sa, 1.0), ta, tb)
        sm = cfd(tm)
        left = sm < 0
        ta, sa = np.where(left, tm, ta), np.where(left, sm, sa)
        tb, sb = np.where(left, tb, tm), np.where(left, sb, sm)
    t_star = ta - sa * (tb - ta) / np.where(sb != sa, sb - sa, 1.0)
    h = 1e-3 * dt  # exact derivatives by central differences
    slope_cfd = (cfd(t_star + h) - cfd(t_star - h)) / (2 * h)
    slope_half = (exact(t_half + h) - exact(t_half - h)) / (2 * h) / norm
    slope = np.abs(np.where(found, slope_cfd, slope_half))

    peak_raw = None
    if raw:
        yr = np.einsum("nlk,nk->nl", shape.raw_at(grid[:, :, None] - arrivals[:, None, :]), weights)
        peak_raw = _refined_peak(shape, shape.raw, arrivals, weights, grid, yr, dt)
    return peak, t_half, slope, peak_raw


def echo_features(
    shape: PulseShape,
    arrivals_s,
    weights,
    dt: float,
    t_d: float,
    k_att: float,
    raw_peak: bool = False,
    max_elements: int = 1 << 20,
) -> EchoFeatures:
    """Peak, half-maximum time and CFD slope of each pixel's band-limited echo.

    A pixel lit by one element echoes the reference pulse, shifted and scaled: its features are
    the pulse's own, found once. The others are sampled at ``dt`` on their own window, from just
    before the first arrival to past the last arrival's peak plus the CFD delay (their depth plus
    the pulse), never the whole gate. Each pixel's contributing elements are moved to the front
    and pixels are grouped by element count and window length, in chunks of at most
    ``max_elements`` (pixels x samples x elements) so that memory stays bounded.

    arrivals_s, weights : (n, K) -- two-way delays [s] and Eq. 30 weights (0 = no contribution)
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    n = len(arrivals)
    has = weights > 0
    count = has.sum(axis=1)
    peak = np.zeros(n)
    t_half = np.zeros(n)
    slope = np.zeros(n)
    peak_raw = np.zeros(n) if raw_peak else None

    single = np.flatnonzero(count == 1)
    if len(single):
        j = np.argmax(has[single], axis=1)
        w, t = weights[single, j], arrivals[single, j]
        one = _single_element(shape, dt, t_d, k_att, raw_peak)
        peak[single], t_half[single], slope[single] = w * one[0], t + one[1], one[2]
        if raw_peak:
            peak_raw[single] = w * one[3]

    two = np.flatnonzero(count == 2)
    if len(two):
        table = _pair_table(shape, dt, t_d, k_att, raw_peak)
        t1, t2, w1, w2 = _pair_elements(arrivals[two], weights[two], has[two])
        close = t2 - t1 <= table.max_separation_s
        sel = two[close]
        w = w1[close] + w2[close]
        out = table.features(t2[close] - t1[close], w1[close] / w)
        peak[sel], t_half[sel], slope[sel] = w * out[0], t1[close] + out[1], out[2]
        if raw_peak:
            peak_raw[sel] = w * out[3]
        count = count.copy()
        count[sel] = 0  # done

    multi = np.flatnonzero(count > 1)
    if len(multi):
        order = np.argsort(~has[multi], axis=1, kind="stable")  # contributions first
        arr = np.take_along_axis(arrivals[multi], order, axis=1)
        wts = np.take_along_axis(weights[multi], order, axis=1)
        width = _bucket_counts(count[multi])
        threaded = int(np.sum(width)) * 64 > _THREAD_MIN_ELEMENTS  # ~64 samples per window
        jobs = []
        pending = np.zeros(0, np.int64)
        for k in np.unique(width):  # element counts up to a power of two, small groups padded
            pending = np.concatenate([pending, np.flatnonzero(width == k)])
            if len(pending) >= 256 or k == width.max():
                a, w, p = arr[pending, :k], wts[pending, :k], multi[pending]
                jobs += _jobs(shape, a, w, p, dt, t_d, max_elements, threaded)
                pending = pending[:0]

        def work(job):
            pixels, args = job
            return pixels, _features_chunk(shape, *args, k_att, raw_peak)

        # numpy releases the GIL in these array passes: two threads use both cores, when the work
        # is large enough to repay starting them
        if threaded:
            outputs = parallel.map_threads(work, jobs)
        else:
            outputs = [work(job) for job in jobs]
        for sel, out in outputs:
            peak[sel], t_half[sel], slope[sel] = out[0], out[1], out[2]
            if raw_peak:
                peak_raw[sel] = out[3]
    return EchoFeatures(peak, t_half, slope, peak_raw)


def _jobs(shape, arrivals, weights, pixel, dt, t_d, max_elements, threaded=False) -> list[tuple]:
    """Chunks (pixel, the arguments of _features_chunk up to t_begin) of pixels with k elements
    each (contributing or of weight 0), grouped by window length (at least one chunk per thread
    if ``threaded``)."""
    k = arrivals.shape[1]
    has = weights > 0
    t_first = np.where(has, arrivals, np.inf).min(axis=1)
    t_last = np.where(has, arrivals, -np.inf).max(axis=1)
    arrivals = np.where(has, arrivals, t_first[:, None])  # keep lookups in range
    # Each window starts where the pulse is below 0.4 / k of its peak: y there is at most
    # 0.4/k sum(w) p_max, below half of max(y) >= max_k(w_k) p_max >= sum(w)/k p_max. Capped at
    # 10 % and two samples early, so that the CFD's delayed copy exists around its crossing.
    t_begin = shape.rising_time_s(min(0.4 / k, 0.1)) - 2 * dt
    span = shape.t_peak_s + t_d - t_begin + 3 * dt
    n_samples = np.ceil((t_last - t_first + span) / dt).astype(np.int64) + 2
    # chunks of pixels sorted by window length, each sampled on its longest window (at most
    # 50 % longer than its shortest unless that leaves fewer than 512 pixels): few large array
    # passes (the per-pass overhead dominates small ones), little padding
    order = np.argsort(n_samples, kind="stable")
    n_samples = n_samples[order]
    cap = -(-len(order) // parallel.threads()) if threaded else len(order)
    jobs = []
    i = 0
    while i < len(order):
        j = int(np.searchsorted(n_samples, 1.5 * n_samples[i], side="right"))
        j = min(max(j, i + 512), i + cap, len(order))
        while j > i + 1 and (j - i) * int(n_samples[j - 1]) * k > max_elements:
            j = i + max(1, min(j - i - 1, max_elements // (int(n_samples[j - 1]) * k)))
        sel = order[i:j]
        length = int(n_samples[j - 1])
        jobs.append(
            (pixel[sel], (arrivals[sel], weights[sel], t_first[sel], length, dt, t_d, t_begin))
        )
        i = j
    return jobs


_SINGLE: dict[tuple, tuple] = {}
_PAIRS: dict[tuple, PairTable] = {}


def _pair_elements(arrivals, weights, has):
    """The two contributing elements of each row, earlier first: t1, t2, w1, w2 (each (n,))."""
    k = arrivals.shape[1]
    i = np.argmax(has, axis=1)
    j = k - 1 - np.argmax(has[:, ::-1], axis=1)
    rows = np.arange(len(arrivals))
    ta, tb, wa, wb = arrivals[rows, i], arrivals[rows, j], weights[rows, i], weights[rows, j]
    swap = tb < ta
    return (
        np.where(swap, tb, ta),
        np.where(swap, ta, tb),
        np.where(swap, wb, wa),
        np.where(swap, wa, wb),
    )


@dataclass(frozen=True)
class PairTable:
    """Features of the two-element echo (weights q, 1 - q at delays 0 and d) on a grid of
    separations d in [0, max_separation_s] and shares q in [0, 1], bilinearly interpolated. A
    two-element echo of total weight W at t1, t2 has peak W P(d, q), half-maximum t1 + T(d, q) and
    CFD slope S(d, q) (the normalised CFD signal does not scale with W)."""

    max_separation_s: float
    grid: tuple  # (P, T, S, R) arrays of shape (n_d, n_q); R (raw peak) or None

    def features(self, d, q) -> tuple:
        n_d, n_q = self.grid[0].shape
        x = np.clip(d / self.max_separation_s, 0.0, 1.0) * (n_d - 1)
        y = np.clip(q, 0.0, 1.0) * (n_q - 1)
        i = np.minimum(x.astype(np.int64), n_d - 2)
        j = np.minimum(y.astype(np.int64), n_q - 2)
        fx, fy = x - i, y - j

        def at(m):
            return (m[i, j] * (1 - fx) + m[i + 1, j] * fx) * (1 - fy) + (
                m[i, j + 1] * (1 - fx) + m[i + 1, j + 1] * fx
            ) * fy

        return tuple(at(m) if m is not None else None for m in self.grid)


# the pair table's reach and resolution: separations up to half the 10-90 % rise time (merged
# sub-ray echoes are at most a quarter apart), 65 x 65 nodes (interpolation error ~7 um in range,
# 1e-5 in peak: measured against the sampled features)
PAIR_REACH = 0.5
PAIR_NODES = 65


def _pair_table(shape: PulseShape, dt: float, t_d: float, k_att: float, raw: bool) -> PairTable:
    """The pulse's two-element features, computed like any echo's once and kept."""
    key = (shape.tau_s, shape.a, shape.sigma_h_s, dt, t_d, k_att, raw)
    if key not in _PAIRS:
        if len(_PAIRS) > 64:
            _PAIRS.clear()
        reach = PAIR_REACH * shape.rise_time_10_90_s
        d, q = np.meshgrid(
            np.linspace(0.0, reach, PAIR_NODES), np.linspace(0.0, 1.0, PAIR_NODES), indexing="ij"
        )
        arrivals = np.stack([np.zeros(d.size), d.ravel()], axis=1)
        weights = np.stack([q.ravel(), 1.0 - q.ravel()], axis=1)
        jobs = _jobs(shape, arrivals, weights, np.arange(d.size), dt, t_d, 1 << 22)
        grid = [np.zeros(d.size) for _ in range(4)]
        for pixels, args in jobs:
            for g, v in zip(grid, _features_chunk(shape, *args, k_att, raw), strict=True):
                if v is not None:
                    g[pixels] = v
        grid = [g.reshape(d.shape) for g in grid]
        _PAIRS[key] = PairTable(reach, (*grid[:3], grid[3] if raw else None))
    return _PAIRS[key]


def _single_element(shape: PulseShape, dt: float, t_d: float, k_att: float, raw: bool) -> tuple:
    """Features (peak, t_half, slope, raw peak) of the reference pulse arriving at t = 0 with
    unit weight, computed like any echo's and kept: a one-element echo is this pulse shifted and
    scaled (its half-maximum and CFD crossings move with the arrival; the slope of the normalised
    CFD signal does not change)."""
    key = (shape.tau_s, shape.a, shape.sigma_h_s, dt, t_d, k_att, raw)
    if key not in _SINGLE:
        if len(_SINGLE) > 64:
            _SINGLE.clear()
        ((_, args),) = _jobs(
            shape, np.zeros((1, 1)), np.ones((1, 1)), np.zeros(1), dt, t_d, 1 << 20
        )
        out = _features_chunk(shape, *args, k_att, raw)
        _SINGLE[key] = tuple(float(v[0]) if v is not None else None for v in out)
    return _SINGLE[key]


def _bucket_counts(count: np.ndarray) -> np.ndarray:
    """Element counts rounded up to a power of two (pixels then share a few array shapes)."""
    return 2 ** np.ceil(np.log2(np.maximum(count, 1))).astype(np.int64)


def split_elements(arrivals_s, weights, spread_s):
    """Each element as the two-point rule of a delay spread: halves at +- ``spread_s``.

    arrivals_s, weights : (n, K); spread_s : (n,) standard deviation of each element's delays [s]
    (the range spread of a sub-ray's cell, two-way). Returns (n, 2 K) delays and weights; a pixel
    with no spread keeps each element whole (its twin has weight 0).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    s = np.asarray(spread_s, dtype=np.float64)[:, None]
    spread = s > 0
    early = np.where(weights > 0, arrivals - s, arrivals)
    late = np.where(weights > 0, arrivals + s, arrivals)
    half = np.where(spread, 0.5 * weights, weights)
    return (
        np.concatenate([early, late], axis=1),
        np.concatenate([half, np.where(spread, half, 0.0)], axis=1),
    )


def merge_elements(arrivals_s, weights, window_s: float):
    """Merge each pixel's elements that arrive within ``window_s`` of each other into two.

    Delays are cut into bins of ``window_s`` from the pixel's first arrival; each bin's elements
    become the two-point distribution with the same total weight, mean delay, spread and skew
    (the two-point Gauss rule of the bin's delays), so the echo changes only through the fourth
    and higher moments of each bin, O(window^4) times the pulse's fourth derivative. A pixel lit
    by a plane or a few facets keeps a few elements instead of every sub-ray.

    arrivals_s, weights : (n, K) -- delays [s] and weights (0 = none)
    Returns (n, 2 S) delays and weights, S the most bins any pixel uses (unused: weight 0).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    n, k = arrivals.shape
    has = weights > 0
    if n == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    t0 = np.where(has, arrivals, np.inf).min(axis=1, keepdims=True)
    t0 = np.where(np.isfinite(t0), t0, 0.0)
    row = np.broadcast_to(np.arange(n)[:, None], (n, k))[has]
    x = ((arrivals - t0) / window_s)[has]  # delay since the pixel's first, in bins
    b = np.floor(x).astype(np.int64)
    w, u = weights[has], x - b  # u: position inside the bin, [0, 1)
    n_bins = int(b.max()) + 1 if len(b) else 1
    key = row * n_bins + b
    if n * n_bins <= 8 * max(n * k, 1):  # dense: number the occupied bins of each row
        occupied = (np.bincount(key, minlength=n * n_bins) > 0).reshape(n, n_bins)
        position = np.cumsum(occupied, axis=1) - 1
        n_seg = max(int(position[:, -1].max()) + 1, 1)
        seg = position.ravel()[key]
    else:  # a few pixels span many bins: number the distinct keys instead
        keys, inverse = np.unique(key, return_inverse=True)
        first = np.searchsorted(keys // n_bins, np.arange(n))
        seg_of_key = np.arange(len(keys)) - first[keys // n_bins]
        n_seg = int(seg_of_key.max()) + 1
        seg = seg_of_key[inverse]
    dest = row * n_seg + seg
    m0 = np.bincount(dest, w, minlength=n * n_seg)
    safe = np.where(m0 > 0, m0, 1.0)
    mu = np.bincount(dest, w * u, minlength=n * n_seg) / safe
    d = u - mu[dest]  # central moments from deviations: no cancellation
    wd2 = w * d * d
    sd = np.sqrt(np.bincount(dest, wd2, minlength=n * n_seg) / safe)
    c3 = np.bincount(dest, wd2 * d, minlength=n * n_seg) / safe
    start = np.zeros(n * n_seg)
    start[dest] = b
    gamma = np.where(sd > 1e-9, c3 / np.maximum(sd, 1e-9) ** 3, 0.0)
    root = np.sqrt(gamma**2 + 4.0)
    z1, z2 = 0.5 * (gamma - root), 0.5 * (gamma + root)  # z1 z2 = -1, z1 + z2 = gamma
    p1 = z2 / (z2 - z1)
    t_nodes = np.stack([start + mu + sd * z1, start + mu + sd * z2], axis=-1) * window_s
    w_out = np.stack([m0 * p1, m0 * (1.0 - p1)], axis=-1).reshape(n, 2 * n_seg)
    t_out = t0 + t_nodes.reshape(n, 2 * n_seg)
    return np.where(w_out > 0, t_out, t0), w_out


# below this (pixels x samples x elements), a thread pool costs more than it saves: the many
# small array passes then contend for the GIL (measured: 3200 pixels of ~3 elements ran in 13 ms
# on one thread, 23 ms on two)
_THREAD_MIN_ELEMENTS = 1 << 21


def echo_waveform(shape: PulseShape, arrivals_s, weights, dt: float):
    """One pixel's full echo on its own window, for display and export.

    arrivals_s, weights : (K,) -- one pixel's sub-ray delays [s] and weights
    Returns t_s (L,), raw P_r per joule (L,), band-limited y per joule (L,).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    has = weights > 0
    if not has.any():
        return np.zeros(0), np.zeros(0), np.zeros(0)
    a, w = arrivals[has], weights[has]
    t = np.arange(a.min() + shape.t_start_s, a.max() + shape.t_end_s, dt)
    tau = t[:, None] - a[None, :]
    return t, shape.raw_at(tau) @ w, shape.filtered_at(tau) @ w
