"""``lmapd bench --atlas``: the MRO's whole sphere of view directions as ``lmapd atlas`` runs it,
and the quality stage's cost per frame with its samples shared against drawn anew; prints
figures (never asserted).

    lmapd bench --atlas [--pixels N] [--workers 2] [--repeats 7] [--json FILE] [--quick]

1. The quality stage per frame, A against B in one process, interleaved over the same attitudes:
   A as the atlas runs it (the recall's 50,000 area samples of the mesh drawn once per mesh and
   seed, the mesh's closest-point tree built once per mesh), B as every frame made them before
   (both caches emptied before each B frame). Median and range over ``repeats`` x 12
   attitudes.
2. The whole atlas at 10 deg (614 attitudes; 30 deg, 62, with --quick) at ``--pixels`` (64,
   then 128, by default) on a Dask LocalCluster of ``--workers`` single-threaded workers, wall
   time from ``run_atlas``'s call to its table, summary, map and scene files written, the
   cluster's start included (what a user waits for), with its per-attitude frame time as the
   workers timed it.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ... import mesh_distance, quality
from ...atlas import build_atlas, run_atlas
from ...pipeline import Pipeline
from ...scene import load_scene, with_overrides

_ATTITUDES = [(p, a) for p in (-60.0, -20.0, 20.0, 60.0) for a in (0.0, 120.0, 240.0)]


def _quality_ab(pixels: int, repeats: int) -> dict[str, list[float]]:
    """The quality stage's time per frame [s]: shared samples and tree (A) against none (B), in
    turn."""
    base = with_overrides(load_scene("paper"), pixels=pixels)
    pipeline = Pipeline()
    times: dict[str, list[float]] = {"shared": [], "anew": []}
    results = [
        pipeline.run(with_overrides(base, pitch_deg=p, azimuth_deg=a)) for p, a in _ATTITUDES
    ]
    for _ in range(repeats):
        for r in results:
            caster = r.caster
            assert caster is not None  # a pipeline's result has its target's caster
            for mode in ("shared", "anew"):
                if mode == "anew":
                    quality._SAMPLES.clear()
                    mesh_distance.clear()
                t0 = time.perf_counter()
                quality.quality_metrics(
                    r.cloud, caster, r.hits, base.receive.fov_rad, base.quality.tau_m, base.seed
                )
                times[mode].append(time.perf_counter() - t0)
    return times


def _cpu_name() -> str:
    """The CPU's model name (/proc/cpuinfo), or the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "an unknown CPU"


def _spread(values) -> str:
    v = np.asarray(values)
    return f"{np.median(v) * 1e3:.1f} ms ({v.min() * 1e3:.1f}-{v.max() * 1e3:.1f})"


def main(pixels: tuple[int, ...], workers: int, repeats: int, quick: bool, json_path) -> int:
    step = 30.0 if quick else 10.0
    figures: dict = {
        "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
        "machine": {"cpu": _cpu_name(), "cpus": os.cpu_count(), "platform": platform.platform()},
        "load_average": os.getloadavg()[0],
        "step_deg": step,
        "workers": workers,
        "quality_pixels": pixels[0],
    }
    print(f"lmapd bench --atlas: load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    times = _quality_ab(pixels[0], repeats)
    print(
        f"quality stage per frame at {pixels[0]} px, {len(_ATTITUDES)} attitudes x {repeats}, "
        f"interleaved: samples and closest-point tree shared {_spread(times['shared'])}, "
        f"made anew for each frame {_spread(times['anew'])}"
    )
    figures["quality_s"] = times
    figures["atlas"] = []
    for px in pixels:
        atlas = build_atlas(with_overrides(load_scene("paper"), pixels=px), step)
        with tempfile.TemporaryDirectory(prefix="lmapd-bench-atlas-") as tmp:
            t0 = time.perf_counter()
            report = run_atlas(atlas, Path(tmp) / "atlas", workers=workers, progress=False)
            wall_s = time.perf_counter() - t0
        frame_s = [s for s in report.table.column("frame_s").to_pylist() if s is not None]
        print(
            f"atlas of the MRO at {px} x {px} px, {len(atlas)} attitudes ({step:g} deg) on "
            f"{report.n_workers} workers: {wall_s:.1f} s wall, the cluster's start and the map "
            f"included; a frame with its quality figures {_spread(frame_s)} on a worker"
        )
        figures["atlas"].append(
            {"pixels": px, "n_attitudes": len(atlas), "wall_s": wall_s, "frame_s": frame_s}
        )
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if json_path:
        Path(json_path).write_text(json.dumps(figures, indent=1) + "\n", encoding="utf-8")
    sys.stdout.flush()
    return 0
