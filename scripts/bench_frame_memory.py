"""Benchmark of the launcher's memory budget for frames across sessions: a class whose every tab
asks for the heaviest frame it may at once.

    .venv/bin/python scripts/bench_frame_memory.py [--sessions 30] [--presets reference]
        [--frames-in-flight-mb MB]

For each fidelity preset it starts ``lmapd app`` (sessions forked, no spare; the budget its
default unless ``--frames-in-flight-mb``), opens N sessions one after the other as a class would
(the door, the websocket, the first frame), sums the proportional set size (PSS) of the launcher
and every process under it (the baseline), then has every session ask at once for the heaviest
frame the per-session limit allows at that preset (the most pixels, in the slider's steps, whose
estimate is within ``--frame-memory-mb``) and waits until each page has its frame or a message.
The tree's PSS is sampled every 50 ms meanwhile. It prints, per preset: the frame, its estimate,
the budget, the baseline, the peak and the peak's growth, the tree's PSS once every frame is
done (what the sessions keep of their frames: their stages' caches), how many pages got their
frame, a refusal or nothing, how many were told to wait, and whether every session's process is
still alive (none killed by the kernel's memory killer).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import signal
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the drivers: support.*

import aiohttp
import psutil
from support.frame_sessions import (
    PeakSampler,
    close_page,
    heavy_frame,
    open_page,
    tree_pss_bytes,
)
from support.launch import app_process

import simcore
from app.engine import FRAME_BUDGET_BYTES, frame_bytes
from app.state import SPECS

MIB = 2**20
BUDGET_LINE = re.compile(r"heavy frames in flight across the sessions may take ([\d,]+) MB")


def heaviest(preset: str, limit_bytes: int = FRAME_BUDGET_BYTES) -> tuple[int, int]:
    """The most pixels (in the slider's steps) whose frame at ``preset`` is within the
    per-session limit, and that frame's estimate [bytes]."""
    spec = SPECS["pixels"]
    scene = simcore.load_scene()
    best = (int(spec.lo), 0)
    pixels = int(spec.lo)
    while pixels <= spec.hi:
        need = frame_bytes(simcore.with_overrides(scene, simcore.PRESETS[preset], pixels=pixels))
        if need <= limit_bytes:
            best = (pixels, need)
        pixels += int(spec.step)
    return best


async def one_preset(preset: str, n: int, frames_mb: float | None) -> dict:
    pixels, need = heaviest(preset)
    args = ["--no-spare", "--fork-sessions", "--max-sessions", str(n + 1)]
    if frames_mb is not None:
        args += ["--frames-in-flight-mb", f"{frames_mb:g}"]
    with tempfile.TemporaryDirectory() as folder:
        log_path = Path(folder) / "launcher.log"
        with app_process(sessions=True, app_args=tuple(args), log_path=log_path) as running:
            token = running.token
            base = running.origin
            found = BUDGET_LINE.search(log_path.read_text())
            budget_mb = float(found[1].replace(",", "")) if found else float("nan")
            async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as client:
                pages = [await open_page(client, base, token) for _ in range(n)]
                await asyncio.sleep(2.0)
                sessions_before = _sessions(running.pid)
                baseline = tree_pss_bytes(running.pid)
                started = time.perf_counter()
                with PeakSampler(running.pid) as peak:
                    outcomes = await asyncio.gather(
                        *(
                            heavy_frame(page, state, preset=preset, pixels=pixels)
                            for page, state, _ in pages
                        )
                    )
                wall_s = time.perf_counter() - started
                await asyncio.sleep(2.0)
                after = tree_pss_bytes(running.pid)  # what the sessions keep of their frames
                sessions_after = _sessions(running.pid)
                for page, _, _ in pages:
                    await close_page(page)
            log = log_path.read_text()
    return {
        "preset": preset,
        "pixels": pixels,
        "need_mb": need / MIB,
        "budget_mb": budget_mb,
        "baseline_mb": baseline / MIB,
        "peak_mb": peak.peak_bytes / MIB,
        "after_mb": after / MIB,
        "samples": peak.n_samples,
        "frames": sum(o["frame"] for o in outcomes),
        "refused": sum(bool(o["error"]) for o in outcomes),
        "nothing": sum(not o["frame"] and not o["error"] for o in outcomes),
        "waited": sum(bool(o["waits"]) for o in outcomes),
        "alive": len(sessions_after & sessions_before),
        "exited": log.count("its process exited"),
        "wall_s": wall_s,
        "errors": sorted({o["error"][:120] for o in outcomes if o["error"]}),
    }


def _sessions(launcher_pid: int) -> set[int]:
    """The session processes under the launcher (the zygote's children)."""
    try:
        procs = psutil.Process(launcher_pid).children(recursive=True)
    except psutil.Error:
        return set()
    return {p.pid for p in procs if p.ppid() != launcher_pid}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=int, default=30)
    parser.add_argument(
        "--presets",
        nargs="+",
        choices=tuple(simcore.PRESETS),
        default=list(simcore.PRESETS),
    )
    parser.add_argument("--frames-in-flight-mb", type=float, default=None)
    args = parser.parse_args(argv)
    # stopped by SIGTERM: the launcher is still stopped (app_process's cleanup runs)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    memory = psutil.virtual_memory()
    print(
        f"machine: {os.cpu_count()} cores, {memory.total / 1e9:.1f} GB, "
        f"{memory.available / 1e9:.1f} GB available; load {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    for preset in args.presets:
        r = asyncio.run(one_preset(preset, args.sessions, args.frames_in_flight_mb))
        growth = r["peak_mb"] - r["baseline_mb"]
        print(
            f"{preset}: {args.sessions} sessions each asking {r['pixels']} px "
            f"(estimate {r['need_mb']:,.0f} MB) at once; budget {r['budget_mb']:,.0f} MB; "
            f"tree PSS {r['baseline_mb']:,.0f} MB before, peak {r['peak_mb']:,.0f} MB "
            f"(+{growth:,.0f} MB, {r['samples']} samples), {r['after_mb']:,.0f} MB after; "
            f"frames {r['frames']}, refused "
            f"{r['refused']}, no answer {r['nothing']}; told to wait {r['waited']}; sessions "
            f"alive after {r['alive']}/{args.sessions}, exited {r['exited']}; "
            f"{r['wall_s']:.0f} s; load {os.getloadavg()[0]:.1f}",
            flush=True,
        )
        for error in r["errors"]:
            print(f"  message: {error}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
