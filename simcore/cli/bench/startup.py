"""``lmapd bench --startup``: how long ``lmapd simulate`` takes from a fresh process, phase by
phase: imports, target load, BVH build, first frame and the point-cloud write.

Each run is a new Python process that does what ``lmapd simulate --out cloud.ply`` does and
times its own phases with ``time.perf_counter``, reporting them as one line of JSON; the parent
also times that whole process (interpreter start and exit included) and then a real
``lmapd simulate`` (``python -m simcore.cli``), end to end. Figures are the median and the range
over the runs (a shared machine drifts: a single figure would mislead). The on-disk caches
(processed target, pulse timing marks) are filled first, as after a first run; with
``cold=True`` one more probe runs on an empty cache. Figures are printed, never asserted.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..common import say

# (key in the probe's JSON, label): what lmapd simulate does, in order
PHASES = (
    ("import_s", "import (CLI, imaging chain)"),
    ("target_load_s", "target load (cached mesh)"),
    ("bvh_build_s", "BVH build"),
    ("first_frame_s", "first frame"),
    ("write_s", "write (PLY)"),
)
TOTALS = (
    ("process_s", "the probe's process, start to exit"),
    ("command_s", "lmapd simulate, end to end"),
)

# the probe: ``lmapd simulate [--set pixels=N] --out OUT``, with a clock between its phases
PROBE = r"""
import time

t0 = time.perf_counter()
import json
import os
import sys

import simcore.cli
from simcore import geometry, io, parallel, pipeline
from simcore.materials import MATERIAL_NAMES
from simcore.scene import load_scene, with_overrides
from simcore.target import load_target

t1 = time.perf_counter()
out, pixels = sys.argv[1], int(sys.argv[2])
scene = with_overrides(load_scene(None), {"pixels": pixels})
model = load_target(scene.target)
t2 = time.perf_counter()
caster = geometry.RayCaster(model)
t3 = time.perf_counter()
assert pipeline.CHAIN[0].name == "target"
outputs = {"target": geometry.TargetStage(model=model, caster=caster)}
with parallel.blas_serial():
    for stage in pipeline.CHAIN[1:]:
        outputs[stage.name] = stage.compute(scene, *(outputs[u] for u in stage.upstream))
t4 = time.perf_counter()
comments = (f"scene {scene.name}", f"material_id indexes: {' '.join(MATERIAL_NAMES)}")
io.write_cloud(out, outputs["cloud"], comments)
t5 = time.perf_counter()
times = {
    "import_s": t1 - t0,
    "target_load_s": t2 - t1,
    "bvh_build_s": t3 - t2,
    "first_frame_s": t4 - t3,
    "write_s": t5 - t4,
    "n_points": len(outputs["cloud"]),
}
sys.stdout.write(json.dumps(times) + "\n")
sys.stdout.flush()
os._exit(0)  # as the lmapd script ends simulate
"""


def probe_run(pixels: int, env: dict[str, str] | None = None) -> dict[str, float]:
    """One fresh process's phase times [s] (the PROBE's JSON) and its whole wall time
    ``process_s`` [s], measured from here."""
    with tempfile.TemporaryDirectory(prefix="lmapd-bench-") as folder:
        out = str(Path(folder) / "cloud.ply")
        t0 = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-c", PROBE, out, str(pixels)],
            capture_output=True,
            text=True,
            check=True,
            env=env,
        )
        process_s = time.perf_counter() - t0
    times = json.loads(done.stdout.strip().splitlines()[-1])
    times["process_s"] = process_s
    return times


def command_s(pixels: int) -> float:
    """Wall time [s] of ``lmapd simulate --set pixels=N --out cloud.ply``, end to end."""
    with tempfile.TemporaryDirectory(prefix="lmapd-bench-") as folder:
        argv = ["simulate", "--set", f"pixels={pixels}", "--out", str(Path(folder) / "c.ply")]
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "simcore.cli", *argv], capture_output=True, check=True
        )
        return time.perf_counter() - t0


def summary(runs: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Median, min and max over ``runs`` of every phase and the whole process [s]."""
    keys = [k for k, _ in (*PHASES, *TOTALS)]
    return {
        stat: {k: fn([r[k] for r in runs]) for k in keys}
        for stat, fn in (("median_s", statistics.median), ("min_s", min), ("max_s", max))
    }


def warm_caches(pixels: int) -> None:
    """Fill the on-disk caches a run reads (the processed target, the pulse's timing marks)."""
    from ...pulse import scene_pulse_shape  # noqa: PLC0415
    from ...scene import load_scene, with_overrides  # noqa: PLC0415
    from ...target import load_target  # noqa: PLC0415

    scene = with_overrides(load_scene(None), {"pixels": pixels})
    load_target(scene.target)
    scene_pulse_shape(scene)


def run(processes: int = 7, pixels: int = 256, cold: bool = False) -> dict:
    """Time ``processes`` fresh runs of the paper scene at ``pixels`` per side (caches warm) and,
    with ``cold``, one more on an empty cache."""
    warm_caches(pixels)
    runs = [{**probe_run(pixels), "command_s": command_s(pixels)} for _ in range(processes)]
    fig = {"processes": processes, "pixels": pixels, "runs": runs, **summary(runs)}
    if cold:
        with tempfile.TemporaryDirectory(prefix="lmapd-cache-") as empty:
            fig["cold_run"] = probe_run(pixels, env={**os.environ, "LMAPD_CACHE_DIR": empty})
    return fig


def _cell(fig: dict, key: str) -> str:
    ms = {stat: 1e3 * fig[stat][key] for stat in ("median_s", "min_s", "max_s")}
    return f"{ms['median_s']:.0f} ({ms['min_s']:.0f}-{ms['max_s']:.0f})"


def format_table(fig: dict) -> str:
    """The figures as a Markdown table: median (min-max) in ms per phase."""
    size = f"{fig['pixels']} x {fig['pixels']}"
    lines = [
        f"lmapd simulate of the paper scene ({size}) in a fresh process: median (min-max) of "
        f"{fig['processes']} processes, caches warm",
        "",
        "| phase | ms |",
        "|---|---|",
    ]
    lines += [f"| {label} | {_cell(fig, key)} |" for key, label in (*PHASES, *TOTALS)]
    if "cold_run" in fig:
        cold = fig["cold_run"]
        lines += [
            "",
            f"On an empty cache (a first run): target load {1e3 * cold['target_load_s']:.0f} ms, "
            f"first frame {1e3 * cold['first_frame_s']:.0f} ms, the probe's process "
            f"{1e3 * cold['process_s']:.0f} ms.",
        ]
    return "\n".join(lines)


def main(quick: bool = False, json_path: str | None = None) -> int:
    """Run the start-up bench (``quick``: 2 processes at 32 x 32, no cold run) and print it."""
    fig = run(processes=2, pixels=32) if quick else run(cold=True)
    say(format_table(fig))
    if json_path:
        from ...io import write_json  # noqa: PLC0415

        write_json(json_path, fig)
    return 0
