"""Benchmark: the Attitudes panel's first level and the levels after it, on the paper scene.

An app like a session's (the paper scene, its first frame shown, the engine warm), then the
panel's button ``--runs`` times (the pitch moved by one degree between runs, which keeps the map's
scene: every attitude is computed again by each run, the map's pipeline caches only its last
frame). Prints, per run, the seconds from the click to each level on screen, and the medians.

    PYTHONPATH=$PWD python scripts/bench_attitudes.py --runs 3 --levels 45 22.5
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import simcore
from app.engine import Engine
from app.main import LmapdApp


def one_map(app: LmapdApp) -> list[float]:
    """The seconds from the button to each level on the page, and the process's CPU seconds by
    then (the frames' runner is idle: the map's), level by level."""
    logic = app.logic.attitudes
    seen: list[float] = []
    draw = logic._show_level
    start, cpu_start = time.perf_counter(), time.process_time()

    def timed(epoch, level):
        seen.append(time.perf_counter() - start)
        seen.append(time.process_time() - cpu_start)
        draw(epoch, level)

    logic._show_level = timed
    app.server.controller.trigger_fn("attitudes_compute")()
    assert logic.runner.wait_idle(600)
    logic._show_level = draw
    return seen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--levels", type=float, nargs="+", default=[45.0, 22.5])
    args = parser.parse_args()
    scene = simcore.load_scene()
    app = LmapdApp(scene, engine=Engine(scene), flow_control=False, debounce_s=0.0)
    app.state.ready()
    assert app.logic.runner.wait_idle(300)
    app.logic.attitudes.levels_deg = tuple(args.levels)
    runs = []
    for i in range(args.runs):
        with app.state:
            app.state.pitch_deg = float(i % 2)
        assert app.logic.runner.wait_idle(300)
        load = os.getloadavg()[0]
        times = one_map(app)
        runs.append(times)
        levels = zip(args.levels, times[::2], times[1::2], strict=True)
        said = ", ".join(f"{s:g} deg {t:.2f} s ({c:.2f} CPU s)" for s, t, c in levels)
        print(f"run {i + 1}: {said} (load average {load:.1f} on {os.cpu_count()} cores)")
    for k, step in enumerate(args.levels):
        for what, j in (("on screen", 2 * k), ("CPU", 2 * k + 1)):
            values = sorted(r[j] for r in runs)
            print(
                f"{step:g} deg level, {what}: median {statistics.median(values):.2f} s "
                f"(range {values[0]:.2f}-{values[-1]:.2f} s, {len(values)} runs)"
            )
    app.logic.runner.close()
    app.logic.attitudes.runner.close()


if __name__ == "__main__":
    main()
