"""``lmapd bench --design``: a design study's wall time on this machine (the built-in
``mro_approach``: 8 envelope points at 128 x 128, interactive preset), with the stages its
envelope points took from their caches, and the machine it ran on."""

from __future__ import annotations

import datetime
import json
import os
import platform
import tempfile
from pathlib import Path

from ... import design


def main(
    quick: bool = False,
    json_path: str | None = None,
    trials: int | None = None,
    workers: int = 2,
    study: str = "mro_approach",
) -> int:
    """Run the study (``trials``: default the study's, 20 with ``quick``) on ``workers`` local
    Dask workers into a temporary folder; print and optionally write the figures."""
    spec = design.load_study(study)
    n = trials if trials is not None else (20 if quick else spec.trials)
    with tempfile.TemporaryDirectory(prefix="lmapd-bench-design-") as folder:
        result = design.run(spec, Path(folder) / "study", trials=n, workers=workers)
    screened = [r for r in result.records if r.stage == "screen"]
    frames = sum(len(r.points) for r in result.records)
    figures = {
        "study": spec.name,
        "trials": n,
        "envelope_points": len(spec.envelope),
        "workers": workers,
        "frames": frames,
        "wall_s": round(result.wall_s, 1),
        "s_per_trial": round(result.wall_s / max(len(screened), 1), 2),
        "feasible": sum(r.feasible for r in screened),
        "stages": result.tally.as_dict(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
        "date": datetime.date.today().isoformat(),
    }
    print(
        f"design study {spec.name}: {n} trials x {len(spec.envelope)} envelope points "
        f"({frames} frames, {spec.preset} screening, {spec.confirm_preset} confirmation) on "
        f"{workers} workers: {result.wall_s:.1f} s ({figures['s_per_trial']} s a trial); "
        f"{figures['feasible']} feasible"
    )
    print(result.tally.line())
    print(f"machine: {figures['machine']}, {figures['date']}")
    if json_path:
        Path(json_path).write_text(json.dumps(figures, indent=2) + "\n")
    return 0
