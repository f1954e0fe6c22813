"""The Geiger-mode frame before any avalanche is drawn: the photon budget (the frame's pulse
energy, photoelectrons and primary rates), the gate, the detector's timing, and the frame's
expected load (the avalanches it records), with the refusal of frames too large to simulate.

The model: docs/physics.md#geiger-mode.
"""

from __future__ import annotations

import numpy as np

from ...constants import C, H
from ...echo import EchoStage
from ...plugins.declaration import FrameLoad
from ...scene import Scene, SceneError
from . import events as ev
from .limits import BYTES_PER_EVENT, MAX_EVENTS

MAX_EVENTS_PER_PULSE = 10_000  # expected avalanches of one pixel in one gate at most


ECHO_TAIL_SCALES = 12.0  # the analysis window runs 12 s past the echo (Gamma(2) tail 8e-5)


JITTER_REACH = 4.0  # jitter standard deviations the windows allow either side


def background_power_w(scene: Scene, background=None) -> np.ndarray:
    """(rows, cols) optical background power per pixel at the detector [W]: the background
    stage's ``power_w``, zeros where there is none (night, or no background stage)."""
    n = scene.detector.pixels
    if background is None:
        return np.zeros((n, n))
    power_w = np.asarray(getattr(background, "power_w", background), dtype=np.float64)
    if power_w.shape != (n, n):
        raise ValueError(f"background power_w has shape {power_w.shape}, expected {(n, n)}")
    return power_w


def photon_energy_j(wavelength_m: float) -> float:
    """h nu = h c / lambda [J]."""
    return H * C / wavelength_m


def frame_pulse_energy_j(scene: Scene) -> float:
    """The energy of the Geiger-mode frame's pulses, laser.pulse_energy_j attenuated by
    ``gm.attenuation_db``: E 10^(-A / 10) [J]."""
    return scene.laser.pulse_energy_j * 10.0 ** (-scene.gm.attenuation_db / 10.0)


def _gate_s(scene: Scene) -> tuple[float, float]:
    """Gate opening since emission and gate length [s] (the LM-APD's gate)."""
    half = scene.timing.range_gate_m / 2.0
    lo = max(0.0, scene.gate_center_m - half)
    hi = scene.gate_center_m + half
    return 2.0 * lo / C, 2.0 * (hi - lo) / C


def _detector(scene: Scene) -> ev.Detector:
    gm = scene.gm
    return ev.Detector(
        gate_s=_gate_s(scene)[1],
        dead_time_s=gm.dead_time_s,
        jitter_s=gm.jitter_s,
        bin_s=gm.bin_s,
        afterpulsing=gm.afterpulsing,
        crosstalk=gm.crosstalk,
    )


def expected_load(scene: Scene, signal_pe, rate_hz, lit_pixel) -> tuple[float, float]:
    """The frame's load before any avalanche is drawn: the most avalanches one pixel records
    in one gate, and the avalanches of the whole frame (every pixel, ``gm.pulses`` pulses),
    from each pixel's primaries in the gate (its constant rate over the gate, plus its echo's
    photoelectrons) capped by the dead time, with crosstalk and afterpulsing.

    signal_pe : (n,) mean echo photoelectrons per pulse of the lit pixels ``lit_pixel`` [1]
    rate_hz : (pixels**2,) every pixel's constant primary rate [1/s]
    """
    gm = scene.gm
    gate_s = _gate_s(scene)[1]
    primaries = np.asarray(rate_hz, dtype=np.float64) * gate_s
    primaries[np.asarray(lit_pixel)] += signal_pe
    cap = 1.0 + gate_s / gm.dead_time_s if gm.dead_time_s > 0 else np.inf
    per_gate = np.minimum(primaries, cap) * (1.0 + gm.crosstalk) / (1.0 - gm.afterpulsing)
    worst = float(per_gate.max()) if len(per_gate) else 0.0
    return worst, float(per_gate.sum()) * gm.pulses


def _frame_rates(scene: Scene, echo: EchoStage, background) -> tuple[np.ndarray, np.ndarray]:
    """(n,) the lit pixels' echo photoelectrons per pulse and (pixels**2,) every pixel's
    constant primary rate [1/s], as :func:`respond` forms them."""
    hv_j = photon_energy_j(scene.laser.wavelength_m)
    signal_pe = scene.gm.pde * frame_pulse_energy_j(scene) * np.sum(echo.weights, axis=1) / hv_j
    bg_w = background_power_w(scene, background).reshape(-1)
    return signal_pe, scene.gm.pde * bg_w / hv_j + scene.gm.dark_count_rate_hz


def frame_load(scene: Scene, echo: EchoStage, background=None) -> tuple[float, float]:
    """:func:`expected_load` of ``scene``'s frame from its echo and background stages (an
    upper bound: a pixel's echo counts as all its photoelectrons up to the dead time's cap)."""
    signal_pe, rate_hz = _frame_rates(scene, echo, background)
    return expected_load(scene, signal_pe, rate_hz, echo.pixel)


_THROUGHPUT_A = np.logspace(-6.0, 12.0, 181)  # S d / s grid of :func:`_echo_throughput`


def _echo_throughput_table() -> np.ndarray:
    """F(a) = int x e^-x / (1 + a x e^-x) dx over x >= 0 on the grid ``_THROUGHPUT_A``."""
    x = np.linspace(0.0, 80.0, 8001)
    g = x * np.exp(-x)
    f = g[None, :] / (1.0 + _THROUGHPUT_A[:, None] * g[None, :])
    return np.sum((f[:, 1:] + f[:, :-1]) * 0.5 * np.diff(x)[None, :], axis=1)


_THROUGHPUT_F = _echo_throughput_table()


def frame_avalanches(scene: Scene, echo: EchoStage, background=None) -> float:
    """The avalanches ``scene``'s frame records on average, estimated before drawing any: per
    pixel and pulse, the constant rate's renewal throughput over the gate, r T / (1 + r d),
    plus the echo's: its rate S x e^-x / s (Eq. 1's Gamma(2, s) shape, x = t / s) through the
    dead time as a slowly varying renewal process, S F(S d / s) with
    F(a) = int x e^-x / (1 + a x e^-x) dx, at least 1 - e^-S (an echo shorter than the dead
    time fires once at most); times the crosstalk and afterpulsing factors and the pulses.
    Within 20 % of the recorded avalanches from the photon-starved to the piled-up frame
    (tests/app/test_app_budget.py)."""
    gm = scene.gm
    signal_pe, rate_hz = _frame_rates(scene, echo, background)
    gate_s = _gate_s(scene)[1]
    d = gm.dead_time_s
    per_pulse = float(np.sum(rate_hz * gate_s / (1.0 + rate_hz * d)))
    if len(signal_pe):
        a = signal_pe * d / (echo.shape.tau_s / echo.shape.a)
        log_f = np.interp(
            np.log(np.maximum(a, 1e-300)), np.log(_THROUGHPUT_A), np.log(_THROUGHPUT_F)
        )
        per_pulse += float(np.sum(np.maximum(-np.expm1(-signal_pe), signal_pe * np.exp(log_f))))
    return per_pulse * gm.pulses * (1.0 + gm.crosstalk) / (1.0 - gm.afterpulsing)


def _check_load(scene: Scene, signal_pe, rate_hz, lit_pixel) -> None:
    """Refuse frames whose expected avalanches exceed MAX_EVENTS (or one gate's exceed
    MAX_EVENTS_PER_PULSE), before drawing any: one message naming the keys to change."""
    gm = scene.gm
    worst, total = expected_load(scene, signal_pe, rate_hz, lit_pixel)
    if worst > MAX_EVENTS_PER_PULSE:
        raise SceneError(
            f"gm.dead_time_s = {gm.dead_time_s:g} s lets a pixel record about {worst:.3g} "
            f"avalanches per gate (at most {MAX_EVENTS_PER_PULSE:,}): give a longer dead time, "
            "less pulse energy or a shorter timing.range_gate_m"
        )
    if total > MAX_EVENTS:
        raise SceneError(
            f"gm.pulses = {gm.pulses} gives about {total:.3g} avalanches per frame, "
            f"{total * BYTES_PER_EVENT / 2**30:.3g} GiB to simulate (at most {MAX_EVENTS:,}): "
            "fewer pulses, a longer gm.dead_time_s, fewer pixels or a shorter "
            "timing.range_gate_m"
        )


def frame_budget(scene: Scene, echo: EchoStage, background=None) -> FrameLoad:
    """What the frame will record before any avalanche is drawn (the app's budget check): the
    avalanches :func:`frame_avalanches` expects, the memory of each, and whether the core's own
    bounds (:func:`frame_load`) hold."""
    total = frame_avalanches(scene, echo, background)
    worst, bound = frame_load(scene, echo, background)
    return FrameLoad(
        count=total,
        units="avalanches",
        bytes_each=BYTES_PER_EVENT,
        within_core_limits=worst <= MAX_EVENTS_PER_PULSE and bound <= MAX_EVENTS,
        advice="lower the Pulses per frame, the Dark count rate or the Pixels, or raise the "
        "Transmit attenuation or the Dead time",
    )
