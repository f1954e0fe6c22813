"""``lmapd bench --tradeoff``: each fidelity preset's time against its error relative to
``reference``, on the paper scene at several attitudes (oblique solar panels included).

Errors compare noise-free quantities, so that they measure the model and not the random draw:
range RMSE over the pixels lit in both runs (the Eq. 31 range, which carries the waveform bias),
the expected point count (sum of P_d), and the relative L2 error of the band-limited waveforms.

Each frame is followed by its floor, the ray cast alone: every ray the preset's hits stage cast
for it (the base sub-rays, the pixel corners where the preset probes them, the refined pixels'
sub-rays), cast again in one call (:func:`simcore.cli.bench.stages.ray_cast_s`).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ... import geometry
from ...echo import echo_waveform
from ...io import atomic_path, write_json
from ...pipeline import Pipeline, Result
from ...scene import PRESETS, load_scene, with_overrides
from ...target import load_target
from ..common import say
from .stages import ray_cast_s

ATTITUDES = (
    {"pitch_deg": 0.0, "azimuth_deg": 0.0},  # the paper's front view
    {"pitch_deg": 30.0, "azimuth_deg": 0.0},
    {"pitch_deg": 0.0, "azimuth_deg": 60.0},  # solar panels at 60 deg incidence
    {"pitch_deg": 45.0, "azimuth_deg": 30.0},
    {"pitch_deg": 70.0, "azimuth_deg": 0.0},  # panels near grazing
)
WAVEFORM_SAMPLE = 300  # pixels per attitude for the waveform error


def _frame(pipe: Pipeline, scene, i: int, caster) -> tuple[Result, float, float]:
    """One full frame (the pose stages re-run: the pose is nudged between calls), its wall
    time [s] and then the wall time of its ray cast alone [s]."""
    nudged = with_overrides(scene, {"pose.roll_deg": 1e-6 * (i % 2)})
    t0 = time.perf_counter()
    result = pipe.run(nudged)
    wall = time.perf_counter() - t0
    return result, wall, ray_cast_s(caster, frame_rays(nudged, result), nudged)


def frame_rays(scene, result: Result) -> np.ndarray:
    """(n, 3) unit sensor-frame directions of every ray the hits stage cast for ``result``: the
    base sub-rays, the pixel corners if the scene probes them, the refined pixels' sub-rays."""
    rays = result.rays
    parts = [rays.directions.reshape(-1, 3)]
    if scene.fidelity.refine_subrays > rays.subrays:
        if scene.fidelity.probe_corners:
            parts.append(geometry.corner_directions(rays.pixels, rays.fov_rad))
        refined = result.hits.refined_pixels
        if len(refined):
            dirs = geometry.subray_directions(
                rays.pixels, rays.fov_rad, scene.fidelity.refine_subrays, refined
            )
            parts.append(dirs.reshape(-1, 3))
    return np.concatenate(parts)


def waveform_l2_error(result: Result, reference: Result, pixels, rng) -> float:
    """Relative L2 error of band-limited echoes of common pixels, on the reference's windows."""
    sample = rng.choice(pixels, size=min(WAVEFORM_SAMPLE, len(pixels)), replace=False)
    num = den = 0.0
    for p in sample:
        i, j = np.searchsorted(result.echo.pixel, p), np.searchsorted(reference.echo.pixel, p)
        e, r = result.echo, reference.echo
        t, _, y_ref = echo_waveform(r.shape, r.arrivals_s[j], r.weights[j], r.dt_s)
        tau = t[:, None] - e.arrivals_s[i][None, :]
        y = e.shape.filtered_at(tau) @ e.weights[i]
        num += float(np.sum((y - y_ref) ** 2))
        den += float(np.sum(y_ref**2))
    return float(np.sqrt(num / den)) if den > 0 else 0.0


def compare(result: Result, reference: Result, rng) -> dict:
    common = np.intersect1d(result.echo.pixel, reference.echo.pixel)
    i = np.searchsorted(result.echo.pixel, common)
    j = np.searchsorted(reference.echo.pixel, common)
    err = result.detection.range_true_m[i] - reference.detection.range_true_m[j]
    n_ref = float(reference.detection.p_detect.sum())
    n = float(result.detection.p_detect.sum())
    return {
        "range_rmse_m": float(np.sqrt(np.mean(err**2))) if len(err) else 0.0,
        "range_p99_m": float(np.percentile(np.abs(err), 99)) if len(err) else 0.0,
        "point_count_diff_pct": 100.0 * (n - n_ref) / n_ref if n_ref else 0.0,
        "waveform_l2": waveform_l2_error(result, reference, common, rng),
        "refined_pixels": int(len(result.hits.refined_pixels)),
        "lit_pixels": int(len(result.echo.pixel)),
        # of the pixels that echo, the share cast again with the reference's sub-rays
        "refined_share": len(np.intersect1d(result.hits.refined_pixels, result.echo.pixel))
        / max(len(result.echo.pixel), 1),
    }


def run(repeats: int = 5, pixels: int = 256) -> dict:
    """Each preset's median frame time and errors at each attitude. The presets' frames are
    interleaved (one of each per round, ``repeats`` rounds), so that a slow spell of a shared
    machine slows them all and not one preset's figure."""
    base = with_overrides(load_scene(), {"pixels": pixels})
    order = ("reference", *(p for p in PRESETS if p != "reference"))
    pipes = {p: Pipeline() for p in order}  # one cache each: a frame re-runs only the pose stages
    for preset, pipe in pipes.items():
        pipe.run(with_overrides(base, {"preset": preset}))  # mesh, BVH and ray grid, once
    caster = geometry.RayCaster(load_target(base.target))  # the floor's (the same BVH)
    rng = np.random.default_rng(0)
    rows = []
    progress = tqdm(total=len(ATTITUDES) * repeats, desc="trade-off", unit="round", file=sys.stderr)
    for att in ATTITUDES:
        scenes = {p: with_overrides(base, {"preset": p, **att}) for p in order}
        times: dict[str, list[float]] = {p: [] for p in order}
        casts: dict[str, list[float]] = {p: [] for p in order}
        stages: dict[str, list[dict]] = {p: [] for p in order}
        results = {}
        for i in range(repeats):
            for preset in order:
                results[preset], wall, cast = _frame(pipes[preset], scenes[preset], i + 1, caster)
                times[preset].append(wall)
                casts[preset].append(cast)
                stages[preset].append(results[preset].timings_s)
            progress.update()
        ref_time = statistics.median(times["reference"])
        for preset in order:
            wall = statistics.median(times[preset])
            row = {"preset": preset, **att, "time_s": wall, "speedup": ref_time / wall}
            row["ray_cast_s"] = statistics.median(casts[preset])
            row["rays"] = int(len(frame_rays(scenes[preset], results[preset])))
            for stage in ("hits", "echo"):  # where the time goes: rays, then echoes
                row[f"{stage}_s"] = statistics.median(t[stage] for t in stages[preset])
            row.update(compare(results[preset], results["reference"], rng))
            rows.append(row)
    progress.close()
    return {"pixels": pixels, "scene": "paper", "presets": PRESETS, "rows": rows}


def summary(fig: dict) -> list[dict]:
    """Per preset: median time and speed-up, worst range RMSE and count difference."""
    out = []
    for preset in dict.fromkeys(r["preset"] for r in fig["rows"]):
        rows = [r for r in fig["rows"] if r["preset"] == preset]
        out.append(
            {
                "preset": preset,
                "time_s": statistics.median(r["time_s"] for r in rows),
                "speedup_min": min(r["speedup"] for r in rows),
                "speedup_median": statistics.median(r["speedup"] for r in rows),
                "range_rmse_m_max": max(r["range_rmse_m"] for r in rows),
                "range_rmse_m_median": statistics.median(r["range_rmse_m"] for r in rows),
                "point_count_diff_pct_max": max(abs(r["point_count_diff_pct"]) for r in rows),
                "waveform_l2_max": max(r["waveform_l2"] for r in rows),
                "hits_s": statistics.median(r["hits_s"] for r in rows),
                "echo_s": statistics.median(r["echo_s"] for r in rows),
                "ray_cast_s": statistics.median(r["ray_cast_s"] for r in rows),
                "ray_cast_s_min": min(r["ray_cast_s"] for r in rows),
                "ray_cast_s_max": max(r["ray_cast_s"] for r in rows),
                "time_s_min": min(r["time_s"] for r in rows),
                "time_s_max": max(r["time_s"] for r in rows),
                "refined_share_max": max(r["refined_share"] for r in rows),
            }
        )
    return out


def plot(fig: dict, path: Path) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    colours = {"interactive": "tab:orange", "balanced": "tab:blue", "reference": "black"}
    markers = "osD^v"
    f, ax = plt.subplots(figsize=(10, 5))
    for k, att in enumerate(ATTITUDES):
        for r in (
            r
            for r in fig["rows"]
            if r["pitch_deg"] == att["pitch_deg"]
            and r["azimuth_deg"] == att["azimuth_deg"]
            and r["preset"] != "reference"
        ):
            y = max(r["range_rmse_m"] * 1e3, 1e-3)
            c = colours[r["preset"]]
            ax.scatter(r["time_s"] * 1e3, y, color=c, marker=markers[k], s=50)
            if "ray_cast_s" in r:  # the floor: this frame's rays cast alone, joined to the frame
                ax.plot([r["ray_cast_s"] * 1e3, r["time_s"] * 1e3], [y, y], color=c, lw=0.7)
                ax.scatter(r["ray_cast_s"] * 1e3, y, color=c, marker="|", s=90)
        ref = next(
            r
            for r in fig["rows"]
            if r["preset"] == "reference"
            and r["pitch_deg"] == att["pitch_deg"]
            and r["azimuth_deg"] == att["azimuth_deg"]
        )
        ax.axvline(ref["time_s"] * 1e3, color="0.8", lw=0.8)
    for preset, c in colours.items():
        ax.scatter(
            [],
            [],
            color=c,
            label=preset if preset != "reference" else "reference time (grey lines)",
        )
    for k, att in enumerate(ATTITUDES):
        ax.scatter(
            [],
            [],
            color="0.4",
            marker=markers[k],
            label=f"pitch {att['pitch_deg']:.0f}, azimuth {att['azimuth_deg']:.0f} deg",
        )
    ref_rows = [r for r in fig["rows"] if r["preset"] == "reference"]
    ref_time = statistics.median(r["time_s"] for r in ref_rows)
    if all("ray_cast_s" in r for r in fig["rows"]):
        ax.scatter([], [], color="0.4", marker="|", s=90, label="its rays cast alone (floor)")
        ref_cast = statistics.median(r["ray_cast_s"] for r in ref_rows)
        ax.axvline(ref_cast * 1e3, color="black", ls="-.", lw=1)
        ax.plot([], [], color="black", ls="-.", lw=1, label="reference's rays cast alone")
    goals = (("interactive", 20.0, 5.0), ("balanced", 5.0, 2.0))  # the targets
    for preset, speedup, rmse_mm in goals:
        c = colours[preset]
        ax.axvline(ref_time / speedup * 1e3, color=c, ls=":", lw=1)
        ax.axhline(rmse_mm, color=c, ls=":", lw=1)
        ax.plot(
            [], [], color=c, ls=":", label=f"{preset} goal: {speedup:g}x faster, {rmse_mm:g} mm"
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    n = fig["pixels"]
    ax.set_xlabel(f"wall time per frame [ms] ({n} x {n} pixels, 2-core machine)")
    ax.set_ylabel("range RMSE against reference [mm]")
    ax.set_title("Speed against accuracy: fidelity presets on the MRO (NASA/JPL-Caltech model)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    f.tight_layout()
    with atomic_path(path) as tmp:
        f.savefig(tmp, dpi=110, format="png")
    plt.close(f)


def main(out_dir: str, quick: bool = False, pixels: int | None = None) -> int:
    """Run the trade-off bench (``pixels`` per side: default 256, the paper's array, or 128 with
    ``quick``), write DIR/tradeoff.json and DIR/tradeoff.png, print the summary table."""
    n = pixels or (128 if quick else 256)
    with_overrides(load_scene(), {"pixels": n})  # an invalid size is refused before any work
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig = run(repeats=1 if quick else 5, pixels=n)
    fig["summary"] = summary(fig)
    write_json(out / "tradeoff.json", fig)
    plot(fig, out / "tradeoff.png")
    say(f"{n} x {n} pixels, the paper scene at {len(ATTITUDES)} attitudes:")
    say(
        "| preset | median time (ms): all / hits / echo | ray cast alone (ms) | frame / ray cast "
        "| speed-up vs reference (min / median) | range RMSE max (mm) | point count diff max (%) "
        "| waveform L2 max | refined share of lit pixels, max |"
    )
    say("|---|---|---|---|---|---|---|---|---|")
    for s in fig["summary"]:
        say(
            f"| {s['preset']} | {s['time_s'] * 1e3:.0f} / {s['hits_s'] * 1e3:.0f} / "
            f"{s['echo_s'] * 1e3:.0f} | {s['ray_cast_s'] * 1e3:.0f} "
            f"({s['ray_cast_s_min'] * 1e3:.0f}-{s['ray_cast_s_max'] * 1e3:.0f}) | "
            f"{s['time_s'] / s['ray_cast_s']:.1f} | "
            f"{s['speedup_min']:.1f} / {s['speedup_median']:.1f} | "
            f"{s['range_rmse_m_max'] * 1e3:.2f} | {s['point_count_diff_pct_max']:.2f} | "
            f"{s['waveform_l2_max']:.4f} | {s['refined_share_max']:.0%} |"
        )
    say(f"-> {out / 'tradeoff.json'}, {out / 'tradeoff.png'}")
    return 0
