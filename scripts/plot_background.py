"""The MRO at 500 m by night and by day (docs/physics.md#background).

The lidar looks down at the target (its line of sight along the body's nadir, the sunlit Earth
behind the target); by day the Sun stands 30 deg from the line of sight. Four cases: night, day
with a 1 nm, a 10 nm and a 100 nm filter (global threshold: TNR x a dark pixel's noise): the
paper's thermal-noise-limited Si receiver hardly notices 1 nm of sunlight; 100 nm shows where
the background takes over. Writes docs/img/background.png: per case the background
power per pixel, the measured point cloud's range error (noise) with its false alarms, and prints
the figures of each case.

    .venv/bin/python scripts/plot_background.py [--out docs/img/background.png] [--pixels 256]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import simcore

LOOK_DOWN = {"pose.quaternion_wxyz": [1.0, 0.0, 0.0, 0.0], "distance_m": 500.0}
DAY = {"sun.mode": "manual", "sun.azimuth_deg": 0.0, "sun.elevation_deg": 60.0}
CASES = {
    "night": {},
    "day, 1 nm filter": {**DAY, "receive.filter_width_m": 1e-9},
    "day, 10 nm filter": {**DAY, "receive.filter_width_m": 10e-9},
    "day, 100 nm filter": {**DAY, "receive.filter_width_m": 100e-9},
}


def run(pixels: int) -> dict[str, simcore.Result]:
    pipe = simcore.Pipeline()
    out = {}
    for name, keys in CASES.items():
        scene = simcore.with_overrides(simcore.Scene(), {**LOOK_DOWN, "pixels": pixels, **keys})
        t0 = time.perf_counter()
        out[name] = pipe.run(scene)
        s = out[name].summary()
        print(
            f"{name:34s} points {s['n_target_points']:6d}  outliers {s['n_outliers']:7d}  "
            f"dropped {s['n_dropped']:5d}  range sigma median "
            f"{1e3 * (s['range_sigma_m_median'] or float('nan')):.2f} mm  background median "
            f"{s['background_power_w_median']:.3g} W  max {s['background_power_w_max']:.3g} W"
            f"  [{time.perf_counter() - t0:.2f} s]"
        )
    return out


def plot(results: dict[str, simcore.Result], path: Path) -> None:
    fig, axes = plt.subplots(2, len(results), figsize=(4.2 * len(results), 8.2))
    for col, (name, res) in enumerate(results.items()):
        s = res.summary()
        bg = res.background.power_w
        ax = axes[0, col]
        shown = np.where(bg > 0, bg, np.nan)
        if np.isfinite(shown).any():
            im = ax.imshow(np.log10(shown), cmap="magma")
            fig.colorbar(im, ax=ax, fraction=0.046, label="log10 background power [W]")
        else:
            ax.imshow(np.zeros_like(bg), cmap="gray", vmin=0, vmax=1)
        ax.set_title(f"{name}\nbackground per pixel", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        ax = axes[1, col]
        true_m = np.full(res.pixels**2, np.nan)
        true_m[res.echo.pixel] = res.detection.range_true_m
        err_mm = 1e3 * (res.range_image_m - true_m.reshape(res.pixels, res.pixels))
        lim = 40.0
        im = ax.imshow(err_mm, cmap="coolwarm", vmin=-lim, vmax=lim)
        out = res.detection.outliers
        n = res.pixels
        ax.plot(out.pixel % n, out.pixel // n, ",", color="k", alpha=0.5)
        sigma = s["range_sigma_m_median"]
        noise = f"median range sigma {1e3 * sigma:.1f} mm" if sigma else "no points"
        ax.set_title(
            f"range error; {s['n_target_points']} points, {s['n_outliers']} false alarms\n{noise}",
            fontsize=9,
        )
        ax.set_xticks([])
        ax.set_yticks([])
        if col == len(results) - 1:
            fig.colorbar(im, ax=ax, fraction=0.046, label="measured - noise-free range [mm]")
    fig.suptitle(
        "MRO at 500 m, looking down with the sunlit Earth behind (albedo 0.3); by day the Sun is "
        "30 deg from the line of sight. Target model: NASA MRO (NASA 3D Resources).",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img/background.png"))
    parser.add_argument("--pixels", type=int, default=256)
    args = parser.parse_args()
    plot(run(args.pixels), args.out)


if __name__ == "__main__":
    main()
