"""The run of ``lmapd reproduce``: every item in turn, then ``report.json``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ... import io
from ..._version import __version__
from ...materials import MATERIAL_NAMES
from ...reproduce import PAPER, git_commit, settings_for
from .items_clouds import item_attitude, item_conventions, item_flyaround, item_resolution
from .items_echo import item_brdf, item_detection, item_waveforms
from .items_light import item_daylight
from .run import ReproduceRun, total_steps

__all__ = ["ITEMS", "REPORT_NAME", "run_reproduction"]

REPORT_NAME = "report.json"
ITEMS = (
    "brdf",
    "detection",
    "waveforms",
    "attitude",
    "resolution",
    "flyaround",
    "conventions",
    "daylight",  # beyond the paper: background light
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
    run = ReproduceRun(out, settings, total_steps(settings), progress)
    items: dict[str, Any] = {}
    timings: dict[str, float] = {}
    makers = {
        "brdf": item_brdf,
        "detection": item_detection,
        "waveforms": item_waveforms,
        "attitude": item_attitude,
        "resolution": item_resolution,
        "flyaround": item_flyaround,
        "conventions": item_conventions,
        "daylight": item_daylight,
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
        "target_credit": "3D model: Courtesy NASA/JPL-Caltech (NASA 3D Resources)",
        "items": items,
        "figures": [f for item in items.values() for f in item["figures"]],
        "timings_s": timings,
    }
    io.write_json(out / REPORT_NAME, report)
    return report


def _git_fields() -> dict[str, Any]:
    git = git_commit()
    return {"git_commit": git["commit"], "git_dirty": git["dirty"]}
