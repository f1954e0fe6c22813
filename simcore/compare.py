"""The same scene with every receiver (``lmapd compare``): the LM-APD's single flash against the
Geiger-mode array's frame (and any other registered receiver) over distance and pulse energy
(docs/physics.md#geiger-mode).

Per (receiver, distance, pulse energy): target points, the range error of the detected pixels
(measured less the noise-free range: its rms, its median, the bias, and its sd about the mean,
the noise; for the Geiger-mode array the noise-free range is the echo's energy-weighted one, so a
piled-up histogram's bias shows as bias, not noise, beside the receiver's predicted bias and
sd), the false points of the frame's cloud (``n_outliers``) beside their prediction
(``n_false_points_expected``, the same basis for both receivers: points in the cloud per frame;
docs/physics.md#false-points), and the pulses needed for a detection
probability ``p_target`` in the median lit pixel: for the LM-APD, independent flashes with its
per-flash P_d (Eq. 27) until one detects, ceil(ln(1 - P) / ln(1 - P_d)); for the Geiger-mode
array, the least frame length N whose P_d (counts of N pulses against the threshold) reaches P.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import receivers
from .pipeline import Pipeline
from .scene import Scene, with_overrides

DISTANCES_M = (100.0, 300.0, 1000.0, 3000.0, 10000.0)
ENERGIES_J = (5e-5, 5e-3)
MAX_PULSES = 10_000  # the search for the pulses needed stops here (reported as inf)


@dataclass(frozen=True)
class Row:
    receiver: str
    distance_m: float
    pulse_energy_j: float
    n_lit: int
    n_points: int
    range_noise_m: float
    range_bias_m: float
    range_sd_m: float
    predicted_bias_m: float
    predicted_sd_m: float
    n_outliers: int
    n_false_points_expected: float
    pulses_needed: float
    signal_pe_median: float


def pulses_needed(scene: Scene, result, p_target: float) -> float:
    """Pulses for P_d >= p_target in the median lit pixel (module docstring); inf if more than
    MAX_PULSES. A receiver that sums pulses into a frame says how (its declaration's
    ``pulses_needed``); otherwise independent flashes, from the per-flash P_d."""
    if len(result.echo.pixel) == 0:
        return math.inf
    own = receivers.get(scene.receiver.kind).pulses_needed
    if own is not None:
        return float(receivers.resolve(own)(scene, result, p_target, MAX_PULSES))
    p = float(np.median(result.detection.p_detect))
    if p >= p_target:
        return 1.0
    if p <= 0:
        return math.inf
    n = math.ceil(math.log1p(-p_target) / math.log1p(-p))
    return float(n) if n <= MAX_PULSES else math.inf


def compare(
    base: Scene,
    distances_m=DISTANCES_M,
    energies_j=ENERGIES_J,
    p_target: float = 0.95,
    progress=None,
) -> list[Row]:
    """Every (receiver, distance, energy) of ``base`` (its pixels, target, optics, seed)."""
    rows = []
    for kind in receivers.kinds():
        declared = receivers.get(kind)
        pipe = Pipeline()
        for d in distances_m:
            for e in energies_j:
                scene = with_overrides(
                    base, {"receiver.kind": kind, "distance_m": d, "pulse_energy_j": e}
                )
                res = pipe.run(scene)
                det = res.detection
                err = det.range_m[det.detected] - det.range_true_m[det.detected]
                pe = getattr(res.receiver, "signal_pe", None)
                s = res.summary()
                rows.append(
                    Row(
                        receiver=kind,
                        distance_m=d,
                        pulse_energy_j=e,
                        n_lit=s["n_lit_pixels"],
                        n_points=s["n_target_points"],
                        range_noise_m=float(np.sqrt(np.mean(err**2))) if len(err) else math.nan,
                        range_bias_m=float(np.median(err)) if len(err) else math.nan,
                        range_sd_m=float(np.std(err)) if len(err) > 1 else math.nan,
                        predicted_bias_m=_figure(s, declared.range_bias_figure, 0.0),
                        predicted_sd_m=_figure(
                            s, declared.range_sigma_figure, s["range_sigma_m_median"]
                        ),
                        n_outliers=s["n_outliers"],
                        n_false_points_expected=float(s.get("n_false_points_expected", math.nan)),
                        pulses_needed=pulses_needed(scene, res, p_target),
                        signal_pe_median=float(np.median(pe))
                        if pe is not None and len(pe)
                        else math.nan,
                    )
                )
                if progress is not None:
                    progress(rows[-1])
    return rows


def _figure(summary: dict, key: str | None, default) -> float:
    """A summary figure as a float (NaN where undefined; ``default`` where the receiver declares
    none)."""
    v = default if key is None else summary.get(key)
    return math.nan if v is None else float(v)
