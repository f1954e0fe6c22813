"""The Geiger-mode receiver stage: every pixel's primary event rate, the echo's photoelectrons
per pulse (the frame's pulses carry ``laser.pulse_energy_j`` less ``gm.attenuation_db``:
photon-starved by default), and the frame itself: ``gm.pulses`` pulses of avalanches of every
pixel (:mod:`.events`: Poisson primaries from the optical echo of Eqs. 1, 29, 30, background and
dark counts; non-paralysable dead time reset per gate, jitter, TDC bins, afterpulsing,
crosstalk), kept as a sparse per-pixel histogram (:mod:`.histogram`); and each lit pixel's
expected histogram's centroid before the thresholds (:mod:`.pileup`), so that a TNR change
re-runs only the detection's cheap half.

The model: docs/physics.md#geiger-mode.
"""

from __future__ import annotations

import numpy as np

from ...echo import EchoStage
from ...scene import Scene
from ...stage import readonly
from . import events as ev
from . import histogram as gh
from .figures import expected_prediction
from .frame import (
    _check_load,
    _detector,
    _gate_s,
    background_power_w,
    frame_pulse_energy_j,
    photon_energy_j,
)
from .records import GmResponse
from .windows import _expected_window_counts

SIGNAL_COUNTS_FLOOR = 1e-6  # expected echo counts a frame below which the count SNR is 0


def respond(scene: Scene, echo: EchoStage, background=None) -> GmResponse:
    """The frame: rates, photoelectrons and the avalanches of ``gm.pulses`` pulses."""
    gm = scene.gm
    energy_j = frame_pulse_energy_j(scene)
    hv_j = photon_energy_j(scene.laser.wavelength_m)
    weights = np.asarray(echo.weights)
    element_pe = gm.pde * energy_j * weights / hv_j
    signal_pe = element_pe.sum(axis=1)
    bg_w = background_power_w(scene, background).reshape(-1)
    rate_hz = gm.pde * bg_w / hv_j + gm.dark_count_rate_hz
    _check_load(scene, signal_pe, rate_hz, echo.pixel)
    t_lo, _ = _gate_s(scene)
    rates = ev.PixelRates(
        rate_hz=rate_hz,
        lit_pixel=np.asarray(echo.pixel),
        element_t_s=np.asarray(echo.arrivals_s) - t_lo,
        element_pe=element_pe,
        scale_s=echo.shape.tau_s / echo.shape.a,
    )
    det = _detector(scene)
    rng = np.random.default_rng([scene.seed, 1917])
    events = ev.simulate_frame(rng, rates, det, gm.pulses)
    hist = gh.histogram(events, det.n_bins, gm.pulses)
    s_counts, b_counts = _expected_window_counts(scene, echo, signal_pe, rate_hz[echo.pixel])
    # a pixel that expects under SIGNAL_COUNTS_FLOOR echo counts a frame (blinded by 1e9 Hz of
    # dark counts or a 1 s dead time in sunlight: 1e-85) has no signal to speak of: SNR 0
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(
            s_counts >= SIGNAL_COUNTS_FLOOR, s_counts / np.sqrt(s_counts + b_counts), 0.0
        )
    expected = expected_prediction(scene, echo, rate_hz, det.n_bins)
    if expected is not None:
        readonly(expected.t_s, expected.sd_s, expected.signal_counts, expected.skew)
    return GmResponse(
        peak_power_w=echo.features.peak_w_per_j * energy_j,
        snr=snr,
        noise_figures={
            "photon_energy_j": hv_j,
            "rate_hz_median": float(np.median(rate_hz)),
            "signal_pe_median": float(np.median(signal_pe)) if len(signal_pe) else 0.0,
            "events": float(len(events)),
        },
        signal_pe=signal_pe,
        rate_hz=rate_hz,
        events=events,
        histogram=hist,
        gate_start_s=t_lo,
        expected=expected,
    )


def _response_reads(s: Scene) -> tuple:
    return (
        s.laser.pulse_energy_j,
        s.gm.attenuation_db,
        s.laser.wavelength_m,
        s.detector.pixels,
        s.timing.range_gate_m,
        s.gate_center_m,
        s.seed,
        s.gm.pde,
        s.gm.dark_count_rate_hz,
        s.gm.dead_time_s,
        s.gm.jitter_s,
        s.gm.bin_s,
        s.gm.pulses,
        s.gm.crosstalk,
        s.gm.afterpulsing,
        # the expected histogram's prediction (``expected``) is the estimator's
        s.gm.coates,
        s.gm.pileup_correction,
    )
