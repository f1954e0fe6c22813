"""The memory a frame takes: ``python tests/support/frame_memory.py PIXELS PRESET DISTANCE_M``
prints, for that frame of the paper scene, one JSON line with its peak memory above what the
warmed process held before it [bytes] and app.engine's estimate. The peak is traced
(``tracemalloc``: numpy's arrays report their buffers to it), so it is the frame's own and
repeatable; the resident memory's peak above the process's earlier one is given beside it."""

from __future__ import annotations

import json
import resource
import sys
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import psutil

import simcore
from app.engine import frame_bytes
from simcore.scene import with_overrides


def measure(pixels: int, preset: str, distance_m: float) -> dict:
    scene = with_overrides(
        simcore.load_scene(), {"preset": preset}, pixels=pixels, distance_m=distance_m
    )
    pipeline = simcore.Pipeline()
    pipeline.run(with_overrides(scene, pixels=8))  # the target, the kernels, the tables
    before = max(
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        psutil.Process().memory_info().rss,
    )
    tracemalloc.start()
    pipeline.run(scene)
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    return {
        "pixels": pixels,
        "preset": preset,
        "distance_m": distance_m,
        "peak_bytes": traced_peak,
        "rss_peak_over_bytes": max(0, peak - before),
        "estimate_bytes": frame_bytes(scene),
    }


if __name__ == "__main__":
    args = sys.argv[1:]
    print(json.dumps(measure(int(args[0]), args[1], float(args[2]))), flush=True)
