"""``lmapd bench --startup``: how long ``lmapd simulate`` takes from a fresh process, phase by
phase: imports, target load, BVH build, first frame and the point-cloud write.

Each run is a new Python process that does what ``lmapd simulate --out cloud.ply`` does and
times its own phases with ``time.perf_counter``, reporting them as one line of JSON: like
``Pipeline.run`` it starts loading the compiled echo kernel on a background thread before the
target loads, and it times how long the echo stage then still waits for it. After the write it
runs one more frame (the pose nudged: what a second frame costs once everything is loaded), so
that the first frame can be set against a warm one; that frame is left out of the process's
time. The parent times that whole process (interpreter start and exit included), then a real
``lmapd simulate``, ``lmapd --help`` and ``lmapd keys`` (``python -m simcore.cli``), end to end,
and a floor probe: the interpreter alone, then what the imports and the kernel cost one by one
(numpy, scipy.special, embreex, numba, the kernel's module, its functions read from numba's
on-disk cache). Figures are the median and the range over the runs (a shared machine drifts: a
single figure would mislead). The on-disk caches (processed target, pulse timing marks, compiled
kernel) are filled first, as after a first run; with ``cold=True`` one more probe runs on an
empty project cache. Figures are printed, never asserted.
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
# inside the phases above, and the warm frame run after them
DETAILS = (
    ("kernel_wait_s", "of the first frame: waiting for the echo kernel"),
    ("warm_frame_s", "a second frame (warm), for comparison"),
)
TOTALS = (
    ("process_s", "the probe's process, start to exit"),
    ("command_s", "lmapd simulate, end to end"),
    ("help_s", "lmapd --help"),
    ("keys_s", "lmapd keys"),
)
# the floors: (key, label), in the FLOOR probe's order; the interpreter is timed by the parent
FLOORS = (
    ("python_s", "interpreter start and exit (python -c pass)"),
    ("numpy_s", "import numpy"),
    ("scipy_s", "import scipy.special (after numpy)"),
    ("embreex_s", "import embreex (after those)"),
    ("simcore_s", "import simcore.cli and the imaging chain (the rest)"),
    ("numba_s", "import numba"),
    ("kernel_import_s", "import simcore.echo.kernel (after numba)"),
    ("kernel_load_s", "the kernel's functions from numba's on-disk cache"),
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
from simcore.echo.features import compiled_kernel, preload
from simcore.materials import MATERIAL_NAMES
from simcore.pulse import scene_pulse_shape
from simcore.scene import load_scene, with_overrides
from simcore.target import load_target

t1 = time.perf_counter()
out, pixels = sys.argv[1], int(sys.argv[2])
scene = with_overrides(load_scene(None), {"pixels": pixels})
preload(scene_pulse_shape(scene))  # as Pipeline.run starts: the kernel loads meanwhile
model = load_target(scene.target)
t2 = time.perf_counter()
caster = geometry.RayCaster(model)
t3 = time.perf_counter()
assert pipeline.CHAIN[0].name == "target"
outputs = {"target": geometry.TargetStage(model=model, caster=caster)}
kernel_wait = 0.0
with parallel.blas_serial():
    for stage in pipeline.CHAIN[1:]:
        if stage.name == "echo":
            tw = time.perf_counter()
            compiled_kernel()  # joins the loading thread
            kernel_wait = time.perf_counter() - tw
        outputs[stage.name] = stage.compute(scene, *(outputs[u] for u in stage.upstream))
t4 = time.perf_counter()
comments = (f"scene {scene.name}", f"material_id indexes: {' '.join(MATERIAL_NAMES)}")
io.write_cloud(out, outputs["cloud"], comments)
t5 = time.perf_counter()
nudged = with_overrides(scene, {"pose.roll_deg": 1e-6})  # every stage after the rays re-runs
with parallel.blas_serial():
    for stage in pipeline.CHAIN[2:]:
        outputs[stage.name] = stage.compute(nudged, *(outputs[u] for u in stage.upstream))
t6 = time.perf_counter()
times = {
    "import_s": t1 - t0,
    "target_load_s": t2 - t1,
    "bvh_build_s": t3 - t2,
    "first_frame_s": t4 - t3,
    "write_s": t5 - t4,
    "kernel_wait_s": kernel_wait,
    "warm_frame_s": t6 - t5,
    "n_points": len(outputs["cloud"]),
}
sys.stdout.write(json.dumps(times) + "\n")
sys.stdout.flush()
os._exit(0)  # as the lmapd script ends simulate
"""


# the floors, one fresh process each: the imports in the order lmapd simulate meets them, then
# numba, the kernel's module and its compiled functions read from the on-disk cache
FLOOR = r"""
import time

t0 = time.perf_counter()
import json
import sys

import numpy

t1 = time.perf_counter()
import scipy.special

t2 = time.perf_counter()
from embreex import rtcore_scene

t3 = time.perf_counter()
import simcore.cli
from simcore import geometry, io, pipeline
from simcore.pulse import scene_pulse_shape
from simcore.scene import load_scene

t4 = time.perf_counter()
import numba

t5 = time.perf_counter()
from simcore.echo import kernel

t6 = time.perf_counter()
shape = scene_pulse_shape(load_scene(None))
t7 = time.perf_counter()
kernel.warm(shape)
t8 = time.perf_counter()
times = {
    "numpy_s": t1 - t0,
    "scipy_s": t2 - t1,
    "embreex_s": t3 - t2,
    "simcore_s": t4 - t3,
    "numba_s": t5 - t4,
    "kernel_import_s": t6 - t5,
    "kernel_load_s": t8 - t7,
}
sys.stdout.write(json.dumps(times) + "\n")
"""


def probe_run(pixels: int, env: dict[str, str] | None = None) -> dict[str, float]:
    """One fresh process's phase times [s] (the PROBE's JSON) and its whole wall time
    ``process_s`` [s], measured from here, less the warm frame it runs after the write."""
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
    times["process_s"] = process_s - times["warm_frame_s"]
    return times


def floor_run() -> dict[str, float]:
    """The floors [s]: ``python -c pass`` timed from here, then the FLOOR probe's steps."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    python_s = time.perf_counter() - t0
    done = subprocess.run([sys.executable, "-c", FLOOR], capture_output=True, text=True, check=True)
    return {"python_s": python_s, **json.loads(done.stdout.strip().splitlines()[-1])}


def command_s(*argv: str) -> float:
    """Wall time [s] of ``lmapd ARGV...`` (``python -m simcore.cli``), end to end."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "simcore.cli", *argv], capture_output=True, check=True)
    return time.perf_counter() - t0


def commands(pixels: int) -> dict[str, float]:
    """End-to-end wall times [s] of lmapd simulate (the paper scene, ``pixels`` per side),
    ``lmapd --help`` and ``lmapd keys``."""
    with tempfile.TemporaryDirectory(prefix="lmapd-bench-") as folder:
        out = str(Path(folder) / "c.ply")
        return {
            "command_s": command_s("simulate", "--set", f"pixels={pixels}", "--out", out),
            "help_s": command_s("--help"),
            "keys_s": command_s("keys"),
        }


def summary(runs: list[dict[str, float]], keys=None) -> dict[str, dict[str, float]]:
    """Median, min and max over ``runs`` of every phase and total (or of ``keys``) [s]."""
    keys = keys or [k for k, _ in (*PHASES, *DETAILS, *TOTALS)]
    return {
        stat: {k: fn([r[k] for r in runs]) for k in keys}
        for stat, fn in (("median_s", statistics.median), ("min_s", min), ("max_s", max))
    }


def warm_caches(pixels: int) -> None:
    """Fill the on-disk caches a run reads (the processed target, the pulse's timing marks, the
    compiled echo kernel)."""
    from ...echo.features import compiled_kernel  # noqa: PLC0415
    from ...pulse import scene_pulse_shape  # noqa: PLC0415
    from ...scene import load_scene, with_overrides  # noqa: PLC0415
    from ...target import load_target  # noqa: PLC0415

    scene = with_overrides(load_scene(None), {"pixels": pixels})
    load_target(scene.target)
    shape = scene_pulse_shape(scene)
    kernel = compiled_kernel()
    if kernel is not None:
        kernel.warm(shape)


def run(processes: int = 7, pixels: int = 256, cold: bool = False) -> dict:
    """Time ``processes`` rounds of fresh runs of the paper scene at ``pixels`` per side (caches
    warm): the probe, the commands and the floors in turn, so that a busy spell of a shared
    machine slows them all; with ``cold``, one more probe on an empty project cache."""
    warm_caches(pixels)
    load_before = os.getloadavg()[0]
    runs, floors = [], []
    for _ in range(processes):
        runs.append({**probe_run(pixels), **commands(pixels)})
        floors.append(floor_run())
    fig = {"processes": processes, "pixels": pixels, "runs": runs, **summary(runs)}
    fig["floors"] = {"runs": floors, **summary(floors, [k for k, _ in FLOORS])}
    if cold:
        with tempfile.TemporaryDirectory(prefix="lmapd-cache-") as empty:
            fig["cold_run"] = probe_run(pixels, env={**os.environ, "LMAPD_CACHE_DIR": empty})
    fig["load_average"] = {"before": load_before, "after": os.getloadavg()[0]}
    return fig


def _cell(fig: dict, key: str) -> str:
    ms = {stat: 1e3 * fig[stat][key] for stat in ("median_s", "min_s", "max_s")}
    return f"{ms['median_s']:.0f} ({ms['min_s']:.0f}-{ms['max_s']:.0f})"


def format_table(fig: dict) -> str:
    """The figures as Markdown tables: median (min-max) in ms per phase, then the floors."""
    size = f"{fig['pixels']} x {fig['pixels']}"
    lines = [
        f"lmapd simulate of the paper scene ({size}) in a fresh process: median (min-max) of "
        f"{fig['processes']} processes, caches warm",
    ]
    if "load_average" in fig:
        load = fig["load_average"]
        lines.append(
            f"1-minute load average {load['before']:.2f} before, {load['after']:.2f} after"
        )
    lines += ["", "| phase | ms |", "|---|---|"]
    lines += [f"| {label} | {_cell(fig, key)} |" for key, label in (*PHASES, *DETAILS, *TOTALS)]
    first = [r["first_frame_s"] / r["warm_frame_s"] for r in fig.get("runs", ())]
    if first:
        lines += [
            "",
            f"First frame / warm frame, process by process: {statistics.median(first):.2f} "
            f"({min(first):.2f}-{max(first):.2f})",
        ]
    if "floors" in fig:
        lines += ["", "The floors, a fresh process each round:", "", "| floor | ms |", "|---|---|"]
        lines += [f"| {label} | {_cell(fig['floors'], key)} |" for key, label in FLOORS]
    if "cold_run" in fig:
        cold = fig["cold_run"]
        lines += [
            "",
            f"On an empty cache (a first run): target load {1e3 * cold['target_load_s']:.0f} ms, "
            f"first frame {1e3 * cold['first_frame_s']:.0f} ms (waiting for the echo kernel "
            f"{1e3 * cold['kernel_wait_s']:.0f} ms), the probe's process "
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
