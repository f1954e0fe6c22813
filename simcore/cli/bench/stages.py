"""``lmapd bench``: median stage timings on the MRO, cached re-run times and peak memory.

A frame's time is the sum of the stages that a pose change re-runs (hits, echo, background,
receiver, detection, cloud); loading the mesh and building the BVH happen once per target and are
reported apart. Beside each frame the bench times the floor, the ray cast alone (every sub-ray of
the frame into the target frame and through Embree, :func:`simcore.geometry.cast_ranges`, on the
frame's threads), interleaved with the frames so that a busy spell of a shared machine slows both;
the frame / ray-cast ratio is taken round by round. Figures are medians with their range (min-max)
over the repeats; they are printed, never asserted.

The frames run on ``simcore.parallel.threads()`` threads (printed, with the rays per second per
core of each ray cast). The scaling table then takes the 256 x 256 x 4 frame (and 512 x 512 x 4
without ``--quick``) and the waveform Monte Carlo of 128 x 128 pixels over a 1 km gate (the
detection stage of ``fidelity.noise_model = "montecarlo"``) at 1, 2, 4, ... threads up to the
cores this process may use, the thread counts in turn within each round, so that a busy spell
slows them alike; the speed-up against one thread is taken round by round. Each frame's round
also times :meth:`simcore.geometry.RayCaster.first_hits` on the frame's rays in the target frame
and Embree alone on the same rays (made float32 beforehand, one equal chunk per thread): the
ratio first hits / raw Embree is the caster's cost over Embree's own at each thread count.
"""

from __future__ import annotations

import datetime
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from ... import geometry, parallel
from ...pipeline import STAGES, Pipeline
from ...scene import load_scene, with_overrides
from ...target import load_target
from ..common import say

FRAME_STAGES = ("hits", "echo", "background", "receiver", "detection", "cloud")

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


def _spread(values) -> dict[str, float]:
    """Median, min and max of ``values``."""
    values = list(values)
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def ray_cast_s(caster: geometry.RayCaster, rays, scene) -> float:
    """Wall time [s] of the ray cast alone: every sub-ray of ``rays`` (a RayGrid, or (n, 3) unit
    sensor-frame directions) for the target in the scene's pose (into the target frame, through
    Embree, ranges and faces out), as the hits stage casts them, on the frame's threads with BLAS
    serial."""
    model = caster.model
    pose = geometry.target_pose(scene.pose, model.extents_m, model.body_from_mesh)
    directions = rays.directions if isinstance(rays, geometry.RayGrid) else rays
    directions = directions.reshape(-1, 3)
    with parallel.blas_serial():
        t0 = time.perf_counter()
        geometry.cast_ranges(caster, directions, pose)
        return time.perf_counter() - t0


@dataclass(frozen=True)
class CastInputs:
    """The rays of a frame as :meth:`RayCaster.first_hits` takes them (target frame, float64) and
    as Embree itself takes them (float32 start points at the tracing start, and directions)."""

    origin_t: np.ndarray
    directions_t: np.ndarray
    start_m: float
    starts32: np.ndarray
    directions32: np.ndarray


def cast_inputs(caster: geometry.RayCaster, rays, scene) -> CastInputs:
    """The sub-rays of ``rays`` (a RayGrid) for the target in the scene's pose (turned with BLAS
    serial: a multi-threaded product leaves OpenBLAS's threads spinning on the cores that the
    timings after it need; measured, a 2-thread frame then ran no faster than on one thread)."""
    model = caster.model
    pose = geometry.target_pose(scene.pose, model.extents_m, model.body_from_mesh)
    dirs_s = rays.directions.reshape(-1, 3)
    with parallel.blas_serial():
        dirs_t = dirs_s @ pose.rotation
    origin_t = -pose.rotation.T @ pose.translation_m
    start = max(0.0, float(np.linalg.norm(pose.translation_m)) - 1.05 * model.radius_m)
    starts = np.ascontiguousarray((origin_t[None, :] + start * dirs_t).astype(np.float32))
    return CastInputs(origin_t, dirs_t, start, starts, np.ascontiguousarray(dirs_t, np.float32))


def first_hits_s(caster: geometry.RayCaster, rays: CastInputs) -> float:
    """Wall time [s] of :meth:`RayCaster.first_hits` on target-frame rays (the caster's own
    work: float32 rays made per chunk, ranges and faces out), on the frame's threads."""
    t0 = time.perf_counter()
    caster.first_hits(rays.origin_t, rays.directions_t, rays.start_m)
    return time.perf_counter() - t0


def raw_embree_s(caster: geometry.RayCaster, rays: CastInputs) -> float:
    """Wall time [s] of Embree alone on the same rays, made float32 beforehand: one equal chunk
    per thread of the frame, each thread one query (the floor of :func:`first_hits_s`)."""
    n = len(rays.starts32)
    bounds = np.linspace(0, n, parallel.threads() + 1).astype(int)
    chunks = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    t0 = time.perf_counter()
    parallel.map_threads(
        lambda part: caster.embree_hits(rays.starts32[part], rays.directions32[part]), chunks
    )
    return time.perf_counter() - t0


def thread_counts(cores: int | None = None) -> list[int]:
    """1, 2, 4, ... up to ``cores`` (the cores this process may use), and ``cores`` itself."""
    cores = parallel.available_cores() if cores is None else max(1, int(cores))
    counts = [1]
    while counts[-1] * 2 <= cores:
        counts.append(counts[-1] * 2)
    if counts[-1] != cores:
        counts.append(cores)
    return counts


def scaling(pipe: Pipeline, scene, counts, repeats: int, caster=None, stage: str | None = None):
    """Time ``scene``'s frame (or one ``stage`` of it) at each thread count of ``counts``, the
    counts in turn within each of ``repeats`` rounds; three poses (pitch 0, 0.5, 1 deg) or, for
    a stage, three seeds in rotation, so that every run computes anew. With ``caster`` each frame
    is followed by the ray cast alone of its sub-rays on the same threads, then by
    :meth:`RayCaster.first_hits` and by Embree alone on the same target-frame rays.

    Returns one row per count: threads, frame_s (or the stage's) and ray_cast_s (median, min,
    max [s]), the speed-ups against the first count taken round by round, the ray cast's rays
    per second per core (per thread), first_hits_s and raw_embree_s (median, min, max [s]) and
    first_hits_over_raw (their ratio, round by round)."""
    if stage is None:
        variants = [with_overrides(scene, pitch_deg=p) for p in (0.0, 0.5, 1.0)]
    else:
        variants = [with_overrides(scene, seed=scene.seed + k) for k in range(3)]
    rays = geometry.stage_rays(scene) if caster is not None else None
    before = parallel.threads()
    frames: dict[int, list[float]] = {t: [] for t in counts}
    casts: dict[int, list[float]] = {t: [] for t in counts}
    hits: dict[int, list[float]] = {t: [] for t in counts}
    raws: dict[int, list[float]] = {t: [] for t in counts}
    inputs = {v.pose: cast_inputs(caster, rays, v) for v in variants} if caster else {}
    k = 1  # the first timed run takes the third variant: the last warm one was the second
    try:
        for t in counts:  # warm each thread count
            parallel.set_threads(t)
            for v in variants[:2]:
                pipe.run(v)
        for _ in range(repeats):
            for t in counts:
                parallel.set_threads(t)
                k += 1
                variant = variants[k % 3]
                result = pipe.run(variant)
                stages = (stage,) if stage else FRAME_STAGES
                frames[t].append(sum(result.timings_s[s] for s in stages))
                if caster is not None:
                    casts[t].append(ray_cast_s(caster, rays, variant))
                    hits[t].append(first_hits_s(caster, inputs[variant.pose]))
                    raws[t].append(raw_embree_s(caster, inputs[variant.pose]))
    finally:
        parallel.set_threads(before)
    n_rays = len(rays.directions.reshape(-1, 3)) if rays is not None else 0
    rows = []
    for t in counts:
        row = {
            "threads": t,
            "frame_s": _spread(frames[t]),
            "speedup": _spread(a / b for a, b in zip(frames[counts[0]], frames[t], strict=True)),
        }
        if casts[t]:
            row["ray_cast_s"] = _spread(casts[t])
            row["ray_cast_speedup"] = _spread(
                a / b for a, b in zip(casts[counts[0]], casts[t], strict=True)
            )
            row["rays_per_s_per_core"] = n_rays / statistics.median(casts[t]) / t
            row["first_hits_s"] = _spread(hits[t])
            row["raw_embree_s"] = _spread(raws[t])
            row["first_hits_over_raw"] = _spread(
                a / b for a, b in zip(hits[t], raws[t], strict=True)
            )
        rows.append(row)
    return rows


def _median_run(pipe: Pipeline, scenes, repeats: int, caster=None, rays=None):
    """Run alternating scenes; return the median total of FRAME_STAGES [s], the median per stage
    [s] and the frames' range; with ``caster`` and ``rays`` also the ray cast alone, timed after
    each frame (median, min, max [s]), and the frame / ray-cast ratio taken round by round."""
    pipe.run(scenes[0])
    pipe.run(scenes[1])  # warm both
    per_stage: dict[str, list[float]] = {s: [] for s in STAGES}
    totals, casts = [], []
    for i in range(repeats):
        result = pipe.run(scenes[i % 2])
        for s in STAGES:
            per_stage[s].append(result.timings_s[s])
        totals.append(sum(result.timings_s[s] for s in FRAME_STAGES))
        if caster is not None:
            casts.append(ray_cast_s(caster, rays, scenes[i % 2]))
    stages = {s: statistics.median(v) for s, v in per_stage.items()}
    floor = {"frame_spread_s": _spread(totals)}
    if casts:
        floor["ray_cast_s"] = _spread(casts)
        floor["ratio"] = _spread(t / c for t, c in zip(totals, casts, strict=True))
    return statistics.median(totals), stages, floor


def peak_memory_mb(pixels: int, subrays: int) -> tuple[float, float]:
    """Peak RSS [MB] of a fresh process after imports and the mesh load, and after one frame."""
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_PROBE.format(pixels=pixels, subrays=subrays)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1])


def machine() -> dict[str, object]:
    """What the figures were measured on: the CPU's model name, the CPUs this process may use,
    the Python and the operating system."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            names = [ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu,
        "cpus": cpus,
        "python": platform.python_version(),
        "platform": platform.platform(terse=True),
    }


def run(quick: bool = False) -> dict:
    started = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M")
    repeats = 5 if quick else 15
    sizes = (64, 128, 256) if quick else (64, 128, 256, 512)
    load_before = os.getloadavg()
    scene = load_scene()
    t0 = time.perf_counter()
    model = load_target(scene.target)
    t_load = time.perf_counter() - t0

    t0 = time.perf_counter()
    caster = geometry.RayCaster(model)
    t_bvh = time.perf_counter() - t0

    pipe = Pipeline()
    rows = []
    configs = [(p, k) for p in sizes for k in (1, 4)]
    for pixels, subrays in tqdm(configs, desc="frames", unit="config", file=sys.stderr):
        base = with_overrides(scene, {"pixels": pixels, "fidelity.subrays": subrays})
        pair = [with_overrides(base, pitch_deg=0.0), with_overrides(base, pitch_deg=0.5)]
        rays = geometry.stage_rays(base)
        total, stages, floor = _median_run(pipe, pair, repeats, caster, rays)
        row = {"pixels": pixels, "subrays": subrays, "frame_s": total, "stages_s": stages}
        if "ray_cast_s" in floor:
            n_rays = pixels * pixels * subrays
            floor["rays_per_s_per_core"] = (
                n_rays / floor["ray_cast_s"]["median"] / parallel.threads()
            )
        rows.append({**row, **floor})

    base = with_overrides(scene, {"pixels": 256, "fidelity.subrays": 4})
    rerun = {}
    for name, key, values in (
        ("tnr", "tnr", (5.0, 5.1)),
        ("pulse_energy", "pulse_energy_j", (5e-3, 5.1e-3)),
    ):
        pair = [with_overrides(base, {key: v}) for v in values]
        total, _, _ = _median_run(pipe, pair, repeats * 2)
        rerun[name] = total
    base_mb, peak_mb = peak_memory_mb(256, 16)
    counts = thread_counts()
    scaled = []
    for pixels in (256,) if quick else (256, 512):
        frame = with_overrides(scene, {"pixels": pixels, "fidelity.subrays": 4})
        scaled.append(
            {
                "what": f"{pixels} x {pixels} x 4 frame",
                "rows": scaling(pipe, frame, counts, repeats, caster),
            }
        )
    mc = with_overrides(
        scene,
        {"pixels": 128, "fidelity.noise_model": "montecarlo", "timing.range_gate_m": 1000.0},
    )
    mc_pipe = Pipeline()
    mc_pipe.adopt(pipe)
    scaled.append(
        {
            "what": "Monte Carlo 128 x 128 over 1 km (detection stage)",
            "rows": scaling(mc_pipe, mc, counts, 3 if quick else 5, stage="detection"),
        }
    )
    return {
        "threads": parallel.threads(),
        "scaling": scaled,
        "mesh_load_s": t_load,
        "bvh_build_s": t_bvh,
        "frames": rows,
        "rerun_256_s": rerun,
        "memory_256x256x16_mb": {"after_imports": base_mb, "peak": peak_mb},
        "repeats": repeats,
        "quick": quick,
        "load_average": {"before": load_before[0], "after": os.getloadavg()[0]},
        "date_utc": started,
        "machine": machine(),
    }


def _ms(spread: dict[str, float]) -> str:
    return f"{spread['median'] * 1e3:.1f} ({spread['min'] * 1e3:.1f}-{spread['max'] * 1e3:.1f})"


def format_table(fig: dict) -> str:
    lines = [
        f"MRO mesh load {fig['mesh_load_s'] * 1e3:.0f} ms, BVH build {fig['bvh_build_s'] * 1e3:.0f}"
        " ms (once per target)",
    ]
    if "load_average" in fig:
        load = fig["load_average"]
        lines.append(
            f"{fig['repeats']} frames per configuration, median (min-max); 1-minute load average "
            f"{load['before']:.2f} before, {load['after']:.2f} after"
        )
    if "threads" in fig:
        cpus = fig.get("machine", {}).get("cpus", "?")
        lines.append(f"Frames on {fig['threads']} threads ({cpus} CPUs this process may use)")
    lines += [
        "",
        "| pixels | sub-rays | frame (ms) | ray cast alone (ms) | frame / ray cast | hits | echo "
        "| background | receiver | detection | cloud | Mrays/s per core |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in fig["frames"]:
        s = r["stages_s"]
        cells = " | ".join(f"{s[k] * 1e3:.1f}" for k in FRAME_STAGES)
        size = f"{r['pixels']} x {r['pixels']}"
        frame = _ms(r["frame_spread_s"]) if "frame_spread_s" in r else f"{r['frame_s'] * 1e3:.1f}"
        if "ray_cast_s" in r:
            q = r["ratio"]
            cast = _ms(r["ray_cast_s"])
            ratio = f"{q['median']:.2f} ({q['min']:.2f}-{q['max']:.2f})"
        else:
            cast = ratio = "-"
        rate = r.get("rays_per_s_per_core")
        per_core = f"{rate / 1e6:.2f}" if rate else "-"
        lines.append(
            f"| {size} | {r['subrays']} | {frame} | {cast} | {ratio} | {cells} | {per_core} |"
        )
    rr = fig["rerun_256_s"]
    mem = fig["memory_256x256x16_mb"]
    lines += [
        "",
        f"Cached re-run at 256 x 256 x 4: after a TNR change {rr['tnr'] * 1e3:.1f} ms, after a "
        f"pulse-energy change {rr['pulse_energy'] * 1e3:.1f} ms.",
        f"Peak memory (RSS) of a 256 x 256 x 16-sub-ray frame: {mem['peak']:.0f} MB "
        f"({mem['after_imports']:.0f} MB of it is the interpreter, libraries and the MRO).",
    ]
    lines += format_scaling(fig.get("scaling", []))
    return "\n".join(lines)


def format_scaling(tables: list[dict]) -> list[str]:
    """The scaling tables: each thread count's time and its speed-up against one thread (median
    (min-max), round by round), with the ray cast's rays per second per core (per thread)."""
    lines: list[str] = []
    for table in tables:
        has_cast = any("ray_cast_s" in r for r in table["rows"])
        lines += ["", f"Scaling, {table['what']}:", ""]
        if has_cast:
            lines += [
                "| threads | frame (ms) | speed-up | ray cast alone (ms) | speed-up "
                "| Mrays/s per core | first hits (ms) | raw Embree (ms) | first hits / raw |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
        else:
            lines += ["| threads | time (ms) | speed-up |", "|---|---|---|"]
        for r in table["rows"]:
            q = r["speedup"]
            cells = [
                str(r["threads"]),
                _ms(r["frame_s"]),
                f"{q['median']:.2f} ({q['min']:.2f}-{q['max']:.2f})",
            ]
            if has_cast:
                c = r["ray_cast_speedup"]
                cells += [
                    _ms(r["ray_cast_s"]),
                    f"{c['median']:.2f} ({c['min']:.2f}-{c['max']:.2f})",
                    f"{r['rays_per_s_per_core'] / 1e6:.2f}",
                ]
                if "first_hits_over_raw" in r:
                    q = r["first_hits_over_raw"]
                    cells += [
                        _ms(r["first_hits_s"]),
                        _ms(r["raw_embree_s"]),
                        f"{q['median']:.2f} ({q['min']:.2f}-{q['max']:.2f})",
                    ]
                else:
                    cells += ["-", "-", "-"]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(quick: bool = False, json_path: str | None = None) -> int:
    fig = run(quick=quick)
    say(format_table(fig))
    if json_path:
        from ...io import write_json  # noqa: PLC0415

        write_json(json_path, fig)
    return 0
