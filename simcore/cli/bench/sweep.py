"""``lmapd bench --sweep``: the same sweep on a Dask LocalCluster of 1 worker, then of 2 workers;
prints figures (never asserted).

    lmapd bench --sweep [--frames 200] [--pixels 128] [--workers 1 2] [--backends kernel numpy]
                        [--repeats 3] [--json FILE] [--quick]

The sweep: the paper scene at PIXELS x PIXELS (4 sub-rays, the default fidelity), a grid of
pitch x azimuth giving FRAMES frames (200 = 20 pitches x 10 azimuths), no point clouds.

What is timed: ``run_sweep`` on a started and warmed cluster, from checking which frames are
done to the Parquet table written, into a fresh folder each time. Excluded (the warm-up): the
cluster start (worker processes importing simcore) and one frame on every worker before the
clock starts (``sweep.warm_workers``), which loads the MRO mesh and builds its BVH there, the
cost paid once per worker. Both clusters are started and warmed first and stay up (idle workers
cost nothing); with ``repeats`` N the configurations then run in turn, N rounds, and each one's
fastest run counts (all are printed): on a shared machine the fastest run is the one least
disturbed by other processes (the median and range of the runs are printed too). The load
average is printed before and after, since other processes take cores from the workers.

With the backends ``kernel numpy`` every worker count gets two clusters: one whose workers compute
the echo features with the compiled kernel (the default) and one whose workers have
``LMAPD_NO_NUMBA=1`` (the numpy path); each cluster's workers are asked which one they use.

Per-frame cost: the sweep's wall time / frames on 1 worker (the throughput of one core,
overheads included) and the median and mean ``frame_s`` of the table (the simulation alone, as
timed on the worker).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ...sweep import build_sweep, run_sweep, warm_workers

_QUIET_LOAD = 0.5  # [-] 1-minute load average above which other processes take cores


def bench_sweep(frames: int, pixels: int):
    """A pitch x azimuth grid of ``frames`` frames (pitches = frames / 10, 10 azimuths)."""
    n_azimuth = 10 if frames % 10 == 0 else 1
    n_pitch = frames // n_azimuth
    pitch = np.round(np.linspace(-60.0, 60.0, n_pitch), 6).tolist()
    azimuth = np.round(np.linspace(0.0, 90.0, n_azimuth), 6).tolist()
    return build_sweep(
        base="paper",
        fixed={"pixels": pixels},
        grid={"pitch_deg": pitch, "azimuth_deg": azimuth},
        name=f"bench-{frames}x{pixels}",
    )


BACKEND_ENV = {"kernel": {}, "numpy": {"LMAPD_NO_NUMBA": "1"}}


def echo_backend() -> str:
    """On a worker: "kernel" if its echo features use the compiled kernel, else "numpy"."""
    try:
        from simcore.echo.features import compiled_kernel  # noqa: PLC0415  (on the worker)
    except ImportError:  # code from before the kernel (a baseline on PYTHONPATH)
        return "numpy"
    return "kernel" if compiled_kernel() is not None else "numpy"


def start_cluster(stack: contextlib.ExitStack, n_workers: int, scene, backend: str) -> dict:
    """A LocalCluster of ``n_workers`` single-threaded processes with the echo ``backend``
    ("kernel" or "numpy"), warmed with ``scene``."""
    from distributed import Client, LocalCluster  # noqa: PLC0415  (Dask: for this bench only)

    t0 = time.perf_counter()
    cluster = stack.enter_context(
        LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
            env=BACKEND_ENV[backend],
        )
    )
    client = stack.enter_context(Client(cluster))
    start_s = time.perf_counter() - t0
    warm_up_s = warm_workers(client, scene)
    used = set(client.run(echo_backend).values())
    if used != {backend}:
        raise SystemExit(f"workers meant for the {backend} path use {used}")
    return {
        "workers": n_workers,
        "backend": backend,
        "client": client,
        "cluster_start_s": start_s,
        "warm_up_s": warm_up_s,
        "wall_s_all": [],
        "frame_s_all": [],
    }


def time_sweep(sweep, run: dict) -> None:
    """One timed sweep on the warm cluster of ``run``, into a fresh folder."""
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as out:
        report = run_sweep(sweep, Path(out), client=run["client"], progress=False)
    if report.n_failed:
        errors = {e for e in report.table.column("error").to_pylist() if e}
        raise SystemExit(f"{report.n_failed} frames failed: {errors}")
    run["wall_s_all"].append(report.wall_s)
    run["frame_s_all"].append(report.table.column("frame_s").to_numpy())


def figures(run: dict) -> dict:
    """The fastest of a configuration's runs, and the frame times of that run."""
    best = int(np.argmin(run["wall_s_all"]))
    times = run["frame_s_all"][best]
    return {
        "workers": run["workers"],
        "backend": run["backend"],
        "cluster_start_s": run["cluster_start_s"],
        "warm_up_s": run["warm_up_s"],
        "wall_s": run["wall_s_all"][best],
        "wall_s_all": run["wall_s_all"],
        "wall_s_median": float(np.median(run["wall_s_all"])),
        "frame_s_median": float(np.median(times)),
        "frame_s_mean": float(np.mean(times)),
    }


def main(
    frames: int = 200,
    pixels: int = 128,
    workers: tuple[int, ...] = (1, 2),
    backends: tuple[str, ...] = ("kernel",),
    repeats: int = 3,
    json_path: str | None = None,
) -> int:
    """Time the sweep of ``frames`` frames at ``pixels`` per side on a warm cluster of each
    worker count and echo backend, ``repeats`` rounds in turn; print the figures and optionally
    write them to ``json_path``."""
    sweep = bench_sweep(frames, pixels)
    n = len(sweep)
    load_before = os.getloadavg()
    print(
        f"sweep: {n} frames at {pixels} x {pixels} pixels, "
        f"{sweep.frames[0].scene.fidelity.subrays} sub-rays; {os.cpu_count()} cores; "
        f"load average {load_before[0]:.2f}",
        file=sys.stderr,
    )
    with contextlib.ExitStack() as stack:  # every cluster up and warm before the first clock
        clusters = [
            start_cluster(stack, w, sweep.frames[0].scene, b) for w in workers for b in backends
        ]
        for _ in range(repeats):  # interleaved, so a busy spell hits every configuration
            for run in clusters:
                time_sweep(sweep, run)
    runs = [figures(run) for run in clusters]
    for r in runs:
        w = r["workers"]
        print(
            f"{w} worker{'s' if w > 1 else ' '} {r['backend']:6}: {r['wall_s']:7.2f} s  "
            f"{1e3 * r['wall_s'] / n:6.1f} ms/frame  {n / r['wall_s']:6.1f} frames/s  "
            f"(frame_s median {1e3 * r['frame_s_median']:.1f} ms, mean "
            f"{1e3 * r['frame_s_mean']:.1f} ms; runs median {r['wall_s_median']:.2f} s: "
            f"{', '.join(f'{x:.2f}' for x in r['wall_s_all'])} s; "
            f"cluster start {r['cluster_start_s']:.1f} s, warm-up {r['warm_up_s']:.1f} s)"
        )
    for b in backends:
        same = [r for r in runs if r["backend"] == b]
        for r in same[1:]:
            print(
                f"speed-up {r['workers']} vs {same[0]['workers']} workers ({b}): "
                f"{same[0]['wall_s'] / r['wall_s']:.2f} x"
            )
    if len(backends) > 1:
        for w in workers:
            by = {r["backend"]: r for r in runs if r["workers"] == w}
            k_all, n_all = by["kernel"]["wall_s_all"], by["numpy"]["wall_s_all"]
            pairs = sorted(y / x for x, y in zip(k_all, n_all, strict=True))
            print(
                f"numpy / kernel on {w} worker{'s' if w > 1 else ''}: fastest runs "
                f"{by['numpy']['wall_s'] / by['kernel']['wall_s']:.2f} x, round by round "
                f"{np.median(pairs):.2f} x ({pairs[0]:.2f}-{pairs[-1]:.2f})"
            )
    load_after = os.getloadavg()
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    if load_before[0] > _QUIET_LOAD:
        print(
            "note: other processes were using the cores; the 2-worker figures are then too slow",
            file=sys.stderr,
        )
    if json_path:
        record = {
            "frames": n,
            "pixels": pixels,
            "cores": os.cpu_count(),
            "load_before": load_before,
            "load_after": load_after,
            "runs": runs,
        }
        Path(json_path).write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return 0
