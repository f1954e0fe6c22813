"""The whole gate of the whole array (docs/physics.md#mc-time-of-flight): every pixel's noisy
current over the range gate, in chunks of bounded memory on worker threads, through the
discriminator; stops sorted into detections and false alarms, timed with the quantisation of
Eq. 26."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from .... import parallel
from ....constants import C
from ....pulse import PulseShape
from ..apd import ReceiverModel
from ..detection import Outliers
from .chunk import GateSetup
from .chunk import gate_chunk as _gate_chunk  # by this name: a test counts its calls
from .currents import BandLimit, band_limit
from .discriminator import (
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

    The steps: the echoes checked and indexed (:func:`lit_echoes`), the samples to simulate
    (:func:`simulated_span`), the :class:`.chunk.GateSetup` every chunk reads, the chunks
    (:func:`chunk_jobs`) run on worker threads (:func:`run_chunks`), their stops collected
    (:func:`collected`).

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
    echoes = lit_echoes(pixel, arrivals_s, weights_per_j, n_pixels_total, shape.tau_s)
    band = band_limit(dt_s, receiver.bandwidth_hz)
    t_lo, n_samples = simulated_span(echoes, gate_center_m, gate_m, dt_s, band)
    setup = GateSetup(
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
        t_ref_s=reference_stop_s(shape, band, t_d_s, cfd_fraction),
        raw_end_s=raw_end_s(shape),
        tau_s=shape.tau_s,
        noise=noise,
        continuous=arming == "continuous",
        lit_of_pixel=echoes.lit_of_pixel,
        arrivals=echoes.arrivals,
        weights=echoes.weights,
        window_lo=echoes.window_lo,
        window_hi=echoes.window_hi,
        noise_scale=_noise_scale(receiver, background_a, n_pixels_total),
        per_pixel_threshold=bool(per_pixel_threshold),
        photon=photon,
        gate_m=(max(0.0, gate_center_m - 0.5 * gate_m), gate_center_m + 0.5 * gate_m),
        key=int(rng.integers(1 << 63)),  # drawn before the chunks' streams are spawned
    )
    jobs = chunk_jobs(rng, n_pixels_total, n_samples + 2 * band.half_width, max_bytes)
    t_setup = time.perf_counter() - t_start
    parts, (t_wave, t_disc) = run_chunks(setup, jobs, n_pixels_total, n_threads)
    t_collect = time.perf_counter()
    result = collected(parts, echoes.pixel, setup, n_pixels_total)
    timings = {
        "setup": t_setup,
        "waveforms_thread_s": t_wave,
        "discriminator_thread_s": t_disc,
        "collect": time.perf_counter() - t_collect,
        "total": time.perf_counter() - t_start,
    }
    return replace(result, timings_s=timings)


class LitEchoes(NamedTuple):
    """The lit pixels' echoes as the gate reads them.

    pixel : (n,) int64 -- flat index of each echo pixel
    arrivals, weights : (n, K) float64 -- two-way delays [s] and weights [1/J] (0: no element)
    lit_of_pixel : (n_total,) int64 -- each pixel's row in the echo arrays, -1 if unlit
    window_lo, window_hi : (n,) float64 -- each pixel's detection window [s]: from one pulse
        width tau before its first element to two after its last
    """

    pixel: np.ndarray
    arrivals: np.ndarray
    weights: np.ndarray
    lit_of_pixel: np.ndarray
    window_lo: np.ndarray
    window_hi: np.ndarray


def lit_echoes(pixel, arrivals_s, weights_per_j, n_pixels_total: int, tau_s: float) -> LitEchoes:
    """The echo inputs checked (shapes, pixel indices in [0, n_pixels_total)) and indexed, with
    each lit pixel's detection window [first arrival - tau, last arrival + 2 tau] [s]."""
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
    lit_of_pixel = np.full(n_pixels_total, -1, dtype=np.int64)
    lit_of_pixel[pixel] = np.arange(len(pixel))
    has = weights > 0
    window_lo = np.where(has, arrivals, np.inf).min(axis=1, initial=np.inf) - tau_s
    window_hi = np.where(has, arrivals, -np.inf).max(axis=1, initial=-np.inf) + 2.0 * tau_s
    return LitEchoes(pixel, arrivals, weights, lit_of_pixel, window_lo, window_hi)


def simulated_span(
    echoes: LitEchoes, gate_center_m: float, gate_m: float, dt_s: float, band: BandLimit
) -> tuple[float, int]:
    """Time of the first simulated sample [s] and the sample count: the range gate's samples
    (:func:`gate_samples`) and, before them, the lead an echo near its opening needs
    (:func:`lead_samples`)."""
    t_lo, n_samples = gate_samples(gate_center_m, gate_m, dt_s)
    first_arrival_s = np.where(echoes.weights > 0, echoes.arrivals, np.inf).min(initial=np.inf)
    lead = lead_samples(first_arrival_s, t_lo, dt_s, band)
    return t_lo - lead * dt_s, n_samples + lead


def chunk_jobs(
    rng: np.random.Generator, n_pixels_total: int, row_samples: int, max_bytes: int
) -> list[tuple[int, int, np.random.Generator]]:
    """The gate's chunks of pixels, (p0, p1, generator): as many rows of ``row_samples`` padded
    samples as fit ``max_bytes`` per worker thread, each chunk with a child of ``rng``."""
    rows = max(1, int(max_bytes) // (_BYTES_PER_SAMPLE * row_samples))
    bounds = [(p, min(p + rows, n_pixels_total)) for p in range(0, n_pixels_total, rows)]
    children = rng.spawn(len(bounds))
    return [(p0, p1, g) for (p0, p1), g in zip(bounds, children, strict=True)]


def run_chunks(
    setup: GateSetup, jobs: list, n_pixels_total: int, n_threads: int | None
) -> tuple[list[dict[str, Any]], tuple[float, float]]:
    """Every chunk through :func:`.chunk.gate_chunk` on worker threads, in order: their stops
    and the thread-seconds of the waveforms and of the discriminator [s]. A frame that runs past
    ``PROGRESS_DELAY_S`` shows its progress on a terminal."""
    parts = []
    t_wave = t_disc = 0.0
    work: Callable[[Any], Any] = lambda job: _gate_chunk(setup, *job)  # noqa: E731
    from tqdm import tqdm  # noqa: PLC0415  (only a long frame shows it)

    # 512 x 512 px take about a minute on two cores; piped or captured output stays silent
    # (disable=None)
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
    return parts, (t_wave, t_disc)


def collected(
    parts: list[dict[str, Any]], pixel: np.ndarray, setup: GateSetup, n_pixels_total: int
) -> McResult:
    """The chunks' stops as one McResult (without timings): per lit pixel its stop count and its
    first detection stop's range; every other stop a false alarm."""
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
    dt_s = setup.band.dt_s
    return McResult(
        pixel=pixel,
        detected=detected,
        range_m=range_m,
        n_stops=n_stops,
        false_alarm_pixel=cat["pixel"][fa],
        false_alarm_range_m=cat["range_m"][fa],
        n_pixels_total=int(n_pixels_total),
        gate_s=(setup.t_lo, setup.t_lo + (setup.n_samples - 1) * dt_s),
        reference_stop_s=setup.t_ref_s,
        threshold_a=setup.threshold_a,
        dt_s=float(dt_s),
        n_unfired=sum(p["unfired"] for p in parts),
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
