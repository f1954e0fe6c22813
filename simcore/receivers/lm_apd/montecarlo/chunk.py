"""One chunk of the gate's pixels (:mod:`.gate` cuts the array into chunks of bounded memory and
runs them on worker threads): the frame's setup every chunk reads, the pulses written into the
chunk's input, its noise and filter, and the discriminator's stops of its pixels."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ....constants import C
from ....echo.features import compiled_kernel
from ....pulse import PulseShape
from ..apd import ReceiverModel
from .currents import BandLimit, noisy_band_limited
from .discriminator import (
    ARMING_MARGIN,
    batches,
    discriminate,
)


@dataclass(frozen=True)
class GateSetup:
    shape: PulseShape
    band: BandLimit
    receiver: ReceiverModel
    energy_j: float
    t_lo: float  # time of gate sample 0 [s]
    n_samples: int
    threshold_a: float
    t_d_s: float
    cfd_fraction: float
    holdoff_s: float
    first_stop: bool
    max_stops: int | None
    resolution_s: float
    t_ref_s: float
    raw_end_s: float
    tau_s: float
    noise: bool
    continuous: bool
    lit_of_pixel: np.ndarray  # (n_total,) index into the echo arrays, -1 if unlit
    arrivals: np.ndarray  # (n_lit, K)
    weights: np.ndarray  # (n_lit, K), per joule
    window_lo: np.ndarray  # (n_lit,) detection window [s]
    window_hi: np.ndarray
    noise_scale: np.ndarray | None = None  # (n_total,) sigma_n,pixel / sigma_n (background)
    per_pixel_threshold: bool = False  # arm at TNR sigma_n,pixel instead of TNR sigma_n
    photon: Any = None  # photon.PhotonNoise, or None for Gaussian shot and dark noise
    # the range gate [m]: the TDC records stops from the time a surface at its near edge gives
    # (its opening plus t_ref) and counts no time before its opening (Eq. 26's quantisation)
    gate_m: tuple[float, float] = (0.0, math.inf)
    key: int = 0  # the flash's 64-bit noise key: pixel p draws its white noise from stream p


def signal_into(x: np.ndarray, setup: GateSetup, lit: np.ndarray, local_rows: np.ndarray):
    """Write i_s = R_resp E sum_k w_k P0(t - t_k) (Eqs. 7, 29, 30) of the lit rows into the
    padded input x, on each pixel's own window (delays exact, never snapped)."""
    pulses_into(
        x, setup, lit, local_rows, setup.shape.raw, 0.0, setup.raw_end_s, setup.band.half_width
    )


def filtered_signal_into(y: np.ndarray, setup: GateSetup, lit: np.ndarray, local_rows: np.ndarray):
    """Add the band-limited signal R_resp E sum_k w_k (h_B * P0)(t - t_k) of the lit rows to y
    at its sample times, in closed form (the pulse table): exact wherever the samples fall. The
    sampled convolution of the sampled pulse errs at the pulse's onset kink by an amount that
    depends on the grid phase (1.3 mm rms in range at the default step)."""
    shape = setup.shape  # the table's whole span: the pulse is below 1e-10 of its peak outside
    t_end_s = shape.t0_s + shape.step_s * (len(shape.filtered) - 1)
    pulses_into(y, setup, lit, local_rows, shape.filtered, shape.t0_s, t_end_s, 0)


def pulses_into(out, setup, lit, local_rows, table, t_begin_s, t_end_s, col_offset):
    """out[row, c] += R_resp E sum_k w_k p(t_c - t_k), t_c = t_lo + (c - col_offset) dt, p the
    pulse table ``table`` (``shape.raw`` or ``shape.filtered``), over each lit row's window
    [first arrival + t_begin_s, last arrival + t_end_s]: by the compiled echo kernel where it is
    available (serial: this runs on the gate's own threads), else in numpy batches."""
    any_weight = (setup.weights[lit] > 0).any(axis=1)
    lit, local_rows = lit[any_weight], local_rows[any_weight]
    if len(lit) == 0:
        return
    dt, m = setup.band.dt_s, col_offset
    width = out.shape[1]
    arr, w = setup.arrivals[lit], setup.weights[lit]
    has = w > 0
    t_first = np.where(has, arr, np.inf).min(axis=1)
    t_last = np.where(has, arr, -np.inf).max(axis=1)
    arr = np.where(has, arr, t_first[:, None])
    scale = setup.receiver.responsivity_a_w * setup.energy_j
    c0 = np.floor((t_first + t_begin_s - setup.t_lo) / dt).astype(np.int64) + m
    c0 = np.clip(c0, 0, width)
    t_end = t_last + t_end_s - setup.t_lo
    c1 = np.clip(np.ceil(t_end / dt).astype(np.int64) + m + 1, 0, width)
    kernel = compiled_kernel()
    if kernel is not None:
        kernel.sample_echoes(
            out, local_rows, c0, np.full(len(lit), setup.t_lo), c0 - m, c1 - m, dt, arr, w,
            table, setup.shape.slope_of(table), setup.shape, scale, parallel=False,
        )  # fmt: skip
        return
    n_cols = c1 - c0
    k = arr.shape[1]
    for sel in batches(np.maximum(n_cols, 1) * k, 1 << 21):
        wmax = int(n_cols[sel].max())
        if wmax <= 0:
            continue
        cols = c0[sel, None] + np.arange(wmax)[None, :]
        t = setup.t_lo + (cols - m) * dt
        p = np.einsum(
            "pwk,pk->pw", setup.shape.lookup(table, t[:, :, None] - arr[sel, None, :]), w[sel]
        )
        inside = cols < c1[sel, None]
        r = np.broadcast_to(local_rows[sel, None], cols.shape)
        out[r[inside], cols[inside]] += (scale * p[inside]).astype(out.dtype)


THREAD_BUFFERS = threading.local()


def buffers(n: int, n_samples: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The chunk's padded input x (n, n_samples + 2 m), zeroed, and a buffer for y (n,
    n_samples), both float32: kept by the calling thread from chunk to chunk (fresh arrays of
    tens of MB a chunk cost their page faults again each time)."""
    held = getattr(THREAD_BUFFERS, "arrays", None)
    if held is None or held[0].shape != (n, n_samples + 2 * m):
        held = (np.empty((n, n_samples + 2 * m), np.float32), np.empty((n, n_samples), np.float32))
        THREAD_BUFFERS.arrays = held
    held[0].fill(0.0)
    return held


def gate_chunk(setup: GateSetup, p0: int, p1: int, rng: np.random.Generator):
    """Simulate pixels p0..p1-1 over the whole gate; return their stops and the part timings."""
    t0 = time.perf_counter()
    n = p1 - p0
    m = setup.band.half_width
    x, y_buffer = buffers(n, setup.n_samples, m)
    lit = setup.lit_of_pixel[p0:p1]
    local = np.flatnonzero(lit >= 0)
    signal_into(x, setup, lit[local], local)
    scale = None if setup.noise_scale is None else setup.noise_scale[p0:p1]
    # the continuous comparator reads x only in rows with a sample near V_T (ARMING_MARGIN
    # below it, in the row's units before the per-pixel scaling; 1 % lower for the rounding):
    # unlit rows whose noise stays lower need no white noise written into x
    level = np.full(n, np.inf)
    if setup.continuous:
        level[:] = 0.99 * (1.0 - ARMING_MARGIN) * setup.threshold_a
        if scale is not None and setup.per_pixel_threshold:
            level *= scale
    level[local] = -np.inf
    written = np.ones(n, dtype=bool)  # the rows that may come near V_T (the kernel says which)
    y = noisy_band_limited(
        rng,
        x,
        setup.receiver,
        setup.band,
        setup.noise,
        add_signal=False,
        row_scale=scale,
        photon=setup.photon,
        stream0=p0,
        key=setup.key,
        white_level=level,
        signal_rows=lit >= 0,
        out=y_buffer,
        rows_written=written,
    )
    filtered_signal_into(y, setup, lit[local], local)
    if scale is not None and setup.per_pixel_threshold:
        # arming at TNR sigma_n,pixel is arming the row over sigma_n,pixel / sigma_n at TNR
        # sigma_n; the CFD's zero crossing does not change with the row's scale
        y /= scale.astype(y.dtype)[:, None]
        x /= scale.astype(x.dtype)[:, None]
    t1 = time.perf_counter()
    stops = discriminate(
        y,
        setup.band.dt_s,
        setup.threshold_a,
        setup.t_d_s,
        setup.cfd_fraction,
        holdoff_s=setup.holdoff_s,
        first_stop=setup.first_stop,
        max_stops=setup.max_stops,
        t0_s=setup.t_lo,
        x_padded_a=x if setup.continuous else None,
        band=setup.band if setup.continuous else None,
        t_open_s=2.0 * setup.gate_m[0] / C + setup.t_ref_s,
        candidate_rows=np.flatnonzero(written) if setup.continuous else None,
    )
    del x, y
    # Eq. 26: e1 per stop, e2 per pixel (each pixel's TDC registers the start once)
    half = 0.5 * setup.resolution_s
    e2 = rng.uniform(-half, half, size=n)
    e1 = rng.uniform(-half, half, size=len(stops.row))
    tof = (stops.t_s + e1) - (setup.t_ref_s + e2[stops.row])
    pixel = stops.row + p0
    lit_idx = setup.lit_of_pixel[pixel]
    is_lit = lit_idx >= 0
    in_window = np.zeros(len(pixel), dtype=bool)
    li = lit_idx[is_lit]
    t_lit = stops.t_s[is_lit]
    in_window[is_lit] = (t_lit >= setup.window_lo[li]) & (t_lit <= setup.window_hi[li])
    out = {
        "pixel": pixel,
        "lit": lit_idx,
        "t_s": stops.t_s,
        "range_m": np.clip(0.5 * C * tof, *setup.gate_m),
        "detection": is_lit & in_window,
        "unfired": int(np.count_nonzero(~stops.fired)),
    }
    return out, (t1 - t0, time.perf_counter() - t1)
