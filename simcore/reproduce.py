"""The numbers behind the reproduction of the paper's results: the run settings, the version, and
the analyses of a result that the figures show (per-material statistics, the matched field of
view, the pixels of Figure 14, pulse widths, the conventions table).

``lmapd reproduce`` (``simcore.cli.reproduce``) runs the scenes, draws the figures and writes the
report; the paper is Wang et al., *Analysis and Simulation of Space-Based LM-APD 3D Imaging*,
Electronics 2023, 12, 2261. Every function here is a pure function of its arguments (no files, no
plotting).
"""

from __future__ import annotations

import math
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import echo, orbit
from .constants import C
from .materials import MATERIAL_NAMES
from .pipeline import Result
from .receivers.lm_apd import timing
from .result import n_peaks

__all__ = [
    "CONVENTION_COLUMNS",
    "ReproduceSettings",
    "convention_row",
    "find_pixels",
    "fwhm_s",
    "git_commit",
    "matched_fov",
    "per_material",
    "run_summary",
    "settings_for",
]

PAPER = (
    "Wang, Quan, Zhang, Liu, Cong, Sun, Li, Wang, Analysis and Simulation of Space-Based LM-APD 3D "
    "Imaging, Electronics 2023, 12(10), 2261, doi:10.3390/electronics12102261"
)
TARGET_HALF_SPAN_M = 7.5  # [m] half the MRO's longest extent (Table 4: 15 m)
FOV_MARGIN = 1.1  # [1] field of view = 2 atan(1.1 * 7.5 m / R): 10 % margin around the target
FIG9_GATE_M = 1000.0  # [m] R_gate of the paper's Figure 9
FIG9_DF_HZ = 12e6  # [Hz] df of the paper's Figure 9 (its Eq. 28)
FIG9_SNRS = (3.0, 5.0, 7.0, 9.0)  # [1] SNR_na of the P_d curves (our choice)
FLYAROUND_FRAMES_S = (3000.0, 4200.0, 5400.0)  # [s] the frames of the paper's Figure 24
FLYAROUND_ENERGY_J = 1e-3  # [J] the pulse energy of the paper's Section 4.2
PAPER_PERIOD_S = orbit.PAPER_PERIOD_S  # [s] 5924.521, the paper's orbit software
RESOLUTION_DISTANCES_M = (500.0, 1000.0)  # [m]
RESOLUTION_PIXELS = (32, 64, 128, 256)  # [px per side]
_GIT_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class ReproduceSettings:
    """What a run computes: the full run or the quick one (tests), and the seed.

    Attributes
    ----------
    quick : bool
        Fewer pixels and Monte Carlo trials (a draft, for tests).
    seed : int
        Seed of every scene and every Monte Carlo generator.
    cloud_pixels : int
        Pixels per side of the attitude and conventions runs.
    waveform_pixels : int
        Pixels per side of the waveform run (reference preset, 8 x 8 sub-rays per pixel).
    attitude_steps_deg : tuple of float
        Pitch steps and azimuth steps [deg].
    mc_pd_trials : int
        Single-surface pixels per (SNR, TNR) Monte Carlo point.
    mc_tnr_step : float
        TNR step of the P_d Monte Carlo points.
    mc_fa_tnrs : tuple of float
        TNR of the false-alarm Monte Carlo points.
    mc_fa_max_pixels : int
        Noise-only pixels per false-alarm point at most.
    mc_fa_target_count : int
        False alarms aimed at per point (fewer pixels where they are frequent).
    flyaround_interval_s : float
        Time between fly-around frames [s].
    flyaround_pixels : int
        Pixels per side of the fly-around frames.
    """

    quick: bool
    seed: int
    cloud_pixels: int
    waveform_pixels: int
    attitude_steps_deg: tuple[float, ...]
    mc_pd_trials: int
    mc_tnr_step: float
    mc_fa_tnrs: tuple[float, ...]
    mc_fa_max_pixels: int
    mc_fa_target_count: int
    flyaround_interval_s: float
    flyaround_pixels: int


def settings_for(quick: bool = False, seed: int = 0) -> ReproduceSettings:
    """The settings of the full run (``quick=False``) or of the quick one, with ``seed``."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if quick:
        return ReproduceSettings(
            quick=True,
            seed=int(seed),
            cloud_pixels=64,
            waveform_pixels=128,
            attitude_steps_deg=(0.0, 30.0, 60.0),
            mc_pd_trials=300,
            mc_tnr_step=1.0,
            mc_fa_tnrs=(2.0, 3.0, 4.0),
            mc_fa_max_pixels=1024,
            mc_fa_target_count=100,
            flyaround_interval_s=600.0,
            flyaround_pixels=64,
        )
    return ReproduceSettings(
        quick=False,
        seed=int(seed),
        cloud_pixels=256,
        waveform_pixels=256,
        attitude_steps_deg=(0.0, 20.0, 40.0, 60.0),
        mc_pd_trials=4000,
        mc_tnr_step=0.5,
        mc_fa_tnrs=(2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0),
        mc_fa_max_pixels=16384,
        mc_fa_target_count=600,
        flyaround_interval_s=300.0,
        flyaround_pixels=256,
    )


def git_commit(path: str | Path | None = None) -> dict[str, Any]:
    """The git commit of the checkout holding ``path`` (default: this package), if any.

    Returns ``{"commit": str | None, "dirty": bool | None}``; both None outside a git checkout or
    without git. Read-only: ``GIT_OPTIONAL_LOCKS=0`` keeps ``git status`` from touching the index.
    """
    folder = Path(path) if path is not None else Path(__file__).resolve().parent
    env = {**os.environ, "GIT_OPTIONAL_LOCKS": "0"}

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(
                ["git", "-C", str(folder), *args],
                capture_output=True,
                text=True,
                timeout=_GIT_TIMEOUT_S,
                env=env,
                check=False,
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None, "dirty": None}
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit.strip(), "dirty": None if status is None else bool(status.strip())}


def finite_median(values) -> float | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else None


def run_summary(result: Result) -> dict[str, Any]:
    """The summary numbers of one run (deterministic: no wall times)."""
    s = result.summary()
    keys = (
        "n_pixels",
        "n_hit_pixels",
        "n_lit_pixels",
        "n_points",
        "n_target_points",
        "n_outliers",
        "n_dropped",
        "n_unlit",
        "p_detect_mean",
        "snr_median",
        "range_sigma_m_median",
        "n_false_expected",
        "n_false_crossings_expected",
    )
    return {k: (float(s[k]) if isinstance(s[k], np.floating) else s[k]) for k in keys}


def per_material(result: Result) -> dict[str, dict[str, Any]]:
    """Per library material seen: lit pixels, detected, median SNR and range sigma [m], and the
    robust spread (1.4826 MAD) of the drawn range errors of the detected pixels [m]."""
    e, d, r = result.echo, result.detection, result.receiver
    out = {}
    for mid in np.unique(e.material_id):
        if mid < 0:
            continue
        sel = e.material_id == mid
        det = sel & d.detected
        err = (d.range_m - d.range_true_m)[det]
        mad = 1.4826 * float(np.median(np.abs(err - np.median(err)))) if len(err) else None
        out[MATERIAL_NAMES[mid]] = {
            "n_lit": int(sel.sum()),
            "n_detected": int(det.sum()),
            "snr_median": finite_median(r.snr[sel]),
            "range_sigma_m_median": finite_median(d.range_sigma_m[det]),
            "range_error_m_robust_sigma": mad,
        }
    return out


def matched_fov(distance_m: float, divergence_rad: float) -> dict[str, float]:
    """Field of view fitting the MRO's 15 m with a 10 % margin at ``distance_m``, and the beam
    expansion ratio that makes the illumination cone (divergence / ratio) equal to it."""
    fov = 2.0 * math.atan(FOV_MARGIN * TARGET_HALF_SPAN_M / distance_m)
    return {"receive.fov_rad": fov, "transmit.beam_expansion_ratio": divergence_rad / fov}


def mc_tnr_grid(s: ReproduceSettings) -> np.ndarray:
    return np.arange(2.0, 12.0 + 1e-9, s.mc_tnr_step)


def subray_parts(result: Result) -> dict[int, np.ndarray]:
    """Flat pixel index -> part index of each sub-ray's first hit (-1 for a miss)."""
    face_part = result.target.face_part
    parts: dict[int, np.ndarray] = {}
    for block in result.hits.blocks():
        part = np.where(block.face >= 0, face_part[np.maximum(block.face, 0)], -1)
        parts.update(zip(block.pixel.tolist(), part, strict=True))
    return parts


def delay_rms_s(arrivals_s: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n,) weighted rms spread of each pixel's sub-ray delays [s] (weights (n, K) >= 0)."""
    w = np.asarray(weights, dtype=np.float64)
    total = np.maximum(w.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    mean = (w * arrivals_s).sum(axis=1, keepdims=True) / total
    return np.sqrt((w * (arrivals_s - mean) ** 2).sum(axis=1) / total[:, 0])


def find_pixels(result: Result) -> dict[str, Any]:
    """The two pixels of Figure 14, found in the echo data.

    ``double_peak``: the largest depth span (Eq. 29 delays) whose band-limited echo has two peaks,
    preferring a pixel that sees the dish (part ``cover``) and another part (the bus);
    ``dish``: all sub-rays on ``cover``, one peak, the largest weighted rms delay spread.
    """
    e = result.echo
    names = result.target.part_names
    cover = names.index("cover") if "cover" in names else -1
    parts = subray_parts(result)
    has = e.weights > 0
    arrivals = np.where(has, e.arrivals_s, 0.0)
    span_s = np.where(has, arrivals, -np.inf).max(axis=1) - np.where(has, arrivals, np.inf).min(
        axis=1
    )
    rms_s = delay_rms_s(arrivals, e.weights)

    def peaks(i):
        _, _, y = echo.echo_waveform(e.shape, e.arrivals_s[i], e.weights[i], e.dt_s)
        return n_peaks(y)

    double = fallback = None
    for i in np.argsort(-span_s, kind="stable")[:400]:
        p = parts[int(e.pixel[i])]
        hit_parts = set(p[p >= 0].tolist())
        if peaks(i) < 2:
            continue
        if fallback is None:
            fallback = i
        if cover in hit_parts and len(hit_parts - {cover}) > 0:
            double = i
            break
    double = fallback if double is None else double
    dish = None
    all_cover = np.array([bool(np.all(parts[int(p)] == cover)) for p in e.pixel])
    for i in np.argsort(-np.where(all_cover, rms_s, -1.0), kind="stable")[:400]:
        if all_cover[i] and peaks(i) == 1:
            dish = i
            break
    found: dict[str, dict[str, Any] | None] = {}
    for key, i in (("double_peak", double), ("dish", dish)):
        if i is None:
            found[key] = None
            continue
        p = parts[int(e.pixel[i])]
        found[key] = {
            "index": int(i),
            "row": int(e.pixel[i] // result.pixels),
            "col": int(e.pixel[i] % result.pixels),
            "depth_span_m": float(0.5 * C * span_s[i]),
            "depth_rms_m": float(0.5 * C * rms_s[i]),
            "parts": sorted(names[k] for k in set(p[p >= 0].tolist())),
        }
    return found


def fwhm_s(t_s: np.ndarray, y: np.ndarray) -> float:
    """Full width at half maximum of a sampled waveform between its outermost half-maximum
    crossings, each interpolated linearly between samples [s]; NaN without a peak inside."""
    if len(y) < 3 or not y.max() > 0:
        return float("nan")
    half = 0.5 * y.max()
    above = np.flatnonzero(y >= half)
    i, j = above[0], above[-1]
    if i == 0 or j == len(y) - 1:
        return float("nan")
    t_up = t_s[i - 1] + (half - y[i - 1]) / (y[i] - y[i - 1]) * (t_s[i] - t_s[i - 1])
    t_down = t_s[j] + (y[j] - half) / (y[j] - y[j + 1]) * (t_s[j + 1] - t_s[j])
    return float(t_down - t_up)


CONVENTION_COLUMNS = (
    "snr_median",
    "peak_current_median_a",
    "range_sigma_m_median",
    "range_sigma_cfd_m_median",
    "p_detect_mean",
    "n_target_points",
    "n_dropped",
    "n_outliers",
    "n_false_expected",
    "n_false_crossings_expected",
    "n_points",
    "depth_extent_m",
)


def convention_row(result: Result) -> dict[str, Any]:
    summary = run_summary(result)
    attrs = result.attributes
    tgt = ~attrs["is_outlier"]
    r = attrs["range_m"][tgt]
    extent = float(np.percentile(r, 99) - np.percentile(r, 1)) if len(r) else None
    row = {k: summary[k] for k in CONVENTION_COLUMNS if k in summary}
    row["peak_current_median_a"] = finite_median(result.receiver.i_pk_a)  # the paper's LM-APD
    d = result.detection
    sigma_t = timing.sigma_quantisation_m(result.scene.timing.resolution_s)
    cfd = np.sqrt(np.maximum(d.range_sigma_m[d.detected] ** 2 - sigma_t**2, 0.0))
    row["range_sigma_cfd_m_median"] = finite_median(cfd)  # Eq. 25 alone (Eq. 24 minus Eq. 26)
    row["depth_extent_m"] = extent
    return {k: row[k] for k in CONVENTION_COLUMNS}
