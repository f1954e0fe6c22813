"""The item of ``lmapd reproduce`` beyond the paper: the MRO at 500 m by night and by day
(docs/physics.md#background), the Sun 30 deg from the line of sight with the sunlit Earth behind
the target, through 1 nm and 10 nm band-pass filters."""

from __future__ import annotations

from typing import Any

import numpy as np

from .draw import credit_line, new_figure
from .run import ReproduceRun

# the lidar looks down the target's body z axis (at the Earth): the sunlit Earth lies behind it
LOOK_DOWN = {"pose.quaternion_wxyz": [1.0, 0.0, 0.0, 0.0], "distance_m": 500.0}
DAY = {"sun.mode": "manual", "sun.azimuth_deg": 0.0, "sun.elevation_deg": 60.0}
DAYLIGHT_CASES = {
    "night": {},
    "day, 1 nm filter": {**DAY, "receive.filter_width_m": 1e-9},
    "day, 10 nm filter": {**DAY, "receive.filter_width_m": 10e-9},
}
COLUMNS = (
    "n_target_points",
    "n_outliers",
    "n_dropped",
    "range_sigma_m_median",
    "background_power_w_median",
    "n_earth_pixels",
)


def item_daylight(run: ReproduceRun) -> dict[str, Any]:
    s = run.settings
    rows, scenes = [], {}
    for name, overrides in DAYLIGHT_CASES.items():
        scene = run.scene({"pixels": s.cloud_pixels, **LOOK_DOWN, **overrides})
        summary = run.run(scene).summary()
        rows.append(
            {"case": name, "sun_angle_deg": summary.get("sun_angle_deg")}
            | {k: summary.get(k) for k in COLUMNS}
        )
        scenes[name] = scene.to_dict()
        run.step(f"daylight: {name}")
    fig = new_figure(11.0, 4.2)
    axes = fig.subplots(1, 3)
    labels = [r["case"] for r in rows]
    x = np.arange(len(rows))
    panels: tuple[tuple[str, str, float], ...] = (
        ("n_target_points", "target points", 1.0),
        ("n_outliers", "outliers (false alarms)", 1.0),
        ("range_sigma_m_median", "range sigma median [mm]", 1e3),
    )
    for ax, (key, title, scale) in zip(axes, panels, strict=True):
        values = [float(r[key] or 0.0) * scale for r in rows]
        ax.bar(x, values, color=["0.35", "C1", "C3"])
        for xx, v in zip(x, values, strict=True):
            text = f"{v:,.0f}" if v >= 100 else f"{v:.3g}"
            ax.text(xx, v, text, ha="center", va="bottom", fontsize=8)
        ax.set_xticks(x, labels, rotation=15, fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(
        f"MRO at 500 m looking down at the sunlit Earth, {s.cloud_pixels} x {s.cloud_pixels} "
        "pixels: by night and by day (Sun 30 deg from the line of sight)",
        fontsize=10,
    )
    credit_line(fig, "3D model: Courtesy NASA/JPL-Caltech (NASA 3D Resources)")
    figure = run.save(fig, "daylight.png")
    run.step("daylight figure")
    return {
        "paper_figure": "beyond the paper: background light (docs/physics.md#background)",
        "figures": [figure],
        "scenes": scenes,
        "columns": ["case", "sun_angle_deg", *COLUMNS],
        "rows": rows,
    }
