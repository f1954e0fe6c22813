"""The discriminator (Eq. 19; docs/physics.md#mc-discriminator): continuous-time arming on V_T, the
constant-fraction stop, the re-arm hold-off, and the reference pulse's own stop."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ....pulse import A_FWHM, PulseShape
from .currents import BandLimit

ARMING_REFINE = 8  # between-sample excursions are looked for at dt / 8
ARMING_MARGIN = 0.15  # pairs of samples within 15 % below V_T may hide an excursion...
ARMING_CURVATURE = 0.25  # ...if their curvature can lift them to V_T (see _refined_crossings)
ARMING_SLACK = 0.02  # fraction of V_T added to that reach
REFERENCE_PHASES = 16  # the reference stop is averaged over this many grid phases
RAW_TAIL = 1e-9  # the emitted pulse is cut where it falls below 1e-9 of its peak


@dataclass(frozen=True)
class Stops:
    """Discriminator output, sorted by row then time.

    row : (s,) int64 -- waveform row of each stop
    t_s : (s,) float64 -- stop time t* [s] (same time origin as the waveform's ``t0_s``)
    t_arm_s : (s,) float64 -- the arming crossing t_a [s]
    fired : (s,) bool -- False where s(t) had no upward zero crossing in the Eq. 19 window (then
        t* = t_a: the zero-crossing comparator was already high when the arming one latched)
    """

    row: np.ndarray
    t_s: np.ndarray
    t_arm_s: np.ndarray
    fired: np.ndarray


def _sample_crossings(y, thr, candidates=None):
    """Upward crossings of ``thr`` between consecutive samples (not at column 0).

    candidates : flat indices of y that include every sample at or above thr (sorted), or None
    Returns row, j (first sample at or above thr), t_a in samples (interpolated)."""
    n, length = y.shape
    if candidates is None:
        flat = np.flatnonzero(y >= thr)
    else:
        flat = candidates[y.reshape(-1)[candidates] >= thr]
    col = flat % length
    prev_above = np.zeros(len(flat), dtype=bool)
    prev_above[1:] = flat[1:] - 1 == flat[:-1]
    idx = flat[~prev_above & (col > 0)]
    yf = y.reshape(-1)
    y0 = yf[idx - 1].astype(np.float64)
    y1 = yf[idx].astype(np.float64)
    j = idx % length
    return idx // length, j, (j - 1) + (thr - y0) / (y1 - y0)


def _refined_crossings(y, thr, x_padded, band: BandLimit, n_sub: int, candidates=None):
    """Excursions above ``thr`` that start and end between two samples both below it.

    Between samples j and j+1 the curve rises above their chord by at most dt^2 / 8 max|y''|. For
    band-limited noise (autocorrelation exp(-t^2 / (4 sigma_h^2))) near level u sigma_n the
    second derivative is N(-u / (2 sigma_h^2), 0.71 / sigma_h^2) in units of sigma_n, so at the
    default dt = 0.35 sigma_h the rise stays below 0.0157 (u / 2 + 5 x 0.71) sigma_n: 0.07 at
    TNR 2, 0.12 at TNR 8, below ARMING_MARGIN x TNR. An echo whose peak barely reaches V_T
    rises by at most ~0.5 % of its peak above the chord. Of the pairs whose larger sample is
    within that margin below ``thr``, those that can reach it by their own curvature (larger
    sample + ARMING_CURVATURE x the larger |second difference| + ARMING_SLACK x thr, twice the
    Taylor bound dt^2/8 |y''| plus slack for y'' varying within the pair) are evaluated exactly
    at q dt / n_sub from the input samples. The tests check that this pre-selection finds the
    same crossings as evaluating every pair within the margin.

    The curve between the samples is h_B * x at the fractional delays plus the chord of what the
    samples hold beyond h_B * x at the two ends (y - h_B * x at j and j + 1): the gate adds the
    band-limited signal in closed form, and h_B * (the signal sampled at dt) differs from it by
    up to 0.4 % of the peak where the band limit is much wider than the step (B = 1 MHz, tau =
    10 ps), more than the curve falls in one sample on the tail of a wide echo; uncorrected, the
    tail's samples below V_T looked like an excursion above it (a second arming on every echo).

    candidates : flat indices of y that include every sample at or above (1 - ARMING_MARGIN) thr
    (sorted), or None.

    Returns row, j (first sample after the excursion's start), t_a in samples.
    """
    n, length = y.shape
    if candidates is None:
        near = np.flatnonzero((y >= (1.0 - ARMING_MARGIN) * thr) & (y < thr))
    else:
        v = y.reshape(-1)[candidates]
        near = candidates[(v >= (1.0 - ARMING_MARGIN) * thr) & (v < thr)]
    if len(near) == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    col = near % length
    # pairs (j, j+1) with j = col - 1 or col, both samples in the row and both below thr
    starts = np.sort(np.concatenate([near[col > 0] - 1, near[col < length - 1]]))
    starts = starts[np.append(True, starts[1:] != starts[:-1])]
    yf = y.reshape(-1)
    ya = yf[starts].astype(np.float64)
    yb = yf[starts + 1].astype(np.float64)
    j = starts % length
    # curvature of the pair from the second differences at both samples (dt^2 y'')
    yp = yf[np.where(j > 0, starts - 1, starts)].astype(np.float64)
    yn = yf[np.where(j + 2 < length, starts + 2, starts + 1)].astype(np.float64)
    d2 = np.maximum(np.abs(yp - 2.0 * ya + yb), np.abs(ya - 2.0 * yb + yn))
    reach = np.maximum(ya, yb) + ARMING_CURVATURE * d2 + ARMING_SLACK * thr
    keep = (ya < thr) & (yb < thr) & (reach >= thr)
    starts, ya, yb = starts[keep], ya[keep], yb[keep]
    row, j = starts // length, starts % length
    m = band.half_width
    taps = band.shifted_taps(n_sub, ends=True).astype(x_padded.dtype)  # (n_sub + 1, 2m + 1)
    frac = np.arange(1, n_sub) / n_sub
    out_row, out_j, out_t = [], [], []
    step = max(1, (1 << 22) // (2 * m + 1))
    offsets = 2 * m - np.arange(2 * m + 1)
    for c in range(0, len(starts), step):
        r, jj = row[c : c + step], j[c : c + step]
        window = x_padded[r[:, None], jj[:, None] + offsets[None, :]]  # (p, 2m + 1)
        full = (window @ taps.T).astype(np.float64)  # (p, n_sub + 1): h_B * x at t_j + q dt / n_sub
        y_a, y_b = ya[c : c + step, None], yb[c : c + step, None]
        off_a, off_b = y_a - full[:, :1], y_b - full[:, -1:]
        sub = full[:, 1:-1] + off_a + (off_b - off_a) * frac[None, :]  # y(t_j + q dt / n_sub)
        vals = np.concatenate([y_a, sub, y_b], axis=1)
        hit = vals[:, 1:-1] >= thr
        any_hit = hit.any(axis=1)
        if not any_hit.any():
            continue
        q = np.argmax(hit, axis=1)[any_hit] + 1  # first sub-point at or above thr
        v = vals[any_hit]
        rows = np.arange(len(v))
        v0, v1 = v[rows, q - 1], v[rows, q]
        out_row.append(r[any_hit])
        out_j.append(jj[any_hit] + 1)
        out_t.append(jj[any_hit] + (q - 1 + (thr - v0) / (v1 - v0)) / n_sub)
    if not out_row:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    return np.concatenate(out_row), np.concatenate(out_j), np.concatenate(out_t)


def _first_local_max(y, row, start):
    """First sample index i >= start where y stops rising (y[i + 1] < y[i]); L-1 if none."""
    length = y.shape[1]
    jpk = np.full(len(row), length - 1, dtype=np.int64)
    todo = np.arange(len(row))
    pos = start.astype(np.int64).copy()
    width = 32
    while len(todo):
        idx = np.minimum(pos[todo, None] + np.arange(width + 1)[None, :], length - 1)
        block = y[row[todo, None], idx]
        falls = (block[:, 1:] < block[:, :-1]) & (idx[:, 1:] > idx[:, :-1])
        found = falls.any(axis=1)
        jpk[todo[found]] = idx[found, 0] + np.argmax(falls[found], axis=1)
        pos[todo] += width
        todo = todo[~found & (pos[todo] < length - 1)]
        width *= 2
    return jpk


def batches(cost, budget: int):
    """Index batches, cheapest first, each of total (count x its largest cost) <= budget."""
    order = np.argsort(cost, kind="stable")
    sorted_cost = cost[order]
    c = 0
    while c < len(order):
        count = max(1, budget // max(1, int(sorted_cost[c])))
        count = max(
            1, min(count, budget // max(1, int(sorted_cost[min(len(order), c + count) - 1])))
        )
        yield order[c : c + count]
        c += count


def _cfd_stop(y, row, t_a, jpk, delay, cfd_fraction):
    """Eq. 19: the last upward zero crossing of s(t) = y(t - t_d) - k y(t) in
    [t_a - t_d, t_pk + t_d], t_d = ``delay`` and k = ``cfd_fraction``.

    All times in samples. y(t - delay) is linear between samples; a crossing is interpolated
    linearly between the two samples that bracket it. Returns t* (samples) and fired (bool).
    """
    length = y.shape[1]
    ns = math.floor(delay)
    frac = delay - ns
    lo = t_a - delay
    hi = jpk + delay
    i0 = np.floor(lo).astype(np.int64)
    i1 = np.ceil(hi).astype(np.int64)
    n_win = i1 - i0 + 1
    t_star = t_a.copy()
    fired = np.zeros(len(row), dtype=bool)
    for sel in batches(n_win, 1 << 22):
        w = int(n_win[sel].max())
        i = i0[sel, None] + np.arange(w)[None, :]  # (p, w) sample indices
        r = row[sel, None]
        yv = y[r, np.clip(i, 0, length - 1)].astype(np.float64)
        yd = (1.0 - frac) * y[r, np.clip(i - ns, 0, length - 1)].astype(np.float64)
        yd += frac * y[r, np.clip(i - ns - 1, 0, length - 1)]
        s = yd - cfd_fraction * yv
        s0, s1 = s[:, :-1], s[:, 1:]
        up = (s0 < 0) & (s1 >= 0)
        tc = i[:, :-1] + s0 / np.where(up, s0 - s1, -1.0)
        ok = up & (tc >= lo[sel, None]) & (tc <= hi[sel, None]) & (i[:, 1:] <= i1[sel, None])
        has = ok.any(axis=1)
        last = w - 2 - np.argmax(ok[:, ::-1], axis=1)
        rows = np.arange(len(sel))
        t_star[sel[has]] = tc[rows, last][has]
        fired[sel[has]] = True
    done = np.flatnonzero(fired)
    t_star[done] = _cubic_crossing(y, row[done], t_star[done], delay, cfd_fraction)
    return t_star, fired


def _cubic_at(y, row, t):
    """y at fractional sample positions t (one per row) by 4-point (cubic) Lagrange
    interpolation: exact for cubics, error O(dt^4) on the smooth band-limited current."""
    length = y.shape[1]
    base = np.floor(t).astype(np.int64)
    u = t - base
    cols = np.clip(base[:, None] + np.arange(-1, 3)[None, :], 0, length - 1)
    v = y[row[:, None], cols].astype(np.float64)
    w = np.stack(
        [
            -u * (u - 1.0) * (u - 2.0) / 6.0,
            (u + 1.0) * (u - 1.0) * (u - 2.0) / 2.0,
            -(u + 1.0) * u * (u - 2.0) / 2.0,
            (u + 1.0) * u * (u - 1.0) / 6.0,
        ],
        axis=1,
    )
    return np.einsum("nk,nk->n", v, w)


def _cubic_crossing(y, row, t_lin, delay, cfd_fraction, steps: int = 4):
    """The CFD zero crossing refined on the cubic interpolant of the samples (samples units).

    The linear crossing of the sampled s(t) (a linear delayed copy, a chord between samples) is
    biased by the curvature of y, by an amount that depends on where the samples fall: -3 mm in
    mean at the default step, and a reference pulse sampled at one phase does not share it.
    Regula falsi (Illinois) on s(t) = y_c(t - t_d) - k y_c(t), y_c the cubic interpolant, in the
    sample interval of the linear crossing; where the interpolant does not bracket a root there,
    the linear crossing stays.
    """
    if len(row) == 0:
        return t_lin

    def s(t):
        return _cubic_at(y, row, t - delay) - cfd_fraction * _cubic_at(y, row, t)

    a = np.floor(t_lin)
    b = a + 1.0
    sa, sb = s(a), s(b)
    ok = (sa < 0) & (sb >= 0)
    t = t_lin.copy()
    side = np.zeros(len(row), dtype=np.int8)  # which end moved last: -1 a, +1 b
    for _ in range(steps):
        t = np.where(ok, a - sa * (b - a) / np.where(sb != sa, sb - sa, 1.0), t)
        st = s(t)
        left = st < 0
        # Illinois: when the same end moves twice, halve the other end's value
        sb = np.where(left & (side == -1), 0.5 * sb, sb)
        sa = np.where(~left & (side == 1), 0.5 * sa, sa)
        a, sa = np.where(left, t, a), np.where(left, st, sa)
        b, sb = np.where(left, b, t), np.where(left, sb, st)
        side = np.where(left, -1, 1).astype(np.int8)
    return np.where(ok, t, t_lin)


def _apply_holdoff(row, t_a, t_star, holdoff, first_stop, max_stops=None):
    """Which arming crossings become stops: after a stop the discriminator is dead from t_a to
    max(t_a, t*) + hold-off; a row records at most ``max_stops`` stops (None: no limit); with
    first_stop only the first stop of a row is kept (``max_stops = 1``).

    row, t_a sorted by (row, t_a). Returns accepted (bool)."""
    m = len(row)
    accepted = np.zeros(m, dtype=bool)
    if m == 0:
        return accepted
    first = np.ones(m, dtype=bool)
    first[1:] = row[1:] != row[:-1]
    start = np.flatnonzero(first)
    rank = np.arange(m) - np.repeat(start, np.diff(np.append(start, m)))
    if first_stop or max_stops == 1:
        accepted[start] = True
        return accepted
    limit = np.inf if max_stops is None else int(max_stops)
    dead_until = np.full(int(row.max()) + 1, -np.inf)
    count = np.zeros(int(row.max()) + 1, dtype=np.int64)
    order = np.argsort(rank, kind="stable")
    bounds = np.cumsum(np.bincount(rank))
    lo = 0
    for hi in bounds:
        sel = order[lo:hi]
        lo = hi
        ok = (t_a[sel] >= dead_until[row[sel]]) & (count[row[sel]] < limit)
        sel = sel[ok]
        accepted[sel] = True
        dead_until[row[sel]] = np.maximum(t_a[sel], t_star[sel]) + holdoff
        count[row[sel]] += 1
    return accepted


def discriminate(
    y_a,
    dt_s: float,
    threshold_a: float,
    t_d_s: float,
    cfd_fraction: float,
    *,
    holdoff_s: float = 0.0,
    first_stop: bool = False,
    max_stops: int | None = None,
    t0_s=0.0,
    x_padded_a=None,
    band: BandLimit | None = None,
    t_open_s: float = -np.inf,
    candidate_rows: np.ndarray | None = None,
) -> Stops:
    """Arming comparator + constant-fraction discriminator over whole waveforms (Eq. 19).

    The discriminator arms where y crosses ``threshold_a`` upwards (t_a, interpolated) and fires
    at the last upward zero crossing of ``s(t) = y(t - t_d) - cfd_fraction y(t)`` in
    ``[t_a - t_d, t_pk + t_d]``, t_pk the first local maximum of y after t_a. Every arming
    crossing is a stop unless it falls in the dead time of the previous stop (from its t_a to
    ``max(t_a, t*) + holdoff_s``) or the waveform already has ``max_stops`` stops;
    ``first_stop`` keeps only the first stop of each waveform (``max_stops = 1``).

    Parameters
    ----------
    y_a : (n, L) float -- band-limited current [A] at ``t0_s + j dt_s``
    dt_s : float -- sample step [s]
    threshold_a : float -- arming level V_T [A]
    t_d_s, cfd_fraction : float -- CFD delay [s] and attenuation [1] (Eq. 19)
    holdoff_s : float -- re-arm hold-off after a stop [s] (the gate simulation uses one FWHM)
    first_stop : bool -- keep only each waveform's first stop
    max_stops : int, optional -- at most this many stops per waveform (None: no limit)
    t0_s : float or (n,) float -- time of each row's sample 0 [s]
    x_padded_a : (n, L + 2 m) float, optional -- the input of h_B (signal + white noise) that
        made ``y_a``; with ``band`` the arming is continuous-time (between-sample excursions
        found exactly); without, only crossings between samples arm (a sampled comparator).
    band : BandLimit, optional
    t_open_s : float -- the TDC's gate opens here [s]: a stop (t*) before it is not recorded and
        neither counts towards ``max_stops`` nor holds off later ones
    candidate_rows : (r,) int, sorted, optional -- the only rows that may reach (1 -
        ARMING_MARGIN) V_T (continuous arming) or V_T (sampled): the others are not searched

    Returns
    -------
    Stops
    """
    y = np.asarray(y_a)
    if y.ndim != 2:
        raise ValueError(f"y_a must be (n, L), got shape {y.shape}")
    thr = float(threshold_a)
    continuous = x_padded_a is not None and band is not None
    # one pass over y (over its candidate rows): the samples the comparators can need (near or
    # above V_T)
    level = min(thr, (1.0 - ARMING_MARGIN) * thr if continuous else thr)
    if candidate_rows is None:
        candidates = np.flatnonzero(y >= level)
    else:
        rows = np.asarray(candidate_rows, dtype=np.int64)
        at = np.flatnonzero(y[rows] >= level)
        length = y.shape[1]
        candidates = rows[at // length] * length + at % length
    row, j, t_a = _sample_crossings(y, thr, candidates)
    if x_padded_a is not None and band is not None:
        r2, j2, t2 = _refined_crossings(
            y, thr, np.asarray(x_padded_a), band, ARMING_REFINE, candidates
        )
        row, j, t_a = np.concatenate([row, r2]), np.concatenate([j, j2]), np.concatenate([t_a, t2])
        order = np.lexsort((t_a, row))
        row, j, t_a = row[order], j[order], t_a[order]
    jpk = _first_local_max(y, row, j)
    t_d = t_d_s / dt_s
    t_star, fired = _cfd_stop(y, row, t_a, jpk, t_d, cfd_fraction)
    t0 = np.broadcast_to(np.asarray(t0_s, dtype=np.float64), (y.shape[0],))
    if t_open_s > -np.inf:
        gated = t0[row] + t_star * dt_s >= t_open_s
        row, t_a, t_star, fired = row[gated], t_a[gated], t_star[gated], fired[gated]
    accepted = _apply_holdoff(row, t_a, t_star, holdoff_s / dt_s, first_stop, max_stops)
    row, t_a, t_star, fired = row[accepted], t_a[accepted], t_star[accepted], fired[accepted]
    return Stops(row.astype(np.int64), t0[row] + t_star * dt_s, t0[row] + t_a * dt_s, fired)


def reference_stop_s(
    shape: PulseShape,
    band: BandLimit,
    t_d_s: float,
    cfd_fraction: float,
    dtype=np.float32,
    n_phases: int = REFERENCE_PHASES,
) -> float:
    """t*_ref: the emitted pulse (t = 0 at its start, Eq. 1) sampled at j dt, band-limited by the
    same taps and timed by the same discriminator, noise-free, armed at half its peak [s].

    Averaged over ``n_phases`` positions of the pulse's start between two samples, (q + 1/2) dt
    / n_phases, as echoes arrive at every phase: what sampling leaves of the crossing's error
    (below 0.1 mm with the cubic crossing) averages out. With the sampled convolution of the
    sampled pulse, one pulse starting on a sample was 3 mm late against the echoes at the
    default step (its onset kink): the Monte Carlo's range bias."""
    dt = band.dt_s
    m = band.half_width
    pre = m + math.ceil(t_d_s / dt) + 4
    t_end = raw_end_s(shape) + t_d_s
    t = dt * (np.arange(pre + math.ceil(t_end / dt) + m + 5) - pre)
    phase_s = dt * (np.arange(n_phases) + 0.5) / n_phases
    x = np.zeros((n_phases, len(t) + 2 * m), dtype=dtype)
    x[:, m : m + len(t)] = shape.raw_at(t[None, :] - phase_s[:, None])
    # the echoes' own signal path: the band-limited pulse in closed form at the sample times
    y = shape.filtered_at(t[None, :] - phase_s[:, None]).astype(dtype)
    stops = discriminate(
        y, dt, 0.5 * float(y.max()), t_d_s, cfd_fraction, t0_s=t[0], x_padded_a=x, band=band
    )
    if len(stops.t_s) != n_phases or not stops.fired.all():
        raise RuntimeError("the reference pulse did not give exactly one CFD stop per phase")
    return float(np.mean(stops.t_s - phase_s[stops.row]))


def raw_end_s(shape: PulseShape) -> float:
    """Time after the pulse start when the emitted pulse falls below RAW_TAIL of its peak [s]."""
    above = np.flatnonzero(shape.raw > RAW_TAIL * shape.raw.max())
    return float(shape.t0_s + shape.step_s * (above[-1] + 1))


def pulse_fwhm_s(shape: PulseShape) -> float:
    """FWHM of the emitted pulse of Eq. 1: tau for a = A_FWHM, 0.699 tau for the paper's a."""
    return shape.tau_s * A_FWHM / shape.a
