"""Reproduce the paper's results from the simulator, side by side with its own forms.

``lmapd reproduce --out DIR [--quick] [--seed N]`` regenerates, with one command, each result of
Wang et al., *Analysis and Simulation of Space-Based LM-APD 3D Imaging*, Electronics 2023, 12, 2261
that this simulator can produce, and writes one PNG per figure plus ``DIR/report.json`` with every
number behind them, the scene of every run, the seed and the simulator's version:

1. ``fig02_brdf.png`` -- Eq. 6 against the incidence angle for the Table 1 materials (Figure 2).
2. ``fig09_detection.png`` -- P_d and false alarms against TNR: Eqs. 27-28 (ours and the paper's)
   with waveform Monte Carlo points, R_gate = 1 km and df = 12 MHz as in Figure 9.
3. ``fig14_waveforms.png`` -- single-pixel echoes found in the echo data: dish rim over the bus
   (a double peak) and a steep part of the dish (a spread echo), with the emitted pulse (Figure 14).
4. ``fig16_pitch.png``, ``fig17_azimuth.png`` -- point clouds over pitch and azimuth steps,
   front and top views, coloured by material (Figures 16, 17).
5. ``fig18_20_resolution.png`` -- 32 to 256 pixels per side at 500 m and 1000 m with the field of
   view (and the illumination cone) matched to the target, and the point counts (Figures 18-20).
6. ``fig07_flyaround.png``, ``fig24_frames.png`` -- the Table 3 fly-around: distance and attitude
   curves (Figure 7) and the frames at t = 3000, 4200 and 5400 s (Figure 24).
7. ``conventions.png`` -- each of the paper's literal forms (``simcore.PAPER_FORMS``) alone against
   ours: its change to SNR, range sigma, outliers and point count on the paper scene.

Every random draw comes from a generator seeded by ``seed``, so a run is reproduced exactly by the
same seed (and ``quick`` flag); only the wall times in ``report["timings_s"]`` differ.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import constants as sc
from scipy import signal
from tqdm import tqdm

from . import detection, echo, io, orbit, receiver, timing
from .flyaround import plot_flyaround, run_flyaround
from .materials import LIBRARY, MATERIAL_NAMES, material_brdf
from .pipeline import Pipeline, Result
from .scene import PAPER_FORMS, Scene, load_scene, with_overrides

__all__ = [
    "ITEMS",
    "REPORT_NAME",
    "ReproduceSettings",
    "add_parser",
    "git_commit",
    "run_cli",
    "run_reproduction",
    "settings_for",
]

C = sc.c  # speed of light [m/s] (exact)
REPORT_NAME = "report.json"
ITEMS = ("brdf", "detection", "waveforms", "attitude", "resolution", "flyaround", "conventions")
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
# Colours of the library materials (index = material id) and of the false alarms.
MATERIAL_COLORS = ("#7f7f7f", "#17becf", "#1f5fbf", "#d4a017", "#3a9a3a", "#9467bd")
OUTLIER_COLOR = "#d62728"
VIEW_HALF_M = 9.0  # [m] half width of the point-cloud panels around the target centre
_CLOUD_NOTE = (
    "false alarms: all over the 1 km range gate (in view: inside the 18 m cube the two views show)"
)
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


# ----------------------------------------------------------------------------------------------
# version and the run context
# ----------------------------------------------------------------------------------------------
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


class _Run:
    """One reproduction: output folder, settings, the shared pipeline and the progress bar."""

    def __init__(self, out: Path, settings: ReproduceSettings, total_steps: int, progress: bool):
        self.out = out
        self.settings = settings
        self.pipeline = Pipeline()
        self.bar = tqdm(
            total=total_steps, desc="reproduce", unit="step", file=sys.stderr, disable=not progress
        )

    def step(self, label: str) -> None:
        self.bar.set_postfix_str(label, refresh=False)
        self.bar.update()

    def scene(self, overrides: dict[str, Any] | None = None) -> Scene:
        """The paper scene with the run's seed and ``overrides``."""
        overrides = {"seed": self.settings.seed, **(overrides or {})}
        return with_overrides(load_scene("paper"), overrides)

    def run(self, scene: Scene) -> Result:
        return self.pipeline.run(scene)

    def rng(self, *stream: int) -> np.random.Generator:
        return np.random.default_rng([self.settings.seed, *stream])

    def save(self, fig, name: str) -> str:
        with io.atomic_path(self.out / name) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
        return name


def _total_steps(s: ReproduceSettings) -> int:
    n_tnr = len(_mc_tnr_grid(s))
    n_frames = len(orbit.flyaround_times(s.flyaround_interval_s, PAPER_PERIOD_S))
    return (
        1  # brdf
        + n_tnr
        + len(s.mc_fa_tnrs)
        + 1  # detection
        + 2  # waveforms
        + 2 * len(s.attitude_steps_deg)
        + 2  # attitude
        + len(RESOLUTION_DISTANCES_M) * len(RESOLUTION_PIXELS)
        + 1  # resolution
        + n_frames
        + len(FLYAROUND_FRAMES_S)
        + 2  # flyaround
        + len(PAPER_FORMS)
        + 3  # conventions
    )


def run_reproduction(
    out_dir: str | Path, *, quick: bool = False, seed: int = 0, progress: bool = True
) -> dict[str, Any]:
    """Regenerate every item, write the PNGs and ``report.json`` into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder, created if missing.
    quick : bool
        The quick settings (``settings_for(True)``): fewer pixels and trials.
    seed : int
        Seed of every scene and Monte Carlo generator (>= 0).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    dict
        The report as written to ``out_dir/report.json``.
    """
    settings = settings_for(quick, seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = _Run(out, settings, _total_steps(settings), progress)
    from . import __version__  # noqa: PLC0415  (defined by the package __init__, read at run time)

    items: dict[str, Any] = {}
    timings: dict[str, float] = {}
    makers = {
        "brdf": _item_brdf,
        "detection": _item_detection,
        "waveforms": _item_waveforms,
        "attitude": _item_attitude,
        "resolution": _item_resolution,
        "flyaround": _item_flyaround,
        "conventions": _item_conventions,
    }
    start = time.perf_counter()
    with run.bar:
        for number, name in enumerate(ITEMS, start=1):
            t0 = time.perf_counter()
            items[name] = {"item": number, **makers[name](run)}
            timings[name] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - start
    report = {
        "title": "lmapd-sim reproduction of the paper's results",
        "paper": PAPER,
        "simulator": {"name": "lmapd-sim", "version": __version__, **_git_fields()},
        "seed": settings.seed,
        "quick": settings.quick,
        "settings": {k: v for k, v in vars(settings).items() if k not in ("quick", "seed")},
        "material_names": list(MATERIAL_NAMES),
        "target_credit": "3D model: NASA/JPL-Caltech (NASA 3D Resources)",
        "items": items,
        "figures": [f for item in items.values() for f in item["figures"]],
        "timings_s": timings,
    }
    io.write_json(out / REPORT_NAME, report)
    return report


def _git_fields() -> dict[str, Any]:
    git = git_commit()
    return {"git_commit": git["commit"], "git_dirty": git["dirty"]}


# ----------------------------------------------------------------------------------------------
# small helpers
# ----------------------------------------------------------------------------------------------
def _figure(width_in: float, height_in: float):
    from matplotlib.figure import Figure  # noqa: PLC0415  (heavy; only when plotting)

    return Figure(figsize=(width_in, height_in), layout="constrained")


def _finite_median(values) -> float | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else None


def _run_summary(result: Result) -> dict[str, Any]:
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
        "p_detect_mean",
        "snr_median",
        "range_sigma_m_median",
        "n_false_expected",
    )
    return {k: (float(s[k]) if isinstance(s[k], np.floating) else s[k]) for k in keys}


def _per_material(result: Result) -> dict[str, dict[str, Any]]:
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
            "snr_median": _finite_median(r.snr[sel]),
            "range_sigma_m_median": _finite_median(d.range_sigma_m[det]),
            "range_error_m_robust_sigma": mad,
        }
    return out


def _matched_fov(distance_m: float, divergence_rad: float) -> dict[str, float]:
    """Field of view fitting the MRO's 15 m with a 10 % margin at ``distance_m``, and the beam
    expansion ratio that makes the illumination cone (divergence / ratio) equal to it."""
    fov = 2.0 * math.atan(FOV_MARGIN * TARGET_HALF_SPAN_M / distance_m)
    return {"receive.fov_rad": fov, "transmit.beam_expansion_ratio": divergence_rad / fov}


def _material_legend(fig, present: set[int], outliers: bool, credit: str | None) -> None:
    from matplotlib.lines import Line2D  # noqa: PLC0415

    handles = [
        Line2D([], [], ls="", marker="o", ms=6, color=MATERIAL_COLORS[m], label=MATERIAL_NAMES[m])
        for m in sorted(present)
    ]
    if outliers:
        handles.append(
            Line2D([], [], ls="", marker="x", ms=6, color=OUTLIER_COLOR, label="false alarm")
        )
    if credit:  # the model's credit as the legend's last entry, so that it never overlaps it
        handles.append(Line2D([], [], ls="", label=f"   {credit}"))
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=len(handles),
        fontsize=8.5,
        handletextpad=0.3,
    )


def _credit(fig, credit: str) -> None:
    """The model's credit line at the bottom right, inside the constrained layout."""
    fig.supxlabel(credit, x=0.995, ha="right", fontsize=7)


def _marker_size(result: Result, half_width_m: float, panel_in: float) -> float:
    """Scatter marker area [pt^2] about one pixel footprint at the target, at least 0.25."""
    footprint_m = result.scene.pose.distance_m * result.scene.ifov_rad
    points_per_m = 72.0 * panel_in / (2.0 * half_width_m)
    return max(0.25, (0.9 * footprint_m * points_per_m) ** 2)


def _draw_cloud(ax_front, ax_top, result: Result, title: str, panel_in: float) -> set[int]:
    """Front view (image x right, up) and, if ``ax_top`` is given, top view (x, depth behind the
    target centre) of one cloud, coloured by material; false alarms inside the panels as red
    crosses. Returns the material ids drawn."""
    pts = result.points
    attrs = result.attributes
    out = attrs["is_outlier"]
    mat = attrs["material_id"]
    depth = pts[:, 2] - result.scene.pose.distance_m
    x, up = pts[:, 0], -pts[:, 1]
    h = VIEW_HALF_M
    size = _marker_size(result, h, panel_in)
    tgt = ~out
    colors = np.array(MATERIAL_COLORS)[np.maximum(mat[tgt], 0)]
    views = [(ax_front, up)] + ([(ax_top, depth)] if ax_top is not None else [])
    # false alarms spread over the whole range gate: draw those inside the panels' cube only
    in_cube = out & (np.abs(x) <= h) & (np.abs(up) <= h) & (np.abs(depth) <= h)
    for ax, vertical in views:
        ax.scatter(x[tgt], vertical[tgt], s=size, c=colors, marker="s", linewidths=0)
        inside = in_cube
        ax.scatter(x[inside], vertical[inside], s=14, c=OUTLIER_COLOR, marker="x", linewidths=0.8)
        ax.set_xlim(-h, h)
        ax.set_ylim(-h, h)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.25)
    ax_front.set_title(
        f"{title}\n{int(tgt.sum())} points, {int(out.sum())} false alarms ({int(in_cube.sum())} "
        "in view)",
        fontsize=8,
    )
    ax_front.set_xlabel("x (image right) [m]", fontsize=7)
    ax_front.set_ylabel("up [m]", fontsize=7)
    if ax_top is not None:
        ax_top.set_xlabel("x (image right) [m]", fontsize=7)
        ax_top.set_ylabel("depth behind centre [m] (lidar below)", fontsize=7)
    return {int(m) for m in np.unique(mat[tgt])}


# ----------------------------------------------------------------------------------------------
# 1. BRDF (Figure 2)
# ----------------------------------------------------------------------------------------------
def _item_brdf(run: _Run) -> dict[str, Any]:
    angle_deg = np.linspace(0.0, 90.0, 361)
    cos_t = np.cos(np.radians(angle_deg))
    names = [n for n in MATERIAL_NAMES if n != "lambertian"] + ["lambertian"]
    rho = {n: material_brdf(cos_t, LIBRARY[n]) for n in names}
    fig = _figure(11.0, 4.4)
    ax_lin, ax_log = fig.subplots(1, 2)
    for n in names:
        style = {"ls": "--", "color": "0.3"} if n == "lambertian" else {}
        for ax in (ax_lin, ax_log):
            ax.plot(angle_deg, rho[n], lw=1.6, label=LIBRARY[n].label, **style)
    ax_log.set_yscale("log")
    ax_log.set_ylim(1e-6, 3.0)
    for ax in (ax_lin, ax_log):
        ax.set_xlabel("incidence angle theta [deg]")
        ax.set_ylabel("BRDF rho [1/sr]")
        ax.set_xlim(0, 90)
        ax.grid(alpha=0.3, which="both")
    ax_lin.set_title("Eq. 6, linear")
    ax_log.set_title("Eq. 6, logarithmic (specular lobes, grazing fall-off)")
    ax_lin.legend(fontsize=8)
    fig.suptitle("BRDF of the Table 1 materials against incidence angle (paper Figure 2)")
    figure = run.save(fig, "fig02_brdf.png")
    run.step("BRDF")
    return {
        "paper_figure": "Figure 2",
        "figures": [figure],
        "scenes": {},
        "parameters": {
            n: {"A": LIBRARY[n].A, "B": LIBRARY[n].B, "m": LIBRARY[n].m, "s": LIBRARY[n].s}
            for n in names
        },
        "angle_deg": angle_deg.tolist(),
        "brdf_per_sr": {n: rho[n].tolist() for n in names},
    }


# ----------------------------------------------------------------------------------------------
# 2. detection probability and false alarms (Figure 9)
# ----------------------------------------------------------------------------------------------
def _mc_tnr_grid(s: ReproduceSettings) -> np.ndarray:
    return np.arange(2.0, 12.0 + 1e-9, s.mc_tnr_step)


def _item_detection(run: _Run) -> dict[str, Any]:
    from . import montecarlo  # noqa: PLC0415  (only for this item)

    s = run.settings
    scene = run.scene()
    rx = receiver.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    shape = echo.pulse_shape(scene.laser.pulse_width_s, echo.A_FWHM, scene.detector.bandwidth_hz)
    energy = scene.laser.pulse_energy_j
    b_hz = scene.detector.bandwidth_hz
    distance = scene.pose.distance_m

    def gate(rng, arrivals, weights, n_total, tnr, gate_m):
        return montecarlo.scene_gate(
            rng, scene, rx, arrivals, weights, tnr=tnr, gate_m=gate_m, n_pixels_total=n_total
        )

    # P_d: single-surface pixels of known SNR through the discriminator; a short gate (10 m)
    snrs = np.array(FIG9_SNRS)
    i_pk = rx.peak_current_for_snr(snrs)
    n_each = s.mc_pd_trials
    tnr_mc = _mc_tnr_grid(s)
    pd_mc = np.zeros((len(snrs), len(tnr_mc)))
    weights = np.repeat(i_pk / (rx.responsivity_a_w * energy * shape.peak_w_per_j), n_each)
    for j, tnr in enumerate(tnr_mc):
        rng = run.rng(2, j)
        arrivals = 2.0 * rng.uniform(distance - 2.0, distance + 2.0, size=(len(weights), 1)) / C
        res = gate(rng, arrivals, weights[:, None], len(weights), float(tnr), 10.0)
        pd_mc[:, j] = res.detected.reshape(len(snrs), n_each).mean(axis=1)
        run.step(f"P_d Monte Carlo, TNR {tnr:g}")
    tnr_curve = np.linspace(0.0, 14.0, 281)
    pd_ours = np.array(
        [
            detection.detection_probability(i, tnr_curve * rx.sigma_n_a, rx.sigma_peak_a(i))
            for i in i_pk
        ]
    )
    pd_paper = np.array([detection.detection_probability_paper(v, tnr_curve) for v in snrs])
    pd_ours_at_mc = np.array(
        [
            detection.detection_probability(i, tnr_mc * rx.sigma_n_a, rx.sigma_peak_a(i))
            for i in i_pk
        ]
    )

    # false alarms: noise-only pixels over the whole 1 km gate
    fa_tnr = np.array(s.mc_fa_tnrs)
    fa_counts, fa_pixels = [], []
    for j, tnr in enumerate(fa_tnr):
        per_pixel = detection.false_alarms_per_pixel(tnr, FIG9_GATE_M, b_hz)
        n_px = int(min(s.mc_fa_max_pixels, math.ceil(s.mc_fa_target_count / per_pixel)))
        empty = np.zeros((0, 1))
        res = gate(run.rng(3, j), empty, empty, n_px, float(tnr), FIG9_GATE_M)
        fa_counts.append(res.n_false_alarms)
        fa_pixels.append(n_px)
        run.step(f"false-alarm Monte Carlo, TNR {tnr:g}")
    fa_counts = np.array(fa_counts, dtype=np.float64)
    fa_pixels = np.array(fa_pixels, dtype=np.float64)
    fa_mc = fa_counts / fa_pixels
    fa_curve_tnr = np.linspace(1.0, 8.0, 141)
    rice = detection.false_alarms_per_pixel(fa_curve_tnr, FIG9_GATE_M, b_hz)
    paper_12 = detection.false_alarms_per_pixel_paper(fa_curve_tnr, FIG9_GATE_M, FIG9_DF_HZ)
    paper_b = detection.false_alarms_per_pixel_paper(fa_curve_tnr, FIG9_GATE_M, b_hz)
    rice_pts = detection.false_alarms_per_pixel(fa_tnr, FIG9_GATE_M, b_hz)
    paper12_pts = detection.false_alarms_per_pixel_paper(fa_tnr, FIG9_GATE_M, FIG9_DF_HZ)
    paperb_pts = detection.false_alarms_per_pixel_paper(fa_tnr, FIG9_GATE_M, b_hz)

    fig = _figure(12.0, 4.8)
    ax_pd, ax_fa = fig.subplots(1, 2)
    for k, snr in enumerate(snrs):
        color = f"C{k}"
        ax_pd.plot(tnr_curve, pd_ours[k], color=color, lw=1.6, label=f"SNR {snr:g}: Eq. 27 ours")
        ax_pd.plot(tnr_curve, pd_paper[k], color=color, lw=1.2, ls="--")
        err = np.sqrt(np.maximum(pd_mc[k] * (1 - pd_mc[k]), 1.0 / n_each) / n_each)
        ax_pd.errorbar(tnr_mc, pd_mc[k], yerr=2 * err, fmt="o", ms=3.5, color=color, capsize=2)
    ax_pd.plot([], [], "k--", lw=1.2, label="Eq. 27 paper (thermal only)")
    ax_pd.plot([], [], "ko", ms=3.5, label=f"waveform Monte Carlo ({n_each} pixels, 2 sigma)")
    ax_pd.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax_pd.set_ylabel("detection probability P_d  [1]")
    ax_pd.set_xlim(0, 14)
    ax_pd.set_ylim(-0.03, 1.03)
    ax_pd.grid(alpha=0.3)
    ax_pd.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=3)
    ax_pd.set_title("Detection probability of a single surface")
    ax_fa.semilogy(fa_curve_tnr, rice, lw=1.8, color="C0", label="Eq. 28 ours (Rice, B = 120 MHz)")
    ax_fa.semilogy(
        fa_curve_tnr,
        paper_12,
        ls=":",
        lw=1.6,
        color="C3",
        label="Eq. 28 paper, df = 12 MHz (Fig. 9)",
    )
    ax_fa.semilogy(
        fa_curve_tnr, paper_b, ls="--", lw=1.4, color="C1", label="Eq. 28 paper, df = B = 120 MHz"
    )
    ax_fa.errorbar(
        fa_tnr,
        fa_mc,
        yerr=2.0 * np.sqrt(np.maximum(fa_counts, 1.0)) / fa_pixels,
        fmt="o",
        ms=4,
        color="k",
        capsize=2,
        label="waveform Monte Carlo (2 Poisson sigma)",
    )
    ax_fa.set_xlabel("TNR = V_T / sigma_n  [1]")
    ax_fa.set_ylabel("false alarms per pixel per pulse  [1]")
    ax_fa.set_title(f"False alarms in a {FIG9_GATE_M / 1e3:g} km range gate")
    ax_fa.set_ylim(1e-6, 1e3)
    ax_fa.grid(alpha=0.3, which="both")
    ax_fa.legend(fontsize=7.5, loc="upper right")
    fig.suptitle(
        "P_d and false alarms against TNR (paper Figure 9): curves = statistical model, points = "
        "noisy waveforms through the CFD discriminator"
    )
    figure = run.save(fig, "fig09_detection.png")
    run.step("Figure 9")
    return {
        "paper_figure": "Figure 9",
        "figures": [figure],
        "scenes": {"receiver": scene.to_dict()},
        "gate_m": FIG9_GATE_M,
        "paper_df_hz": FIG9_DF_HZ,
        "bandwidth_hz": b_hz,
        "sigma_n_a": rx.sigma_n_a,
        "p_detect": {
            "snr": snrs.tolist(),
            "peak_current_a": i_pk.tolist(),
            "tnr_curve": tnr_curve.tolist(),
            "eq27_ours": pd_ours.tolist(),
            "eq27_paper": pd_paper.tolist(),
            "tnr_mc": tnr_mc.tolist(),
            "montecarlo": pd_mc.tolist(),
            "montecarlo_trials": n_each,
            "eq27_ours_at_mc": pd_ours_at_mc.tolist(),
            "max_abs_mc_minus_eq27_ours": float(np.abs(pd_mc - pd_ours_at_mc).max()),
        },
        "false_alarms": {
            "tnr_curve": fa_curve_tnr.tolist(),
            "eq28_ours_rice": rice.tolist(),
            "eq28_paper_df12mhz": paper_12.tolist(),
            "eq28_paper_df_bandwidth": paper_b.tolist(),
            "tnr_mc": fa_tnr.tolist(),
            "montecarlo_count": fa_counts.astype(int).tolist(),
            "montecarlo_pixels": fa_pixels.astype(int).tolist(),
            "montecarlo_per_pixel": fa_mc.tolist(),
            "mc_over_rice": (fa_mc / rice_pts).tolist(),
            "mc_over_paper_df12mhz": (fa_mc / paper12_pts).tolist(),
            "mc_over_paper_df_bandwidth": (fa_mc / paperb_pts).tolist(),
        },
    }


# ----------------------------------------------------------------------------------------------
# 3. single-pixel waveforms (Figure 14)
# ----------------------------------------------------------------------------------------------
def _subray_parts(result: Result) -> dict[int, np.ndarray]:
    """Flat pixel index -> part index of each sub-ray's first hit (-1 for a miss)."""
    face_part = result.target.face_part
    parts = {}
    for block in result.hits.blocks():
        part = np.where(block.face >= 0, face_part[np.maximum(block.face, 0)], -1)
        parts.update(zip(block.pixel.tolist(), part, strict=True))
    return parts


def _n_peaks(y: np.ndarray, fraction: float = 0.15) -> int:
    """Local maxima of ``y`` at least ``fraction`` of its maximum high and as prominent."""
    top = float(np.max(y)) if len(y) else 0.0
    if top <= 0:
        return 0
    peaks, _ = signal.find_peaks(y, height=fraction * top, prominence=fraction * top)
    return len(peaks)


def _delay_rms_s(arrivals_s: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n,) weighted rms spread of each pixel's sub-ray delays [s] (weights (n, K) >= 0)."""
    w = np.asarray(weights, dtype=np.float64)
    total = np.maximum(w.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    mean = (w * arrivals_s).sum(axis=1, keepdims=True) / total
    return np.sqrt((w * (arrivals_s - mean) ** 2).sum(axis=1) / total[:, 0])


def _find_pixels(result: Result) -> dict[str, Any]:
    """The two pixels of Figure 14, found in the echo data.

    ``double_peak``: the largest depth span (Eq. 29 delays) whose band-limited echo has two peaks,
    preferring a pixel that sees the dish (part ``cover``) and another part (the bus);
    ``dish``: all sub-rays on ``cover``, one peak, the largest weighted rms delay spread.
    """
    e = result.echo
    names = result.target.part_names
    cover = names.index("cover") if "cover" in names else -1
    parts = _subray_parts(result)
    has = e.weights > 0
    arrivals = np.where(has, e.arrivals_s, 0.0)
    span_s = np.where(has, arrivals, -np.inf).max(axis=1) - np.where(has, arrivals, np.inf).min(
        axis=1
    )
    rms_s = _delay_rms_s(arrivals, e.weights)

    def peaks(i):
        _, _, y = echo.echo_waveform(e.shape, e.arrivals_s[i], e.weights[i], e.dt_s)
        return _n_peaks(y)

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
    found = {}
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


def _plot_waveform(ax, result: Result, info: dict[str, Any], title: str) -> dict[str, Any]:
    """Draw one pixel's echo (raw, band-limited, emitted pulse, threshold, timing, the sub-ray
    delays of Eq. 29) on ``ax``; return its numbers."""
    e = result.echo
    wf = result.waveform(info["row"], info["col"])
    t0 = 2.0 * result.scene.pose.distance_m / C
    t_ns = (wf.t_s - t0) * 1e9
    i = info["index"]
    has = e.weights[i] > 0
    # the emitted pulse, band-limited, scaled to the echo's peak and delayed by the true range
    emitted_ns = (wf.emitted_t_s + 2.0 * wf.range_true_m / C - t0) * 1e9
    scale = 1e6  # W -> uW
    top = scale * float(wf.filtered_w.max())
    ax.plot(t_ns, scale * wf.power_w, color="0.55", lw=1.0, label="P_r(t), before the band limit")
    ax.plot(t_ns, scale * wf.filtered_w, color="C0", lw=1.8, label="y(t), band-limited (120 MHz)")
    ax.plot(
        emitted_ns,
        scale * wf.emitted_w,
        color="C3",
        lw=1.2,
        ls="--",
        label="emitted pulse, band-limited, scaled, delayed to R",
    )
    ax.axhline(scale * wf.threshold_w, color="k", lw=0.8, ls=":", label="threshold TNR sigma_n")
    ax.axvline((wf.t_half_s - t0) * 1e9, color="C2", lw=0.9, label="half-maximum time (Eq. 31)")
    w = e.weights[i][has]
    ax.vlines((e.arrivals_s[i][has] - t0) * 1e9, 0.0, 0.25 * top * w / w.max(), color="C1", lw=0.6)
    ax.plot([], [], color="C1", lw=0.6, label="sub-ray delays 2 r_k / c and weights (Eq. 29)")
    ax.set_ylim(-0.03 * top, 1.75 * top)
    ax.set_xlabel("time after 2 D / c  [ns]   (D = 500 m, the target centre)")
    ax.set_ylabel("received power [uW]")
    metres = ax.secondary_xaxis("top", functions=(lambda t: 0.5e-9 * C * t, lambda r: 2e9 * r / C))
    metres.set_xlabel("range behind the target centre [m]", fontsize=8)
    metres.tick_params(labelsize=7)
    n_peaks = _n_peaks(wf.filtered_w)
    fwhm, ref_fwhm = _fwhm_s(wf.t_s, wf.filtered_w), _fwhm_s(wf.emitted_t_s, wf.emitted_w)
    ax.set_title(
        f"{title}\npixel (row {info['row']}, col {info['col']}): {' + '.join(info['parts'])}, "
        f"SNR {float(result.receiver.snr[i]):.0f}\n"
        f"depth span {info['depth_span_m']:.2f} m, rms {info['depth_rms_m']:.3f} m; {n_peaks} "
        f"peak(s); FWHM {1e9 * fwhm:.2f} ns (pulse {1e9 * ref_fwhm:.2f} ns)",
        fontsize=8.5,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    return {
        **info,
        "n_peaks": n_peaks,
        "snr": float(result.receiver.snr[i]),
        "peak_power_w": float(result.receiver.peak_power_w[i]),
        "range_true_m": wf.range_true_m,
        "range_m": wf.range_m,
        "fwhm_s": fwhm,
        "emitted_fwhm_s": ref_fwhm,
        "fwhm_ratio": fwhm / ref_fwhm,
        "t_s": wf.t_s.tolist(),
        "power_w": wf.power_w.tolist(),
        "filtered_w": wf.filtered_w.tolist(),
        "arrivals_s": e.arrivals_s[i][has].tolist(),
        "weights_per_j": w.tolist(),
    }


def _fwhm_s(t_s: np.ndarray, y: np.ndarray) -> float:
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


def _item_waveforms(run: _Run) -> dict[str, Any]:
    scene = run.scene({"preset": "reference", "pixels": run.settings.waveform_pixels})
    result = run.run(scene)
    found = _find_pixels(result)
    run.step("waveform pixels")
    fig = _figure(15.0, 4.8)
    ax_img, ax_a, ax_b = fig.subplots(1, 3, width_ratios=(0.8, 1.0, 1.0))
    rng_img = result.range_image_m - scene.pose.distance_m
    im = ax_img.imshow(rng_img, cmap="viridis", interpolation="nearest")
    fig.colorbar(im, ax=ax_img, shrink=0.8, label="range - 500 m [m]")
    ax_img.set_title("range image (front view), the two pixels", fontsize=9)
    ax_img.set_xlabel("column")
    ax_img.set_ylabel("row")
    numbers: dict[str, Any] = {}
    for ax, key, title, marker in (
        (ax_a, "double_peak", "Dish rim over the bus", "o"),
        (ax_b, "dish", "Curved dish, largest single-surface spread", "s"),
    ):
        info = found[key]
        if info is None:
            ax.set_title(f"{title}: no such pixel in this view")
            numbers[key] = None
            continue
        ax_img.plot(
            info["col"], info["row"], marker, mfc="none", mec="red", ms=10, mew=1.6, label=title
        )
        numbers[key] = _plot_waveform(ax, result, info, title)
    ax_img.legend(fontsize=7, loc="lower right")
    fig.suptitle(
        "Single-pixel echoes on the MRO at 500 m, 8 x 8 sub-rays per pixel (paper Figure 14)"
    )
    _credit(fig, result.target.credit)
    figure = run.save(fig, "fig14_waveforms.png")
    run.step("Figure 14")
    return {
        "paper_figure": "Figure 14",
        "figures": [figure],
        "scenes": {"waveforms": scene.to_dict()},
        "summary": _run_summary(result),
        "pixels": numbers,
    }


# ----------------------------------------------------------------------------------------------
# 4. point clouds over pitch and azimuth (Figures 16, 17)
# ----------------------------------------------------------------------------------------------
def _item_attitude(run: _Run) -> dict[str, Any]:
    s = run.settings
    out: dict[str, Any] = {"paper_figure": "Figures 16, 17", "figures": [], "scenes": {}}
    for key, fig_name, paper_fig in (
        ("pitch_deg", "fig16_pitch.png", "Figure 16"),
        ("azimuth_deg", "fig17_azimuth.png", "Figure 17"),
    ):
        steps = s.attitude_steps_deg
        panel_in = 3.0
        fig = _figure(panel_in * len(steps) + 0.6, 2 * panel_in + 1.4)
        axes = fig.subplots(2, len(steps), squeeze=False)
        present: set[int] = set()
        rows = []
        credit = None
        for j, angle in enumerate(steps):
            scene = run.scene({key: angle, "pixels": s.cloud_pixels})
            result = run.run(scene)
            label = f"{key.split('_')[0]} {angle:g} deg"
            present |= _draw_cloud(axes[0, j], axes[1, j], result, label, panel_in)
            credit = result.target.credit
            out["scenes"][f"{key}={angle:g}"] = scene.to_dict()
            rows.append(
                {
                    key: angle,
                    **_run_summary(result),
                    "per_material": _per_material(result),
                }
            )
            run.step(label)
        _material_legend(fig, present, True, credit)
        fig.suptitle(
            f"MRO at 500 m, {s.cloud_pixels} x {s.cloud_pixels} pixels: {key.split('_')[0]} steps, "
            f"front view (top row) and top view (bottom row) ({paper_fig})\n{_CLOUD_NOTE}",
        )
        out["figures"].append(run.save(fig, fig_name))
        out[key.split("_")[0]] = rows
        run.step(f"{paper_fig}")
    return out


# ----------------------------------------------------------------------------------------------
# 5. pixel count and distance (Figures 18-20)
# ----------------------------------------------------------------------------------------------
def _item_resolution(run: _Run) -> dict[str, Any]:
    panel_in = 2.9
    fig = _figure(panel_in * len(RESOLUTION_PIXELS) + 0.4, panel_in * 2 + 1.9)
    axes = fig.subplots(len(RESOLUTION_DISTANCES_M), len(RESOLUTION_PIXELS), squeeze=False)
    table, scenes = [], {}
    present: set[int] = set()
    credit = None
    base = run.scene()
    for i, distance in enumerate(RESOLUTION_DISTANCES_M):
        optics = _matched_fov(distance, base.laser.divergence_rad)
        for j, pixels in enumerate(RESOLUTION_PIXELS):
            scene = run.scene({"distance_m": distance, "pixels": pixels, **optics})
            result = run.run(scene)
            credit = result.target.credit
            label = f"{distance:g} m, {pixels} x {pixels}"
            scenes[label] = scene.to_dict()
            summary = _run_summary(result)
            table.append(
                {
                    "distance_m": distance,
                    "pixels": pixels,
                    "fov_rad": optics["receive.fov_rad"],
                    "beam_expansion_ratio": optics["transmit.beam_expansion_ratio"],
                    "footprint_m": distance * scene.ifov_rad,
                    **summary,
                }
            )
            ax = axes[i, j]
            present |= _draw_cloud(ax, None, result, label, panel_in)
            ax.set_title(
                f"{label}: {summary['n_target_points']} points\n"
                f"footprint {100 * distance * scene.ifov_rad:.1f} cm, SNR median "
                f"{summary['snr_median']:.0f}",
                fontsize=8,
            )
            run.step(label)
    _material_legend(fig, present, True, credit)
    fig.suptitle(
        "Front views at 32 to 256 pixels per side, 500 m (top) and 1000 m (bottom) (paper "
        "Figures 18-20)\nfield of view 2 atan(1.1 x 7.5 m / R) and illumination cone matched to "
        "it; false alarms over the 1 km gate (in view: inside the panel's 18 m cube)"
    )
    figure = run.save(fig, "fig18_20_resolution.png")
    run.step("Figures 18-20")
    return {
        "paper_figure": "Figures 18-20",
        "figures": [figure],
        "scenes": scenes,
        "fov_rule": "fov = 2 atan(1.1 * 7.5 m / R); beam_expansion_ratio = divergence / fov",
        "point_counts": table,
    }


# ----------------------------------------------------------------------------------------------
# 6. the fly-around (Figures 7, 24)
# ----------------------------------------------------------------------------------------------
def _item_flyaround(run: _Run) -> dict[str, Any]:
    s = run.settings
    stats = orbit.distance_stats(orbit.PAPER_TARGET, orbit.PAPER_IMAGING)
    base = run.scene()
    optics = _matched_fov(stats["min_m"], base.laser.divergence_rad)
    scene = run.scene(
        {
            "name": f"paper, {FLYAROUND_ENERGY_J * 1e3:g} mJ, field of view "
            f"{optics['receive.fov_rad'] * 1e3:.1f} mrad",
            "pulse_energy_j": FLYAROUND_ENERGY_J,
            "pixels": s.flyaround_pixels,
            **optics,
        }
    )
    times = orbit.flyaround_times(s.flyaround_interval_s, PAPER_PERIOD_S)
    fly = run_flyaround(scene, times, pipeline=run.pipeline, progress=False)
    run.step("fly-around orbit")
    for _ in range(len(times) - 1):
        run.step("fly-around frames")
    curve = "fig07_flyaround.png"
    plot_flyaround(fly, run.out / curve)
    run.step("Figure 7")

    panel_in = 3.0
    fig = _figure(panel_in * len(FLYAROUND_FRAMES_S) + 0.6, 2 * panel_in + 1.4)
    axes = fig.subplots(2, len(FLYAROUND_FRAMES_S), squeeze=False)
    present: set[int] = set()
    frames = []
    credit = None
    for j, t_s in enumerate(FLYAROUND_FRAMES_S):
        i = int(np.argmin(np.abs(fly.t_s - t_s)))
        if abs(fly.t_s[i] - t_s) > 1e-6:
            raise RuntimeError(f"frame at t = {t_s:g} s is not on the fly-around's time grid")
        frame_scene = with_overrides(
            scene,
            {
                "pose.quaternion_wxyz": fly.pose.quaternion_wxyz[i].tolist(),
                "distance_m": float(fly.pose.distance_m[i]),
            },
        )
        result = run.run(frame_scene)
        credit = result.target.credit
        label = f"t = {t_s:g} s, {fly.pose.distance_m[i]:.1f} m"
        present |= _draw_cloud(axes[0, j], axes[1, j], result, label, panel_in)
        frames.append(
            {
                "t_s": t_s,
                "distance_m": float(fly.pose.distance_m[i]),
                "angles_deg": fly.pose.angles_deg[i].tolist(),
                **_run_summary(result),
            }
        )
        run.step(label)
    _material_legend(fig, present, True, credit)
    fig.suptitle(
        f"Fly-around frames (paper Figure 24): Table 3 orbits, {FLYAROUND_ENERGY_J * 1e3:g} mJ, "
        f"{s.flyaround_pixels} x {s.flyaround_pixels} pixels, field of view "
        f"{optics['receive.fov_rad'] * 1e3:.1f} mrad\n{_CLOUD_NOTE}"
    )
    figure = run.save(fig, "fig24_frames.png")
    run.step("Figure 24")
    records = [{k: v for k, v in r.items() if k not in ("frame_s", "ply")} for r in fly.records]
    return {
        "paper_figure": "Figures 7, 24",
        "figures": [curve, figure],
        "scenes": {"flyaround": scene.to_dict()},
        "paper_period_s": PAPER_PERIOD_S,
        "two_body_period_s": orbit.PAPER_TARGET.period_s,
        "distance_stats_m": stats,
        "paper_distance_m": {"section_2_2_2": 200.0, "section_4_2": 500.0},
        "interval_s": s.flyaround_interval_s,
        "records": records,
        "frames": frames,
    }


# ----------------------------------------------------------------------------------------------
# 7. the conventions table
# ----------------------------------------------------------------------------------------------
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
    "n_points",
    "depth_extent_m",
)


def _convention_row(result: Result) -> dict[str, Any]:
    summary = _run_summary(result)
    attrs = result.attributes
    tgt = ~attrs["is_outlier"]
    r = attrs["range_m"][tgt]
    extent = float(np.percentile(r, 99) - np.percentile(r, 1)) if len(r) else None
    row = {k: summary[k] for k in CONVENTION_COLUMNS if k in summary}
    row["peak_current_median_a"] = _finite_median(result.receiver.i_pk_a)
    d = result.detection
    sigma_t = timing.sigma_quantisation_m(result.scene.timing.resolution_s)
    cfd = np.sqrt(np.maximum(d.range_sigma_m[d.detected] ** 2 - sigma_t**2, 0.0))
    row["range_sigma_cfd_m_median"] = _finite_median(cfd)  # Eq. 25 alone (Eq. 24 minus Eq. 26)
    row["depth_extent_m"] = extent
    return {k: row[k] for k in CONVENTION_COLUMNS}


def _item_conventions(run: _Run) -> dict[str, Any]:
    s = run.settings
    variants = [("ours", {})]
    variants += [(form, {"paper_forms": [form]}) for form in PAPER_FORMS]
    variants.append(("paper (all)", {"conventions": "paper"}))
    rows, scenes = [], {}
    ours = None
    for name, overrides in variants:
        scene = run.scene({"pixels": s.cloud_pixels, **overrides})
        result = run.run(scene)
        row = {"form": name, **_convention_row(result)}
        if ours is None:
            ours = row
        row["ratio_to_ours"] = {
            k: (row[k] / ours[k] if ours[k] not in (0, None) and row[k] is not None else None)
            for k in CONVENTION_COLUMNS
        }
        rows.append(row)
        scenes[name] = scene.to_dict()
        run.step(f"conventions: {name}")

    labels = [r["form"] for r in rows[1:]]
    metrics = (
        ("snr_median", "SNR median"),
        ("range_sigma_m_median", "range sigma median (Eq. 24)"),
        ("range_sigma_cfd_m_median", "CFD part of it (Eq. 25)"),
        ("n_target_points", "target points"),
        ("n_false_expected", "false alarms (expected)"),
        ("depth_extent_m", "depth extent (1-99 %)"),
    )
    fig = _figure(11.0, 7.0)
    ax = fig.subplots()
    y = np.arange(len(labels))
    height = 0.84 / len(metrics)
    for k, (key, label) in enumerate(metrics):
        ratio = np.array([r["ratio_to_ours"][key] or np.nan for r in rows[1:]], dtype=float)
        yk = y + (k - (len(metrics) - 1) / 2) * height
        ax.barh(yk, ratio - 1.0, height, left=1.0, label=label, color=f"C{k}")
        for yy, v in zip(yk, ratio, strict=True):
            if np.isfinite(v) and abs(v - 1.0) > 0.005:
                ax.text(
                    v * (1.04 if v > 1 else 0.96),
                    yy,
                    f"{v:.2f}",
                    va="center",
                    ha="left" if v > 1 else "right",
                    fontsize=6.5,
                )
    ax.set_xscale("log", base=2)
    ax.set_xlim(1 / 8, 8)
    ticks = [1 / 8, 1 / 4, 1 / 2, 1, 2, 4, 8]
    ax.set_xticks(ticks, ["1/8", "1/4", "1/2", "1", "2", "4", "8"])
    ax.minorticks_off()
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(y, labels)
    ax.invert_yaxis()
    ax.set_xlabel("paper form / ours  (log scale; 1 = no change)")
    ax.grid(alpha=0.3, axis="x", which="both")
    ax.legend(fontsize=8, loc="center right")
    ax.set_title(
        f"Each paper-literal form alone against ours, paper scene ({s.cloud_pixels} x "
        f"{s.cloud_pixels} pixels, 500 m, front view)"
    )
    figure = run.save(fig, "conventions.png")
    run.step("conventions figure")
    return {
        "paper_figure": "Equations 1, 14, 25, 27-30 (PHYSICS.md)",
        "figures": [figure],
        "scenes": scenes,
        "columns": list(CONVENTION_COLUMNS),
        "rows": rows,
    }


# ----------------------------------------------------------------------------------------------
# the command line
# ----------------------------------------------------------------------------------------------
def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``reproduce`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    rep = subparsers.add_parser(
        "reproduce",
        help="regenerate the paper's figures from the simulator (PNGs + report.json)",
        description="Regenerate each of the paper's results with the simulator, side by side with "
        "the paper's own forms: DIR/*.png and DIR/report.json (every number, scene, seed, "
        "version). See docs/reproduction.md.",
    )
    rep.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    rep.add_argument(
        "--quick", action="store_true", help="fewer pixels and Monte Carlo trials (a draft)"
    )
    rep.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    rep.set_defaults(func=run_cli)
    return rep


def run_cli(args: argparse.Namespace) -> int:
    """Run ``lmapd reproduce``; return the exit status (0). User errors raise CliError."""
    from .cli import CliError, say  # noqa: PLC0415  (cli imports this module)

    start = time.perf_counter()
    if args.seed < 0:
        raise CliError(f"--seed must be a whole number >= 0, got {args.seed}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {str(out)!r} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CliError(f"--out {str(out)!r}: cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise CliError(f"--out {str(out)!r}: the folder is not writable")
    report = run_reproduction(out, quick=args.quick, seed=args.seed, progress=True)
    say(
        f"{len(report['items'])} items, {len(report['figures'])} figures and {REPORT_NAME} "
        f"-> {out}/  [{time.perf_counter() - start:.1f} s]"
    )
    return 0
