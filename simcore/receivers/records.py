"""The records a receiver hands on: its response to the echoes of one flash (the receiver stage's
output), its detection (the detection stage's) and the false-alarm points. A receiver may subclass
the first two to add its own fields (the Geiger-mode array's frame and thresholds)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, kw_only=True)
class Outliers:
    """False-alarm points: pixel (flat index) and range of each [m]."""

    pixel: np.ndarray  # (n_out,) int64
    range_m: np.ndarray  # (n_out,) float64


@dataclass(frozen=True, kw_only=True)
class Response:
    """A receiver's response to the echoes of one flash (the receiver stage's output).

    peak_power_w : (n,) band-limited peak received power of each lit pixel [W] (point intensity)
    snr : (n,) signal-to-noise ratio of each lit pixel [1] (points' SNR, the app's histogram and
        the summary's median; inf where the receiver has no noise)
    noise_figures : scalar diagnostics of the receiver, name (with unit) -> value
    """

    peak_power_w: np.ndarray
    snr: np.ndarray
    noise_figures: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Detection:
    """Which lit pixels give a point and where, plus the false alarms (the detection stage's
    output). Arrays are (n,), aligned with ``EchoStage.pixel``.

    p_detect : probability of detecting the echo [1]
    detected : bool, the echo was detected inside the range gate
    range_true_m : noise-free measured range (Eq. 31, carries the waveform's bias) [m]
    range_sigma_m : range noise standard deviation [m] (inf where undefined)
    range_m : measured range, NaN where not detected [m]
    threshold_w : the arming threshold as power at the receiver input [W] (waveform plots; with
        per-pixel thresholds, a dark pixel's)
    n_false_per_pixel : expected false alarms per pixel per flash [1]: a float, the same for
        every pixel, or (pixels**2,) per pixel (flat index) where the background makes pixels
        differ
    outliers : the false-alarm points drawn for this flash
    point_attributes : a receiver's own per-point attributes, name -> (values of the lit
        pixels (n,), values of the outliers (n_out,)); the cloud carries them besides its shared
        set (the Geiger-mode receiver's ``counts`` and ``signal_pe``)
    summary_figures : a receiver's own summary figures, dotted name (with unit) -> JSON value
        (e.g. ``gm.saturated_pixel_fraction``); :meth:`simcore.result.Result.summary` adds them.
        Both built-in receivers give ``n_false_points_expected``: the false points expected in
        the cloud per frame, on the basis of the cloud's ``n_outliers``
        (docs/physics.md#false-points)
    """

    p_detect: np.ndarray
    detected: np.ndarray
    range_true_m: np.ndarray
    range_sigma_m: np.ndarray
    range_m: np.ndarray
    threshold_w: float
    n_false_per_pixel: float | np.ndarray
    outliers: Outliers
    point_attributes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    summary_figures: dict[str, Any] = field(default_factory=dict)  # JSON values

    @property
    def n_false_expected(self) -> float:
        """Expected false alarms of the whole array per flash before the stops' limit (the
        LM-APD's noise crossings), not the cloud's false points: those are the summary figure
        ``n_false_points_expected`` [1]."""
        n = self.n_false_per_pixel
        return float(np.sum(n)) if isinstance(n, np.ndarray) else n
