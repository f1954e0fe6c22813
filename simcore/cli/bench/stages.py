"""``lmapd bench``: median stage timings on the MRO, cached re-run times and peak memory.

A frame's time is the sum of the stages that a pose change re-runs (hits, echo, receiver,
detection, cloud); loading the mesh and building the BVH happen once per target and are reported
apart. Figures are medians over repeats; they are printed, never asserted.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time

from tqdm import tqdm

from ...pipeline import STAGES, Pipeline
from ...scene import load_scene, with_overrides
from ...target import load_target
from ..common import say

FRAME_STAGES = ("hits", "echo", "receiver", "detection", "cloud")

_MEMORY_PROBE = r"""
import sys
import simcore
from simcore.cli.bench.stages import high_water_mb
simcore.load_target(simcore.load_scene().target)
base = high_water_mb()
simcore.simulate(pixels={pixels}, overrides={{"fidelity.subrays": {subrays}}})
sys.stdout.write(f"{{base}} {{high_water_mb()}}\n")
"""


def high_water_mb() -> float:
    """Peak resident memory of this process so far [MB] (VmHWM; ru_maxrss survives exec)."""
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    raise OSError("no VmHWM in /proc/self/status")


def _median_run(pipe: Pipeline, scenes, repeats: int):
    """Run alternating scenes; return median total of FRAME_STAGES and median per stage [s]."""
    pipe.run(scenes[0])
    pipe.run(scenes[1])  # warm both
    per_stage = {s: [] for s in STAGES}
    totals = []
    for i in range(repeats):
        result = pipe.run(scenes[i % 2])
        for s in STAGES:
            per_stage[s].append(result.timings_s[s])
        totals.append(sum(result.timings_s[s] for s in FRAME_STAGES))
    return statistics.median(totals), {s: statistics.median(v) for s, v in per_stage.items()}


def peak_memory_mb(pixels: int, subrays: int) -> tuple[float, float]:
    """Peak RSS [MB] of a fresh process after imports and the mesh load, and after one frame."""
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_PROBE.format(pixels=pixels, subrays=subrays)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1])


def run(quick: bool = False) -> dict:
    repeats = 5 if quick else 15
    sizes = (64, 128, 256) if quick else (64, 128, 256, 512)
    scene = load_scene()
    t0 = time.perf_counter()
    model = load_target(scene.target)
    t_load = time.perf_counter() - t0
    from ...geometry import RayCaster  # noqa: PLC0415

    t0 = time.perf_counter()
    RayCaster(model)
    t_bvh = time.perf_counter() - t0

    pipe = Pipeline()
    rows = []
    configs = [(p, k) for p in sizes for k in (1, 4)]
    for pixels, subrays in tqdm(configs, desc="frames", unit="config", file=sys.stderr):
        base = with_overrides(scene, {"pixels": pixels, "fidelity.subrays": subrays})
        pair = [with_overrides(base, pitch_deg=0.0), with_overrides(base, pitch_deg=0.5)]
        total, stages = _median_run(pipe, pair, repeats)
        rows.append({"pixels": pixels, "subrays": subrays, "frame_s": total, "stages_s": stages})

    base = with_overrides(scene, {"pixels": 256, "fidelity.subrays": 4})
    rerun = {}
    for name, key, values in (
        ("tnr", "tnr", (5.0, 5.1)),
        ("pulse_energy", "pulse_energy_j", (5e-3, 5.1e-3)),
    ):
        pair = [with_overrides(base, {key: v}) for v in values]
        total, _ = _median_run(pipe, pair, repeats * 2)
        rerun[name] = total
    base_mb, peak_mb = peak_memory_mb(256, 16)
    return {
        "mesh_load_s": t_load,
        "bvh_build_s": t_bvh,
        "frames": rows,
        "rerun_256_s": rerun,
        "memory_256x256x16_mb": {"after_imports": base_mb, "peak": peak_mb},
        "repeats": repeats,
    }


def format_table(fig: dict) -> str:
    lines = [
        f"MRO mesh load {fig['mesh_load_s'] * 1e3:.0f} ms, BVH build {fig['bvh_build_s'] * 1e3:.0f}"
        " ms (once per target)",
        "",
        "| pixels | sub-rays | frame (ms) | hits | echo | receiver | detection | cloud |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in fig["frames"]:
        s = r["stages_s"]
        cells = " | ".join(f"{s[k] * 1e3:.1f}" for k in FRAME_STAGES)
        size = f"{r['pixels']} x {r['pixels']}"
        lines.append(f"| {size} | {r['subrays']} | {r['frame_s'] * 1e3:.1f} | {cells} |")
    rr = fig["rerun_256_s"]
    mem = fig["memory_256x256x16_mb"]
    lines += [
        "",
        f"Cached re-run at 256 x 256 x 4: after a TNR change {rr['tnr'] * 1e3:.1f} ms, after a "
        f"pulse-energy change {rr['pulse_energy'] * 1e3:.1f} ms.",
        f"Peak memory (RSS) of a 256 x 256 x 16-sub-ray frame: {mem['peak']:.0f} MB "
        f"({mem['after_imports']:.0f} MB of it is the interpreter, libraries and the MRO).",
    ]
    return "\n".join(lines)


def main(quick: bool = False, json_path: str | None = None) -> int:
    fig = run(quick=quick)
    say(format_table(fig))
    if json_path:
        from ...io import write_json  # noqa: PLC0415

        write_json(json_path, fig)
    return 0
