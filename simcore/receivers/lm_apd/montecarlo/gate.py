"""The whole gate of the whole array (docs/physics.md#mc-time-of-flight): every pixel's noisy
current over the range gate, in chunks of bounded memory on worker threads, through the
discriminator; stops sorted into detections and false alarms, timed with the quantisation of
Eq. 26."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .... import parallel
from ....constants import C
from ....echo.features import compiled_kernel
from ....pulse import PulseShape
from ..apd import ReceiverModel
from ..detection import Outliers
from .currents import BandLimit, band_limit, noisy_band_limited
from .discriminator import (
    ARMING_MARGIN,
    batches,
    discriminate,
    pulse_fwhm_s,
    raw_end_s,
    reference_stop_s,
)

_DEFAULT_MAX_BYTES = 64 << 20  # working set per worker thread [bytes]
_BYTES_PER_SAMPLE = 36  # float32 input, output, FFT buffers and masks per sample of a chunk
PROGRESS_DELAY_S = 2.0  # a frame running longer shows a progress bar on a terminal [s]


@dataclass(frozen=True)
class McResult:
    """One flash through the waveform Monte Carlo model.

    pixel : (n,) int64 -- flat index of each echo pixel (as EchoStage.pixel)
    detected : (n,) bool -- a stop fell in the pixel's detection window
    range_m : (n,) float64 -- range of the first detection stop [m], NaN if none
    n_stops : (n,) int64 -- all stops of the pixel's gate (detections and false alarms)
    false_alarm_pixel : (f,) int64 -- flat pixel index of every false-alarm stop (all pixels)
    false_alarm_range_m : (f,) float64 -- its range [m]
    n_pixels_total : int -- pixels simulated (the whole array)
    gate_s : (float, float) -- first and last sample time of the gate [s]
    reference_stop_s : float -- t*_ref [s]
    threshold_a : float -- V_T = TNR sigma_n [A]
    dt_s : float
    n_unfired : int -- stops at t_a because s(t) had no upward zero crossing in the window
    timings_s : dict -- wall time of the run and thread-seconds per part [s]
    """

    pixel: np.ndarray
    detected: np.ndarray
    range_m: np.ndarray
    n_stops: np.ndarray
    false_alarm_pixel: np.ndarray
    false_alarm_range_m: np.ndarray
    n_pixels_total: int
    gate_s: tuple[float, float]
    reference_stop_s: float
    threshold_a: float
    dt_s: float
    n_unfired: int
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def outliers(self) -> Outliers:
        """The false alarms as detection.Outliers (pixel, range), for the point cloud."""
        return Outliers(pixel=self.false_alarm_pixel, range_m=self.false_alarm_range_m)

    @property
    def n_false_alarms(self) -> int:
        return len(self.false_alarm_pixel)


@dataclass(frozen=True)
class _GateSetup:
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


def _signal_into(x: np.ndarray, setup: _GateSetup, lit: np.ndarray, local_rows: np.ndarray):
    """Write i_s = R_resp E sum_k w_k P0(t - t_k) (Eqs. 7, 29, 30) of the lit rows into the
    padded input x, on each pixel's own window (delays exact, never snapped)."""
    _pulses_into(
        x, setup, lit, local_rows, setup.shape.raw, 0.0, setup.raw_end_s, setup.band.half_width
    )


def _filtered_signal_into(
    y: np.ndarray, setup: _GateSetup, lit: np.ndarray, local_rows: np.ndarray
):
    """Add the band-limited signal R_resp E sum_k w_k (h_B * P0)(t - t_k) of the lit rows to y
    at its sample times, in closed form (the pulse table): exact wherever the samples fall. The
    sampled convolution of the sampled pulse errs at the pulse's onset kink by an amount that
    depends on the grid phase (1.3 mm rms in range at the default step)."""
    shape = setup.shape  # the table's whole span: the pulse is below 1e-10 of its peak outside
    t_end_s = shape.t0_s + shape.step_s * (len(shape.filtered) - 1)
    _pulses_into(y, setup, lit, local_rows, shape.filtered, shape.t0_s, t_end_s, 0)


def _pulses_into(out, setup, lit, local_rows, table, t_begin_s, t_end_s, col_offset):
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


_THREAD_BUFFERS = threading.local()


def _buffers(n: int, n_samples: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The chunk's padded input x (n, n_samples + 2 m), zeroed, and a buffer for y (n,
    n_samples), both float32: kept by the calling thread from chunk to chunk (fresh arrays of
    tens of MB a chunk cost their page faults again each time)."""
    held = getattr(_THREAD_BUFFERS, "arrays", None)
    if held is None or held[0].shape != (n, n_samples + 2 * m):
        held = (np.empty((n, n_samples + 2 * m), np.float32), np.empty((n, n_samples), np.float32))
        _THREAD_BUFFERS.arrays = held
    held[0].fill(0.0)
    return held


def _gate_chunk(setup: _GateSetup, p0: int, p1: int, rng: np.random.Generator):
    """Simulate pixels p0..p1-1 over the whole gate; return their stops and the part timings."""
    t0 = time.perf_counter()
    n = p1 - p0
    m = setup.band.half_width
    x, y_buffer = _buffers(n, setup.n_samples, m)
    lit = setup.lit_of_pixel[p0:p1]
    local = np.flatnonzero(lit >= 0)
    _signal_into(x, setup, lit[local], local)
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
    _filtered_signal_into(y, setup, lit[local], local)
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


def gate_samples(gate_center_m: float, gate_m: float, dt_s: float) -> tuple[float, int]:
    """Time of the first gate sample [s] and the sample count of the range gate
    [R_st - R_gate / 2, R_st + R_gate / 2] (clipped at 0)."""
    lo = max(0.0, gate_center_m - 0.5 * gate_m)
    hi = gate_center_m + 0.5 * gate_m
    t_lo, t_hi = 2.0 * lo / C, 2.0 * hi / C
    return t_lo, int(math.floor((t_hi - t_lo) / dt_s)) + 1


def lead_samples(first_arrival_s: float, t_lo_s: float, dt_s: float, band: BandLimit) -> int:
    """Samples to simulate before the gate's opening so that an echo arriving near it is seen
    rising: the band limit's (zero-phase) response starts ``band.half_width`` samples before
    the optical pulse, and a comparator needs an upward crossing. 0 when the first echo
    arrives later than that (the gate's own samples suffice; stops before the opening are not
    recorded either way)."""
    need = (band.half_width + 8) * dt_s - (first_arrival_s - t_lo_s)
    return max(0, math.ceil(need / dt_s)) if math.isfinite(need) else 0


def montecarlo_gate(
    rng: np.random.Generator,
    *,
    pixel,
    arrivals_s,
    weights_per_j,
    shape: PulseShape,
    dt_s: float,
    receiver: ReceiverModel,
    pulse_energy_j: float,
    n_pixels_total: int,
    gate_center_m: float,
    gate_m: float,
    tnr: float,
    t_d_s: float,
    cfd_fraction: float,
    resolution_s: float,
    first_stop: bool = False,
    max_stops: int | None = None,
    holdoff_s: float | None = None,
    noise: bool = True,
    arming: str = "continuous",
    max_bytes: int = _DEFAULT_MAX_BYTES,
    n_threads: int | None = None,
    background_a=None,
    per_pixel_threshold: bool = False,
    photon: Any = None,
) -> McResult:
    """Waveform Monte Carlo of one flash over the whole gate of every pixel
    (docs/physics.md#monte-carlo).

    Parameters
    ----------
    rng : numpy.random.Generator -- the flash's noise key is drawn from it (each pixel's white
        noise from its own stream under it), then children are spawned, one per chunk of pixels
    pixel : (n,) int -- flat index of each echo pixel, in [0, n_pixels_total)
    arrivals_s, weights_per_j : (n, K) float -- Eq. 29-30 two-way delays [s] and weights (per
        joule of pulse energy: P_r(t) = E sum_k w_k P0(t - t_k)); weight 0 = no element
    shape : PulseShape -- the emitted pulse (Eq. 1)
    dt_s : float -- time step [s]
    receiver : ReceiverModel -- gain, noise, responsivity (Eqs. 7-18)
    pulse_energy_j : float -- E [J]
    n_pixels_total : int -- pixels of the array; the unlit ones see noise only
    gate_center_m, gate_m : float -- range gate R_st and R_gate [m]
    tnr : float -- V_T = tnr sigma_n
    t_d_s, cfd_fraction : float -- CFD delay [s] and fraction (Eq. 19)
    resolution_s : float -- timing resolution T_t [s] (Eq. 26)
    first_stop : bool -- keep only each pixel's first stop (``max_stops = 1``)
    max_stops : int, optional -- each pixel records at most this many stops (None: no limit); a
        noise stop before the echo then masks it (docs/physics.md#limited-stops)
    holdoff_s : float, optional -- re-arm hold-off; default one FWHM of the emitted pulse
    noise : bool -- False: noise-free waveforms through the same discriminator
    arming : "continuous" (an analog comparator) or "sampled" (crossings between samples only)
    max_bytes : int -- working set per worker thread [bytes]
    n_threads : int, optional -- worker threads (the noise kernel, numpy and scipy.fft release
        the GIL); None: the frame's threads (:func:`simcore.parallel.threads`)
    background_a : (n_pixels_total,) float, optional -- each pixel's background current at the
        APD output, R_resp P_bg [A]: its shot noise joins the pixel's white noise
        (docs/physics.md#background-noise); its DC level is removed (AC coupling)
    per_pixel_threshold : bool -- arm each pixel at TNR x its own signal-free noise (with
        ``background_a``); False: TNR x a dark pixel's sigma_n
    photon : photon.PhotonNoise, optional -- Poisson photoelectrons with McIntyre gains for
        the shot and bulk dark noise (``fidelity.noise_model = "photon"``); None: Gaussian

    Returns
    -------
    McResult
    """
    if arming not in ("continuous", "sampled"):
        raise ValueError(f"arming must be 'continuous' or 'sampled', got {arming!r}")
    t_start = time.perf_counter()
    pixel = np.asarray(pixel, dtype=np.int64).reshape(-1)
    arrivals = np.atleast_2d(np.asarray(arrivals_s, dtype=np.float64))
    weights = np.atleast_2d(np.asarray(weights_per_j, dtype=np.float64))
    if arrivals.shape != weights.shape or arrivals.shape[0] != len(pixel):
        raise ValueError(
            f"arrivals_s {arrivals.shape} and weights_per_j {weights.shape} must be (n, K) "
            f"with n = len(pixel) = {len(pixel)}"
        )
    if len(pixel) and (pixel.min() < 0 or pixel.max() >= n_pixels_total):
        raise ValueError(f"pixel indices must lie in [0, {n_pixels_total})")
    band = band_limit(dt_s, receiver.bandwidth_hz)
    t_ref = reference_stop_s(shape, band, t_d_s, cfd_fraction)
    t_lo, n_samples = gate_samples(gate_center_m, gate_m, dt_s)
    lit_of_pixel = np.full(n_pixels_total, -1, dtype=np.int64)
    lit_of_pixel[pixel] = np.arange(len(pixel))
    has = weights > 0
    lead = lead_samples(np.where(has, arrivals, np.inf).min(initial=np.inf), t_lo, dt_s, band)
    t_lo, n_samples = t_lo - lead * dt_s, n_samples + lead
    tau = shape.tau_s
    window_lo = np.where(has, arrivals, np.inf).min(axis=1, initial=np.inf) - tau
    window_hi = np.where(has, arrivals, -np.inf).max(axis=1, initial=-np.inf) + 2.0 * tau
    setup = _GateSetup(
        shape=shape,
        band=band,
        receiver=receiver,
        energy_j=float(pulse_energy_j),
        t_lo=t_lo,
        n_samples=n_samples,
        threshold_a=float(tnr) * receiver.sigma_n_a,
        t_d_s=float(t_d_s),
        cfd_fraction=float(cfd_fraction),
        holdoff_s=pulse_fwhm_s(shape) if holdoff_s is None else float(holdoff_s),
        first_stop=first_stop,
        max_stops=None if max_stops is None else int(max_stops),
        resolution_s=float(resolution_s),
        t_ref_s=t_ref,
        raw_end_s=raw_end_s(shape),
        tau_s=tau,
        noise=noise,
        continuous=arming == "continuous",
        lit_of_pixel=lit_of_pixel,
        arrivals=arrivals,
        weights=weights,
        window_lo=window_lo,
        window_hi=window_hi,
        noise_scale=_noise_scale(receiver, background_a, n_pixels_total),
        per_pixel_threshold=bool(per_pixel_threshold),
        photon=photon,
        gate_m=(max(0.0, gate_center_m - 0.5 * gate_m), gate_center_m + 0.5 * gate_m),
        key=int(rng.integers(1 << 63)),
    )
    rows = max(1, int(max_bytes) // (_BYTES_PER_SAMPLE * (n_samples + 2 * band.half_width)))
    bounds = [(p, min(p + rows, n_pixels_total)) for p in range(0, n_pixels_total, rows)]
    children = rng.spawn(len(bounds))
    jobs = [(p0, p1, g) for (p0, p1), g in zip(bounds, children, strict=True)]
    t_setup = time.perf_counter() - t_start

    parts = []
    t_wave = t_disc = 0.0
    work: Callable[[Any], Any] = lambda job: _gate_chunk(setup, *job)  # noqa: E731
    from tqdm import tqdm  # noqa: PLC0415  (only a long frame shows it)

    # a frame that runs past PROGRESS_DELAY_S shows its progress on a terminal (512 x 512 px
    # take about a minute on two cores); piped or captured output stays silent (disable=None)
    bar = tqdm(
        total=n_pixels_total,
        desc="Monte Carlo",
        unit="px",
        unit_scale=True,
        file=sys.stderr,
        disable=None,
        delay=PROGRESS_DELAY_S,
        leave=False,
    )
    n_threads = parallel.threads() if n_threads is None else int(n_threads)
    with bar, ThreadPoolExecutor(max_workers=max(1, min(n_threads, len(jobs)))) as pool:
        for (p0, p1, _), (out, (tw, td)) in zip(jobs, pool.map(work, jobs), strict=True):
            parts.append(out)
            t_wave += tw
            t_disc += td
            bar.update(p1 - p0)

    t_collect = time.perf_counter()
    cat = {k: np.concatenate([p[k] for p in parts]) for k in ("pixel", "lit", "t_s", "range_m")}
    detection = np.concatenate([p["detection"] for p in parts])
    n_lit = len(pixel)
    lit = cat["lit"]
    n_stops = np.bincount(lit[lit >= 0], minlength=n_lit).astype(np.int64)
    det_lit, det_t, det_r = lit[detection], cat["t_s"][detection], cat["range_m"][detection]
    order = np.lexsort((det_t, det_lit))
    first_lit, first_at = np.unique(det_lit[order], return_index=True)
    detected = np.zeros(n_lit, dtype=bool)
    detected[first_lit] = True
    range_m = np.full(n_lit, np.nan)
    range_m[first_lit] = det_r[order][first_at]
    fa = ~detection
    timings = {
        "setup": t_setup,
        "waveforms_thread_s": t_wave,
        "discriminator_thread_s": t_disc,
        "collect": time.perf_counter() - t_collect,
        "total": time.perf_counter() - t_start,
    }
    return McResult(
        pixel=pixel,
        detected=detected,
        range_m=range_m,
        n_stops=n_stops,
        false_alarm_pixel=cat["pixel"][fa],
        false_alarm_range_m=cat["range_m"][fa],
        n_pixels_total=int(n_pixels_total),
        gate_s=(t_lo, t_lo + (n_samples - 1) * dt_s),
        reference_stop_s=t_ref,
        threshold_a=setup.threshold_a,
        dt_s=float(dt_s),
        n_unfired=sum(p["unfired"] for p in parts),
        timings_s=timings,
    )


def _noise_scale(receiver: ReceiverModel, background_a, n_pixels_total: int):
    """(n_total,) each pixel's signal-free noise over sigma_n, sqrt(1 + F_chain 2 q M F i_bg B
    / sigma_n^2), or None without background."""
    if background_a is None:
        return None
    i_bg = np.maximum(np.asarray(background_a, dtype=np.float64).reshape(-1), 0.0)
    if i_bg.shape != (n_pixels_total,):
        raise ValueError(f"background_a must be ({n_pixels_total},), got {i_bg.shape}")
    return receiver.sigma_peak_a(i_bg) / receiver.sigma_n_a


def montecarlo_detection(
    rng: np.random.Generator,
    echo_stage,
    receiver_model: ReceiverModel,
    scene,
    first_stop: bool = False,
    max_stops: int | None = None,
    **options,
) -> McResult:
    """The Monte Carlo detection stage for the pipeline: one flash of ``scene``.

    Parameters
    ----------
    rng : numpy.random.Generator
    echo_stage : pipeline.EchoStage -- uses pixel, arrivals_s, weights, shape, dt_s, cfd_delay_s
    receiver_model : ReceiverModel
    scene : Scene -- detector.pixels, laser.pulse_energy_j, timing (tnr, resolution_s,
        cfd_fraction, range_gate_m), gate_center_m; fidelity.noise_model = "photon" draws the
        shot and bulk dark noise photon by photon (detector.excess_noise_k, dark_bulk_a)
    first_stop : bool -- keep only each pixel's first stop (default: multi-stop)
    max_stops : int, optional -- at most this many stops per pixel (the pipeline passes
        ``timing.max_stops``; None: no limit)
    **options -- passed to :func:`montecarlo_gate` (holdoff_s, noise, arming, max_bytes,
        n_threads)

    Returns
    -------
    McResult -- per echo pixel (in echo_stage.pixel order): detected, range_m, n_stops; the
    false alarms of every pixel of the array; timings.
    """
    t = scene.timing
    if scene.fidelity.noise_model == "photon":
        from .photon import PhotonNoise  # noqa: PLC0415

        options.setdefault(
            "photon", PhotonNoise(scene.detector.excess_noise_k, scene.detector.dark_bulk_a)
        )
    return montecarlo_gate(
        rng,
        pixel=echo_stage.pixel,
        arrivals_s=echo_stage.arrivals_s,
        weights_per_j=echo_stage.weights,
        shape=echo_stage.shape,
        dt_s=echo_stage.dt_s,
        receiver=receiver_model,
        pulse_energy_j=scene.laser.pulse_energy_j,
        n_pixels_total=scene.detector.pixels**2,
        gate_center_m=scene.gate_center_m,
        gate_m=t.range_gate_m,
        tnr=t.tnr,
        t_d_s=echo_stage.cfd_delay_s,
        cfd_fraction=t.cfd_fraction,
        resolution_s=t.resolution_s,
        first_stop=first_stop,
        max_stops=max_stops,
        **options,
    )
