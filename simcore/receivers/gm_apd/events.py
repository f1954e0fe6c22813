"""Geiger-mode avalanches of every pixel and pulse of a frame (docs/physics.md#gm-events).

Each pixel's primary events are an inhomogeneous Poisson process over the range gate: the echo's
photoelectrons, rate ``PDE P_r(t) / (h nu)`` with ``P_r(t) = E sum_k w_k P0(t - t_k)`` the
optical echo of Eqs. 1, 29, 30 (the waveform the LM-APD's electronics band-limit), plus a
constant rate ``PDE P_bg / (h nu) + DCR`` of background photoelectrons and dark counts. Eq. 1 is
a Gamma(2, s) density with s = tau / a, so element k alone is a Poisson process whose
cumulative intensity is ``N_k G((t - t_k) / s)``, ``G(x) = 1 - (1 + x) e^-x``: its next event
after any time is drawn exactly by inverting G (time rescaling). The pixel's process is the
superposition of its elements' and the constant one, so the next event after the pixel re-arms
is the earliest of their next events (competing Poisson processes): exact, in continuous time,
however bright the echo (no photon is drawn that the pixel cannot see).

The detector (docs/physics.md#gm-dead-time): an avalanche makes the pixel blind for the dead time
``d``; events during it are lost and do not extend it (non-paralysable: actively quenched). Every
pixel is re-armed when the gate opens for each pulse (reset per gate): framed GM-APD arrays arm
the whole array at the gate, and a frame has no pulse rate from which a carried-over dead time
could follow. A dead time longer than the gate gives the first-photon detector. With
probability ``p_ap`` an avalanche is followed by an afterpulse the instant the pixel re-arms
(released trapped carriers; an afterpulse can afterpulse again). Crosstalk: with probability
``p_ct`` an avalanche fires one of its four nearest neighbours (chosen at random) at the same
instant, unless that neighbour is dead then (one generation, drawn after the pixels' own events).
Every recorded avalanche is then timed with Gaussian jitter and the TDC's bin.

Pixels are simulated in chunks of bounded size on the frame's threads (simcore.parallel); each
chunk draws from its own child generator spawned from the caller's, so a frame is reproducible
for a seed whatever the threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import parallel
from ...stage import Cancelled, stop_check

PAIRS_PER_CHUNK = 1 << 19  # (pixel, pulse) pairs simulated at once by one thread
X_END = 60.0  # G(x) beyond 60 s is 1 - 61 e^-60 = 1 - 5e-25: an element's process has ended
EVENT_SIGNAL, EVENT_BACKGROUND, EVENT_AFTERPULSE, EVENT_CROSSTALK = 0, 1, 2, 3


@dataclass(frozen=True, kw_only=True)
class PixelRates:
    """What drives each pixel's avalanches over the gate [0, T) (times from the gate's opening).

    rate_hz : (n_pixels,) constant primary event rate (background photoelectrons and dark
        counts) of every pixel of the array [1/s]
    lit_pixel : (n,) int64 flat index of each pixel that sees the echo, ascending
    element_t_s : (n, K) start time of each echo element's pulse (Eq. 1's t = 0), from the gate's
        opening [s]
    element_pe : (n, K) mean photoelectrons of each element per pulse, PDE E w_k / (h nu) [1]
        (0 = no element)
    scale_s : s = tau / a, the Gamma(2, s) scale of Eq. 1's pulse [s]
    """

    rate_hz: np.ndarray
    lit_pixel: np.ndarray
    element_t_s: np.ndarray
    element_pe: np.ndarray
    scale_s: float


@dataclass(frozen=True, kw_only=True)
class Detector:
    """The Geiger-mode pixel: gate T, dead time d, jitter, TDC bin, afterpulsing, crosstalk."""

    gate_s: float
    dead_time_s: float
    jitter_s: float
    bin_s: float
    afterpulsing: float = 0.0
    crosstalk: float = 0.0

    @property
    def n_bins(self) -> int:
        return int(np.ceil(self.gate_s / self.bin_s))


@dataclass(frozen=True, kw_only=True)
class Events:
    """The frame's recorded avalanches, sorted by pixel, then bin, then pulse.

    pixel : (m,) int32 flat pixel index; pulse : (m,) int32 pulse index
    bin : (m,) int32 TDC bin from the gate's opening (jitter included; events timed outside the
        gate are not recorded)
    kind : (m,) int8 EVENT_SIGNAL, EVENT_BACKGROUND (background or dark), EVENT_AFTERPULSE,
        EVENT_CROSSTALK -- what caused it (diagnostics and tests; a real array cannot tell)
    """

    pixel: np.ndarray
    pulse: np.ndarray
    bin: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return len(self.pixel)


def gamma2_cdf(x):
    """G(x) = 1 - (1 + x) e^-x, the CDF of Gamma(2, 1), accurate for small x (0 for x <= 0)."""
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return -np.expm1(np.log1p(x) - x)


def gamma2_inverse_hazard(y):
    """x >= 0 with x - ln(1 + x) = y, i.e. 1 - G(x) = e^-y: the inverse of Gamma(2, 1)'s
    cumulative hazard. Newton from a start that is within 2 % everywhere (series for small y,
    the fixed point x = y + ln(1 + x) for large y); five steps reach the rounding error."""
    y = np.asarray(y, dtype=np.float64)
    small = np.sqrt(2.0 * y) + (2.0 / 3.0) * y
    large = y + np.log1p(y + np.log1p(y))
    x = np.where(y < 1.5, small, large)
    for _ in range(5):
        f = x - np.log1p(x) - y
        x = np.maximum(x - f * (1.0 + x) / np.maximum(x, 1e-300), 0.0)
    return x


_Z_MAX = 8.0  # the table covers y = z^2 <= 64 (1 - G = e^-64); beyond, Newton
_Z_NODES = 1 << 13


def _inverse_hazard_table() -> np.ndarray:
    """x(z) of :func:`gamma2_inverse_hazard` at z = sqrt(y) on a uniform grid of _Z_NODES
    nodes over [0, _Z_MAX]: x is smooth in z (sqrt(2) z near 0, z^2 far out), so linear
    interpolation errs by at most (dz^2 / 8) max|x''| < 1e-6 (a femtosecond at s = 2 ns)."""
    z = np.linspace(0.0, _Z_MAX, _Z_NODES)
    x = gamma2_inverse_hazard(z * z)
    x.setflags(write=False)
    return x


_TABLE = _inverse_hazard_table()
_Z_STEP = _Z_MAX / (_Z_NODES - 1)


def inverse_hazard_fast(y: np.ndarray) -> np.ndarray:
    """:func:`gamma2_inverse_hazard` by the table (Newton beyond it)."""
    u = np.sqrt(y)
    u *= 1.0 / _Z_STEP
    far = u >= _Z_NODES - 1
    np.minimum(u, _Z_NODES - 1.000001, out=u)
    i = u.astype(np.intp)
    u -= i
    x = _TABLE[i]
    x += u * (_TABLE[i + 1] - x)
    if far.any():
        x[far] = gamma2_inverse_hazard(y[far])
    return x


def simulate_frame(
    rng: np.random.Generator,
    rates: PixelRates,
    detector: Detector,
    n_pulses: int,
) -> Events:
    """Every recorded avalanche of ``n_pulses`` pulses of every pixel (module docstring).

    Returns Events sorted by (pixel, bin, pulse).
    """
    n_pixels = len(rates.rate_hz)
    per_chunk = max(1, PAIRS_PER_CHUNK // int(n_pulses))
    bounds = [(p, min(p + per_chunk, n_pixels)) for p in range(0, n_pixels, per_chunk)]
    children = rng.spawn(len(bounds) + 1)
    lit_of = np.full(n_pixels, -1, dtype=np.int64)
    lit_of[rates.lit_pixel] = np.arange(len(rates.lit_pixel))

    stop = stop_check()  # a frame no longer wanted ends between chunks

    def work(job):
        (p0, p1), g = job
        if stop is not None and stop():
            raise Cancelled("stopped while drawing the avalanches")
        return _chunk_events(g, rates, lit_of, p0, p1, detector, int(n_pulses))

    jobs = list(zip(bounds, children[:-1], strict=True))
    parts = parallel.map_threads(work, jobs)
    pixel = np.concatenate([p[0] for p in parts])
    pulse = np.concatenate([p[1] for p in parts])
    t_s = np.concatenate([p[2] for p in parts])
    kind = np.concatenate([p[3] for p in parts])
    g = children[-1]
    if detector.crosstalk > 0 and len(pixel):
        pixel, pulse, t_s, kind = _with_crosstalk(g, pixel, pulse, t_s, kind, detector, n_pixels)
    return _timed(g, pixel, pulse, t_s, kind, detector)


def _chunk_events(g, rates: PixelRates, lit_of, p0, p1, det: Detector, n_pulses):
    """The avalanches of pixels p0..p1-1 over all pulses, in true (unjittered) time: pixel,
    pulse, t_s, kind. Round r finds every (pixel, pulse) pair's r-th avalanche at once."""
    n = p1 - p0
    pair_pixel = np.repeat(np.arange(p0, p1, dtype=np.int64), n_pulses)
    pair_pulse = np.tile(np.arange(n_pulses, dtype=np.int32), n)
    rate = rates.rate_hz[pair_pixel]
    lit = lit_of[pair_pixel]
    # the lit pairs' elements, flattened: element e of lit pixel i is (i, k) with pe > 0
    has = rates.element_pe > 0
    n_elem = has.sum(axis=1)
    e_t = rates.element_t_s[has]
    e_pe = rates.element_pe[has]
    e_first = np.concatenate([[0], np.cumsum(n_elem)])[:-1]
    s = rates.scale_s
    t_arm = np.zeros(len(pair_pixel))  # the pair is armed from here on
    pending_ap = np.zeros(len(pair_pixel), dtype=bool)
    active = np.flatnonzero((rate > 0) | (lit >= 0))
    out_pair, out_t, out_kind = [], [], []
    first_round = True
    while len(active):
        t0 = t_arm[active]
        t_next = np.full(len(active), np.inf)
        kind = np.full(len(active), EVENT_BACKGROUND, dtype=np.int8)
        r = rate[active]
        bg = r > 0
        t_next[bg] = t0[bg] + g.standard_exponential(int(bg.sum())) / r[bg]
        # the echo: each element's next event after t0, the earliest of them
        li = lit[active]
        idx = np.flatnonzero(li >= 0)
        if len(idx):
            cnt = n_elem[li[idx]]
            owner = np.repeat(idx, cnt)  # position in `active` of each (pair, element)
            e = np.arange(len(owner)) + np.repeat(e_first[li[idx]] - (np.cumsum(cnt) - cnt), cnt)
            pe = e_pe[e]
            draw = g.standard_exponential(len(owner))
            if first_round:  # armed since the gate opened: every element is still to come
                fires = draw < pe
                owner, e, pe, g1 = owner[fires], e[fires], pe[fires], draw[fires]
                g1 /= pe
                y = -np.log1p(-g1)
            else:  # the survival 1 - G after the next event: 1 - G(x0) less the drawn share
                x0 = np.clip((t0[owner] - e_t[e]) / s, 0.0, X_END)
                surv = np.exp(np.log1p(x0) - x0)  # (1 + x) e^-x, accurate far in the tail
                fires = draw < pe * surv  # the element's photoelectrons still to come
                owner, e, pe = owner[fires], e[fires], pe[fires]
                y = -np.log(surv[fires] - draw[fires] / pe)
            t_sig = e_t[e] + s * inverse_hazard_fast(y)
            best = np.full(len(active), np.inf)
            if len(owner):  # owner is ascending: each pair's elements are contiguous
                first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
                best[owner[first]] = np.minimum.reduceat(t_sig, first)
            sig = best < t_next
            t_next[sig] = best[sig]
            kind[sig] = EVENT_SIGNAL
        ap = pending_ap[active]
        t_next[ap] = t0[ap]
        kind[ap] = EVENT_AFTERPULSE
        inside = t_next < det.gate_s
        active, t_next, kind = active[inside], t_next[inside], kind[inside]
        out_pair.append(active)
        out_t.append(t_next)
        out_kind.append(kind)
        t_arm[active] = t_next + det.dead_time_s
        if det.afterpulsing > 0:
            pending_ap[active] = g.random(len(active)) < det.afterpulsing
        keep = t_arm[active] < det.gate_s
        active = active[keep]
        first_round = False
    pair = np.concatenate(out_pair) if out_pair else np.zeros(0, np.int64)
    return (
        pair_pixel[pair].astype(np.int32),
        pair_pulse[pair],
        np.concatenate(out_t) if out_t else np.zeros(0),
        np.concatenate(out_kind) if out_kind else np.zeros(0, np.int8),
    )


def _with_crosstalk(g, pixel, pulse, t_s, kind, det: Detector, n_pixels: int):
    """Add the crosstalk avalanches: each avalanche fires, with probability p_ct, one of its four
    nearest neighbours (at random; none off the array) at the same instant, unless that
    neighbour is within the dead time of one of its own avalanches of that pulse."""
    side = int(round(np.sqrt(n_pixels)))
    src = np.flatnonzero(g.random(len(pixel)) < det.crosstalk)
    row, col = np.divmod(pixel[src].astype(np.int64), side)
    step = g.integers(0, 4, size=len(src))
    row = row + np.array([-1, 1, 0, 0])[step]
    col = col + np.array([0, 0, -1, 1])[step]
    on = (row >= 0) & (row < side) & (col >= 0) & (col < side)
    nb = (row * side + col)[on]
    src = src[on]
    t_ct, pulse_ct = t_s[src], pulse[src]
    # the neighbour's last own avalanche of that pulse at or before t_ct (one sorted search
    # on (pixel, pulse) + t / T, the time as a fraction of the gate below the key's unit)
    n_p = int(pulse.max()) + 1
    scale = 0.5 / det.gate_s
    key = (pixel.astype(np.int64) * n_p + pulse) + t_s * scale
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    want = (nb * n_p + pulse_ct).astype(np.float64)
    j = np.searchsorted(key_s, want + t_ct * scale, side="right") - 1
    same = (j >= 0) & (np.floor(key_s[np.maximum(j, 0)]) == want)
    dead = np.zeros(len(nb), dtype=bool)
    dead[same] = t_ct[same] - t_s[order][j[same]] < det.dead_time_s
    keep = ~dead
    return (
        np.concatenate([pixel, nb[keep].astype(np.int32)]),
        np.concatenate([pulse, pulse_ct[keep]]),
        np.concatenate([t_s, t_ct[keep]]),
        np.concatenate([kind, np.full(int(keep.sum()), EVENT_CROSSTALK, np.int8)]),
    )


def _timed(g, pixel, pulse, t_s, kind, det: Detector) -> Events:
    """Jitter and the TDC bin of every avalanche; those timed outside the gate are dropped."""
    t = t_s + det.jitter_s * g.standard_normal(len(t_s))
    b = np.floor(t / det.bin_s)
    keep = (b >= 0) & (b < det.n_bins)
    pixel, pulse, b, kind = pixel[keep], pulse[keep], b[keep].astype(np.int64), kind[keep]
    n_pulses = int(pulse.max()) + 1 if len(pulse) else 1
    if (int(pixel.max()) + 1 if len(pixel) else 1) * det.n_bins * n_pulses * 4 < 2**62:
        # one packed key (pixel, bin, pulse, kind) sorted: a fraction of a lexsort's time
        key = ((pixel.astype(np.int64) * det.n_bins + b) * n_pulses + pulse) * 4 + kind
        key.sort()
        key, kind = np.divmod(key, 4)
        key, pulse = np.divmod(key, n_pulses)
        pixel, b = np.divmod(key, det.n_bins)
        return Events(
            pixel=pixel.astype(np.int32),
            pulse=pulse.astype(np.int32),
            bin=b.astype(np.int32),
            kind=kind.astype(np.int8),
        )
    order = np.lexsort((pulse, b, pixel))
    return Events(
        pixel=pixel[order], pulse=pulse[order], bin=b[order].astype(np.int32), kind=kind[order]
    )
