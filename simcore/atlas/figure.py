"""The atlas's map: the metric over every view direction in an equal-area (Mollweide)
projection, the best and worst attitudes marked, the target's silhouette at a few attitudes.

Longitude is the azimuth (0 deg, the front view, in the middle), latitude the pitch. A cell
where the lidar does not see the target is grey, one where it sees it but the figure has no
value (no target point) is hatched: neither is drawn as zero quality.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .. import io
from ..scene import Scene
from .frame import METRICS, metric_values
from .grid import AttitudeGrid

_NOT_SEEN = "#c8c8c8"
_EDGE_STEPS = 6  # [-] points along each cell edge (the projection bends the meridians)


def _lon_deg(azimuth_deg: float) -> float:
    """Azimuth [deg] as the map's longitude in [-180, 180) (the front view in the middle)."""
    return (azimuth_deg + 180.0) % 360.0 - 180.0


def cell_polygons(pitch_deg: float, azimuth_deg: float, d_pitch: float, d_az: float):
    """The cell of a grid point as polygons of (lon, lat) [rad] (two where it crosses the map's
    edge at 180 deg; a pole's is a cap over every longitude)."""
    if abs(pitch_deg) == 90.0:
        lat_a, lat_b = math.copysign(90.0 - d_pitch / 2, pitch_deg), pitch_deg
        spans = [(-180.0, 180.0)]
    else:
        lat_a, lat_b = pitch_deg - d_pitch / 2, pitch_deg + d_pitch / 2
        lo = _lon_deg(azimuth_deg) - d_az / 2
        hi = lo + d_az
        if lo < -180.0:
            spans = [(-180.0, hi), (lo + 360.0, 180.0)]
        elif hi > 180.0:
            spans = [(lo, 180.0), (-180.0, hi - 360.0)]
        else:
            spans = [(lo, hi)]
    polys = []
    for a, b in spans:
        lons = np.linspace(a, b, _EDGE_STEPS)
        lats = np.linspace(lat_a, lat_b, _EDGE_STEPS)
        ring = [
            *zip(lons, np.full(_EDGE_STEPS, lat_a), strict=True),
            *zip(np.full(_EDGE_STEPS, b), lats, strict=True),
            *zip(lons[::-1], np.full(_EDGE_STEPS, lat_b), strict=True),
            *zip(np.full(_EDGE_STEPS, a), lats[::-1], strict=True),
        ]
        polys.append(np.radians(np.asarray(ring)))
    return polys


def write_map(
    path: Path,
    table,
    scene: Scene,
    grid: AttitudeGrid,
    metric: str,
    summary: dict[str, Any],
    insets: bool = True,
) -> None:
    """Draw the map of ``metric`` from the atlas ``table`` of ``scene`` over ``grid`` into
    ``path`` (PNG); ``summary`` (simcore.atlas.summarize) gives the best and worst."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415
    from matplotlib.collections import PolyCollection  # noqa: PLC0415
    from matplotlib.patches import Patch  # noqa: PLC0415

    column, label, better = METRICS[metric]
    values = metric_values(table, metric)
    pitch = np.asarray(table.column("pitch_deg").to_pylist())
    azimuth = np.asarray(table.column("azimuth_deg").to_pylist())
    seen = np.asarray([n or 0 for n in table.column("n_hit_pixels").to_pylist()]) > 0
    fig = plt.figure(figsize=(10, 7.2), dpi=110)
    ax = fig.add_axes((0.05, 0.40, 0.80, 0.50), projection="mollweide")
    finite = values[np.isfinite(values)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
    if column.endswith(("precision", "recall", "f_score")) or column.startswith("n_"):
        vmin = 0.0  # a share or a count from nought: the colours' lengths read as ratios
    if vmax <= vmin:
        vmax = vmin + 1.0
    cmap = plt.get_cmap("viridis" if better != "low" else "viridis_r")
    norm = matplotlib.colors.Normalize(vmin, vmax)
    polys, colours, hatched = [], [], []
    for i in range(len(values)):
        cell = cell_polygons(pitch[i], azimuth[i], grid.pitch_step_deg, grid.azimuth_step_deg)
        if np.isfinite(values[i]):
            colour = cmap(norm(values[i]))
        else:
            colour = _NOT_SEEN if not seen[i] else "white"
        for poly in cell:
            polys.append(poly)
            colours.append(colour)
            hatched.append(seen[i] and not np.isfinite(values[i]))
    ax.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="none"))
    blank = [p for p, h in zip(polys, hatched, strict=True) if h]
    if blank:
        ax.add_collection(
            PolyCollection(blank, facecolors="none", edgecolors="#888888", hatch="///", lw=0)
        )
    ax.grid(True, color="white", lw=0.4, alpha=0.6)
    ticks = np.arange(-150, 151, 30)
    ax.set_xticks(np.radians(ticks))
    ax.set_xticklabels([f"{int(t) % 360}°" for t in ticks], fontsize=7)
    ax.set_xlabel("azimuth_deg (0: the front view)")
    ax.set_ylabel("pitch_deg")
    for which, marker in (("best", "*"), ("worst", "X")):
        chosen = summary.get(which)
        if chosen:
            ax.plot(
                math.radians(_lon_deg(chosen["azimuth_deg"])),
                math.radians(chosen["pitch_deg"]),
                marker=marker,
                ms=13,
                mfc="white" if which == "best" else "#d62728",
                mec="black",
                ls="none",
                label=f"{which}: pitch {chosen['pitch_deg']:g}°, azimuth "
                f"{chosen['azimuth_deg']:g}°, {chosen['value']:.3g}",
            )
    label = label.replace("at tau", f"at tau = {100 * scene.quality.tau_m:g} cm")
    cax = fig.add_axes((0.87, 0.44, 0.018, 0.42))
    bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    bar.set_label(label)
    handles, _ = ax.get_legend_handles_labels()
    if not seen.all():
        handles += [Patch(facecolor=_NOT_SEEN, label="target not seen")]
    if blank:
        handles += [
            Patch(facecolor="white", edgecolor="#888888", hatch="///", label="seen, no value")
        ]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2, fontsize=8)
    s = scene
    median = summary.get("median")
    median_text = "n/a" if median is None else f"{median:.3g}"
    fig.suptitle(
        f"{label} over every view direction: {len(values)} attitudes, "
        f"{grid.pitch_step_deg:g}° x {grid.azimuth_step_deg:g}° grid\n"
        f"{s.detector.pixels} x {s.detector.pixels} px at {s.pose.distance_m:g} m; "
        f"median over the sphere {median_text} (by solid angle)",
        fontsize=10,
    )
    if insets:
        credit = _draw_insets(fig, scene, summary)
        fig.text(0.5, 0.01, credit, ha="center", fontsize=7, color="#444444")
    with io.atomic_path(path) as tmp, np.errstate(invalid="ignore"):  # the poles' inverse
        fig.savefig(tmp, format="png")
    plt.close(fig)


def _inset_attitudes(summary: dict[str, Any]) -> list[tuple[str, float, float]]:
    """The attitudes drawn as silhouettes: best, worst, the front view and a side view."""
    chosen = [
        (which, summary[which]["pitch_deg"], summary[which]["azimuth_deg"])
        for which in ("best", "worst")
        if summary.get(which)
    ]
    for name, p, a in (("front", 0.0, 0.0), ("side", 0.0, 90.0), ("top", 90.0, 0.0)):
        if len(chosen) < 4 and all((p, a) != (q, b) for _, q, b in chosen):
            chosen.append((name, p, a))
    return chosen


def _draw_insets(fig, scene: Scene, summary: dict[str, Any]) -> str:
    """The target's silhouette (its pixels' hits) at a few attitudes, under the map; returns the
    target's credit line."""
    from ..pipeline import Pipeline  # noqa: PLC0415
    from ..scene import with_overrides  # noqa: PLC0415

    pipeline = Pipeline()
    credit = ""
    chosen = _inset_attitudes(summary)
    for k, (name, p, a) in enumerate(chosen):
        result = pipeline.run(with_overrides(scene, pitch_deg=p, azimuth_deg=a))
        mask = result.hits.hit_pixel_mask.reshape(result.pixels, result.pixels)
        credit = f"target: {result.target.name}; {result.target.credit}"
        ax = fig.add_axes((0.06 + k * 0.225, 0.04, 0.17, 0.19))
        ax.imshow(mask, cmap="Greys", vmin=0, vmax=1.6, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{name}: pitch {p:g}°, az {a:g}°", fontsize=8)
    return credit
