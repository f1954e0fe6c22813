"""The Geiger-mode array's scene section, ``[gm]`` (its keys with their units, ranges and docs),
and the rules between its keys and the shared ones (the histogram's size), checked when a scene
selects the array. Loads no numpy: the scene reads it."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import SceneError
from ...scene.fields import key

SPEED_OF_LIGHT_M_S = 299_792_458.0  # [m/s] exact (SI)


# The most pulses one Geiger-mode frame may accumulate: 10^4 pulses of a 256 x 256 array are
# 6.6e8 pixel-pulses (minutes on two cores); more is a different instrument (a long dwell).
MAX_GM_PULSES = 10_000


@dataclass(frozen=True)
class GeigerMode:
    pde: float = key(
        0.3,
        "1",
        0.0,
        1.0,
        "Geiger-mode photon detection efficiency (InGaAs GM-APD at 1064 nm)",
        lo_open=True,
    )
    dark_count_rate_hz: float = key(
        10e3, "Hz", 0.0, 1e9, "Geiger-mode dark count rate per pixel (armed)"
    )
    dead_time_s: float = key(
        1e-6,
        "s",
        0.0,
        1.0,
        "Geiger-mode dead time after each avalanche: non-paralysable, re-armed at each gate "
        "opening (longer than the gate: first photon only)",
    )
    jitter_s: float = key(
        200e-12, "s", 0.0, 1e-6, "Geiger-mode timing jitter (rms, Gaussian)", lo_open=True
    )
    bin_s: float = key(
        250e-12,
        "s",
        0.0,
        10e-9,
        "Geiger-mode TDC bin width of the histogram (a coarse TDC: at most 10 ns, 1.5 m)",
        lo_open=True,
    )
    pulses: int = key(
        100, "1", 1, MAX_GM_PULSES, "Geiger-mode pulses per frame, histogrammed per pixel"
    )
    crosstalk: float = key(
        0.0, "1", 0.0, 0.5, "Geiger-mode crosstalk: chance an avalanche fires a 4-neighbour"
    )
    afterpulsing: float = key(
        0.0, "1", 0.0, 0.5, "Geiger-mode afterpulsing: chance an avalanche fires again on re-arm"
    )
    coates: bool = key(
        True, "-", doc="Geiger-mode range from the Coates-corrected histogram (false: raw counts)"
    )
    attenuation_db: float = key(
        50.0,
        "dB",
        0.0,
        200.0,
        "Geiger-mode transmit attenuation: the frame's pulses carry laser.pulse_energy_j x "
        "10^(-attenuation_db / 10) (50 dB: the paper's 5 mJ becomes 50 nJ, under one "
        "photoelectron per pixel per pulse on the paper scene, where single-photon receivers "
        "operate; 0: the full pulse, piled up)",
    )
    pileup_correction: str = key(
        "none",
        "-",
        doc="Geiger-mode first-photon (pile-up) correction: none (the centroid of the "
        "histogram) or fit (the first-photon model fitted to each pixel's first avalanches "
        "per armed pulse: echo start and photoelectrons per pulse)",
        choices=("none", "fit"),
    )


# Geiger-mode histogram sizes (simcore/receivers/gm_apd/): bins are int32 in the event records;
# each detected pixel's centroid reads a dense analysis window of
# (s + 4 jitter) + (12 s + 4 jitter) bins (s = tau / 2.446, the pulse's Gamma(2) scale), in
# blocks of GM_WINDOW_BLOCK_VALUES values (32 MB of float64); over the whole array at most
# GM_MAX_WINDOW_VALUES values (about 2 GB of float64 passes, seconds on two cores).
GM_MAX_GATE_BINS = 2**31 - 1
GM_WINDOW_BLOCK_VALUES = 1 << 22
GM_MAX_WINDOW_VALUES = 1 << 28
GM_PULSE_SCALE_OVER_TAU = 1.0 / 2.446386  # s / tau for Eq. 1 with tau the FWHM (the larger s)


def gm_analysis_window_bins(scene) -> float:
    """Bins of one Geiger-mode pixel's dense analysis window: one pulse scale s and four
    jitter sigmas before the peak window, twelve s and four sigmas after it (an upper bound of
    ``detection.detect``'s, clipped to the gate)."""
    g = scene.gm
    s = scene.laser.pulse_width_s * GM_PULSE_SCALE_OVER_TAU
    reach = 4.0 * g.jitter_s
    window = (s + reach) / g.bin_s + (12.0 * s + reach) / g.bin_s + 3.0  # the ceils
    return min(window, gm_gate_bins(scene))


def gm_gate_bins(scene) -> float:
    """TDC bins of the Geiger-mode range gate (a float: it may exceed any integer type)."""
    lo = max(0.0, scene.gate_center_m - scene.timing.range_gate_m / 2.0)
    hi = scene.gate_center_m + scene.timing.range_gate_m / 2.0
    bins = 2.0 * (hi - lo) / SPEED_OF_LIGHT_M_S / scene.gm.bin_s
    return float(math.ceil(bins)) if math.isfinite(bins) else math.inf


def check_scene(scene) -> None:
    """The Geiger-mode gate fits int32 bins and the analysis windows stay within
    GM_WINDOW_BLOCK_VALUES per pixel and GM_MAX_WINDOW_VALUES over the array: refused before
    any ray is cast, naming the keys to change."""
    g = scene.gm
    n_bins = gm_gate_bins(scene)
    if n_bins > GM_MAX_GATE_BINS:
        raise SceneError(
            f"gm.bin_s = {g.bin_s:g} s splits the gate (timing.range_gate_m = "
            f"{scene.timing.range_gate_m:g} m) into {n_bins:.3g} bins (at most "
            f"{GM_MAX_GATE_BINS:,}): give a coarser gm.bin_s or a shorter timing.range_gate_m"
        )
    window = gm_analysis_window_bins(scene)
    total = window * scene.detector.pixels**2
    if window > GM_WINDOW_BLOCK_VALUES or total > GM_MAX_WINDOW_VALUES:
        floor_s = g.bin_s * max(window / GM_WINDOW_BLOCK_VALUES, total / GM_MAX_WINDOW_VALUES)
        raise SceneError(
            f"gm.bin_s = {g.bin_s:g} s is too fine for gm.jitter_s = {g.jitter_s:g} s and "
            f"laser.pulse_width_s = {scene.laser.pulse_width_s:g} s: each pixel's analysis "
            f"window is {window:.3g} bins, {total:.3g} over the {scene.detector.pixels}^2 "
            f"pixels (at most {GM_WINDOW_BLOCK_VALUES:,} and {GM_MAX_WINDOW_VALUES:,}): give "
            f"gm.bin_s of at least {floor_s:.2g} s, a smaller gm.jitter_s or fewer "
            "detector.pixels"
        )
