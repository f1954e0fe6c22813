"""A test-only receiver: ideal and noiseless. Not shipped: it proves that a receiver is one module
and one registration (tests/core/test_receivers.py, tests/core/test_cache_keys.py register it)."""

from __future__ import annotations

import numpy as np

from simcore import receivers
from simcore.receivers.lm_apd import timing
from simcore.receivers.lm_apd.detection import Outliers

KIND = "ideal"


def respond(scene, echo, background) -> receivers.Response:
    """The band-limited peak power; the 'SNR' is its margin over the fixed threshold (an ideal
    receiver ignores the background light)."""
    peak_w = echo.features.peak_w_per_j * scene.laser.pulse_energy_j
    return receivers.Response(
        peak_power_w=peak_w, snr=peak_w / THRESHOLD_W, noise_figures={"threshold_w": THRESHOLD_W}
    )


def detect(scene, echo, response: receivers.Response) -> receivers.Detection:
    """Every echo above the threshold, at its noise-free half-maximum range, inside the gate."""
    t = scene.timing
    r_true_m = timing.range_from_half_max_m(echo.features.t_half_s, echo.shape.t_half_s)
    lo = max(0.0, scene.gate_center_m - t.range_gate_m / 2.0)
    hi = scene.gate_center_m + t.range_gate_m / 2.0
    detected = (response.peak_power_w >= THRESHOLD_W) & (r_true_m >= lo) & (r_true_m <= hi)
    return receivers.Detection(
        p_detect=detected.astype(np.float64),
        detected=detected,
        range_true_m=r_true_m,
        range_sigma_m=np.zeros(len(detected)),
        range_m=np.where(detected, r_true_m, np.nan),
        threshold_w=THRESHOLD_W,
        n_false_per_pixel=0.0,
        outliers=Outliers(pixel=np.zeros(0, np.int64), range_m=np.zeros(0)),
    )


THRESHOLD_W = 1e-9  # [W] at the receiver input
IDEAL = receivers.Receiver(
    kind=KIND,
    doc="ideal, noiseless: every echo above 1 nW, at its true range",
    response_reads=lambda s: (s.laser.pulse_energy_j,),
    respond=respond,
    detection_reads=lambda s: (s.timing.range_gate_m, s.gate_center_m),
    detect=detect,
)
