"""A Geiger-mode frame's photon counts as a chart draws them (the app's ``counts`` chart, named
by the declaration): each pixel's histogram, the counts expected from the same pulses (dead time,
jitter and bins included) and the counts that would arrive without dead time."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .expected import Timing, expected_histogram
from .frame import frame_pulse_energy_j, photon_energy_j
from .limits import armed_probability


@dataclass(frozen=True)
class FrameCounts:
    """The counts of a ``gm_apd`` result: its gate's opening [s], TDC bin [s], bins and pulses,
    and per pixel (flat index) the measured, expected and arriving counts."""

    result: Any

    @property
    def gate_start_s(self) -> float:
        return self.result.receiver.gate_start_s

    @property
    def bin_s(self) -> float:
        return self.result.scene.gm.bin_s

    @property
    def n_bins(self) -> int:
        return self.result.receiver.histogram.n_bins

    @property
    def pulses(self) -> int:
        return self.result.scene.gm.pulses

    def pixel_counts(self, flat: int) -> tuple[np.ndarray, np.ndarray]:
        """The bins of pixel ``flat`` that hold avalanches, and their counts."""
        return self.result.receiver.histogram.pixel_counts(flat)

    def expected(self, w, flat: int, k0: int, k1: int) -> np.ndarray:
        """(k1 - k0,) the avalanches bins k0 .. k1 - 1 of pixel ``flat`` hold on average."""
        return expected_counts(self.result, w, flat, k0, k1)

    def arriving(self, w, flat: int, k: np.ndarray) -> np.ndarray:
        """The avalanches per bin ``k`` without dead time or jitter."""
        return arriving_counts(self.result, w, flat, k)


def frame_counts(result) -> FrameCounts:
    return FrameCounts(result)


def _element_pe(result: Any, flat: int) -> tuple[np.ndarray, np.ndarray]:
    """(1, K) arrival from the gate's opening [s] and mean photoelectrons per pulse of each
    echo element of pixel ``flat`` (one empty element for a pixel without an echo)."""
    scene, echo, rx = result.scene, result.echo, result.receiver
    at = np.flatnonzero(np.asarray(echo.pixel) == flat)
    if not len(at):
        return np.zeros((1, 1)), np.zeros((1, 1))
    per_weight = (
        scene.gm.pde * frame_pulse_energy_j(scene) / photon_energy_j(scene.laser.wavelength_m)
    )
    arrivals = np.asarray(echo.arrivals_s)[at] - rx.gate_start_s
    return arrivals, per_weight * np.asarray(echo.weights)[at]


def expected_counts(result: Any, w, flat: int, k0: int, k1: int) -> np.ndarray:
    """(k1 - k0,) the avalanches bins k0 .. k1 - 1 of pixel ``flat`` hold on average over the
    frame's pulses: its echo and constant rate through the dead time, the jitter and the bins
    (``expected.expected_histogram``; the pixel armed at the window's start as the background's
    renewal process leaves it)."""
    scene, rx = result.scene, result.receiver
    gm = scene.gm
    element_t, element_pe = _element_pe(result, flat)
    rate = np.asarray(rx.rate_hz[flat : flat + 1], dtype=np.float64)
    armed = armed_probability(rate, k0 * gm.bin_s, gm.dead_time_s)
    scale_s = result.echo.shape.tau_s / result.echo.shape.a
    timing = Timing(
        scale_s=scale_s,
        jitter_s=gm.jitter_s,
        bin_s=gm.bin_s,
        dead_time_s=gm.dead_time_s,
        n_pulses=gm.pulses,
    )
    q, _ = expected_histogram(timing, element_t, element_pe, rate, np.array([k0]), k1 - k0, armed)
    return gm.pulses * q[0]


def arriving_counts(result: Any, w, flat: int, k: np.ndarray) -> np.ndarray:
    """Mean avalanches per bin over the frame without dead time or jitter: pulses x bin x
    (PDE x the echo's photon rate P_r(t) / (h nu) + the pixel's background and dark rate)."""
    scene, rx = result.scene, result.receiver
    gm = scene.gm
    t = rx.gate_start_s + (k + 0.5) * gm.bin_s
    echo_w = np.interp(t, w.t_s, w.power_w, left=0.0, right=0.0) if len(w.t_s) else 0.0 * t
    # the waveform is the laser pulse's; the frame's pulses carry it less the attenuation
    echo_w = echo_w * frame_pulse_energy_j(scene) / scene.laser.pulse_energy_j
    rate_hz = gm.pde * echo_w / photon_energy_j(scene.laser.wavelength_m) + rx.rate_hz[flat]
    return gm.pulses * gm.bin_s * rate_hz
