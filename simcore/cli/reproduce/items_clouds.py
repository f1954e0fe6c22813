"""The items of ``lmapd reproduce`` about whole point clouds: attitude steps (Figures 16, 17),
resolution (Figures 18-20), the fly-around (Figures 7, 24) and the conventions table."""

from __future__ import annotations

from typing import Any

import numpy as np

from ... import orbit
from ...flyaround import run_flyaround
from ...reproduce import (
    CONVENTION_COLUMNS,
    FLYAROUND_ENERGY_J,
    FLYAROUND_FRAMES_S,
    PAPER_PERIOD_S,
    RESOLUTION_DISTANCES_M,
    RESOLUTION_PIXELS,
    convention_row,
    matched_fov,
    per_material,
    run_summary,
)
from ...scene import PAPER_FORMS, with_overrides
from ..flyaround import plot_flyaround
from .draw import CLOUD_NOTE, draw_cloud, material_legend, new_figure
from .run import ReproduceRun


def item_attitude(run: ReproduceRun) -> dict[str, Any]:
    s = run.settings
    out: dict[str, Any] = {"paper_figure": "Figures 16, 17", "figures": [], "scenes": {}}
    for key, fig_name, paper_fig in (
        ("pitch_deg", "fig16_pitch.png", "Figure 16"),
        ("azimuth_deg", "fig17_azimuth.png", "Figure 17"),
    ):
        steps = s.attitude_steps_deg
        panel_in = 3.0
        fig = new_figure(panel_in * len(steps) + 0.6, 2 * panel_in + 1.4)
        axes = fig.subplots(2, len(steps), squeeze=False)
        present: set[int] = set()
        rows = []
        credit = None
        for j, angle in enumerate(steps):
            scene = run.scene({key: angle, "pixels": s.cloud_pixels})
            result = run.run(scene)
            label = f"{key.split('_')[0]} {angle:g} deg"
            present |= draw_cloud(axes[0, j], axes[1, j], result, label, panel_in)
            credit = result.target.credit
            out["scenes"][f"{key}={angle:g}"] = scene.to_dict()
            rows.append(
                {
                    key: angle,
                    **run_summary(result),
                    "per_material": per_material(result),
                }
            )
            run.step(label)
        material_legend(fig, present, True, credit)
        fig.suptitle(
            f"MRO at 500 m, {s.cloud_pixels} x {s.cloud_pixels} pixels: {key.split('_')[0]} steps, "
            f"front view (top row) and top view (bottom row) ({paper_fig})\n{CLOUD_NOTE}",
        )
        out["figures"].append(run.save(fig, fig_name))
        out[key.split("_")[0]] = rows
        run.step(f"{paper_fig}")
    return out


def item_resolution(run: ReproduceRun) -> dict[str, Any]:
    panel_in = 2.9
    fig = new_figure(panel_in * len(RESOLUTION_PIXELS) + 0.4, panel_in * 2 + 1.9)
    axes = fig.subplots(len(RESOLUTION_DISTANCES_M), len(RESOLUTION_PIXELS), squeeze=False)
    table, scenes = [], {}
    present: set[int] = set()
    credit = None
    base = run.scene()
    for i, distance in enumerate(RESOLUTION_DISTANCES_M):
        optics = matched_fov(distance, base.laser.divergence_rad)
        for j, pixels in enumerate(RESOLUTION_PIXELS):
            scene = run.scene({"distance_m": distance, "pixels": pixels, **optics})
            result = run.run(scene)
            credit = result.target.credit
            label = f"{distance:g} m, {pixels} x {pixels}"
            scenes[label] = scene.to_dict()
            summary = run_summary(result)
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
            present |= draw_cloud(ax, None, result, label, panel_in)
            ax.set_title(
                f"{label}: {summary['n_target_points']} points\n"
                f"footprint {100 * distance * scene.ifov_rad:.1f} cm, SNR median "
                f"{summary['snr_median']:.0f}",
                fontsize=8,
            )
            run.step(label)
    material_legend(fig, present, True, credit)
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


def item_flyaround(run: ReproduceRun) -> dict[str, Any]:
    s = run.settings
    stats = orbit.distance_stats(orbit.PAPER_TARGET, orbit.PAPER_IMAGING)
    base = run.scene()
    optics = matched_fov(stats["min_m"], base.laser.divergence_rad)
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
    fig = new_figure(panel_in * len(FLYAROUND_FRAMES_S) + 0.6, 2 * panel_in + 1.4)
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
        present |= draw_cloud(axes[0, j], axes[1, j], result, label, panel_in)
        frames.append(
            {
                "t_s": t_s,
                "distance_m": float(fly.pose.distance_m[i]),
                "angles_deg": fly.pose.angles_deg[i].tolist(),
                **run_summary(result),
            }
        )
        run.step(label)
    material_legend(fig, present, True, credit)
    fig.suptitle(
        f"Fly-around frames (paper Figure 24): Table 3 orbits, {FLYAROUND_ENERGY_J * 1e3:g} mJ, "
        f"{s.flyaround_pixels} x {s.flyaround_pixels} pixels, field of view "
        f"{optics['receive.fov_rad'] * 1e3:.1f} mrad\n{CLOUD_NOTE}"
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


def item_conventions(run: ReproduceRun) -> dict[str, Any]:
    s = run.settings
    variants: list[tuple[str, dict[str, Any]]] = [("ours", {})]
    variants += [(form, {"paper_forms": [form]}) for form in PAPER_FORMS]
    variants.append(("paper (all)", {"conventions": "paper"}))
    rows, scenes = [], {}
    ours = None
    for name, overrides in variants:
        scene = run.scene({"pixels": s.cloud_pixels, **overrides})
        result = run.run(scene)
        row = {"form": name, **convention_row(result)}
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
        ("n_false_crossings_expected", "false alarms (Eq. 28, expected)"),
        ("depth_extent_m", "depth extent (1-99 %)"),
    )
    fig = new_figure(11.0, 7.0)
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
