"""``lmapd bench --gm``: Geiger mode's wall times (issue 41), in fresh processes taken in turn, so
that a busy spell of a shared machine slows every code version alike; prints figures (never
asserted).

    lmapd bench --gm [--rounds 3] [--repeats 3] [--before DIR] [--json FILE] [--quick]

Each round runs, for this code (A) and, with ``before`` (an older checkout, put first on
PYTHONPATH), for that code (B), in turn:

- ``cold``: ``lmapd simulate`` of the paper scene in Geiger mode (``receiver.kind=gm_apd``,
  ``gm.pulses=100``) at 256 x 256, its wall time from a fresh process to its exit, once with the
  user's cache as it is (warm: numba's kernels and the Geiger-mode tables cached) and once with an
  empty table cache (``$LMAPD_CACHE_DIR`` a fresh folder, numba's kernels still cached in
  ``$NUMBA_CACHE_DIR``); linear mode's run beside them;
- ``session``: one process at 128 x 128 (and 256 x 256 without ``--quick``) keeping one
  ``Pipeline``, as the app does: a linear-mode frame, then the first Geiger-mode frame (the
  switch), then ``repeats`` changes each of pitch, pulse energy, TNR and pulses, each to a value
  not seen before (a slider being dragged).

Figures: the median over the rounds (and the repeats) and its range (min-max). The load average
is printed before and after: other processes take cores from the runs.
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

# self-contained (the public API only), so that it also runs on older code (--before)
SESSION_PROBE = r"""
import json, sys, time
from simcore.pipeline import Pipeline
from simcore.scene import Scene, with_overrides

pixels, repeats = int(sys.argv[1]), int(sys.argv[2])
base = with_overrides(Scene(), {"detector.pixels": pixels, "gm.pulses": 100})
pipe = Pipeline()
pipe.run(base)  # linear mode first, as an app session starts
gm = with_overrides(base, {"receiver.kind": "gm_apd"})
t0 = time.perf_counter()
first = pipe.run(gm)
out = {"first_s": time.perf_counter() - t0, "first_stages_s": first.timings_s}
changes = {
    "pitch": lambda i: {"pose.pitch_deg": 2.0 + 1.5 * i},
    "energy": lambda i: {"laser.pulse_energy_j": 5e-3 * (1.0 + 0.13 * (i + 1))},
    "tnr": lambda i: {"timing.tnr": 5.0 + 0.5 * (i + 1)},
    "pulses": lambda i: {"gm.pulses": 100 + 17 * (i + 1)},
}
for name, value in changes.items():
    times, stages = [], []
    for i in range(repeats):
        scene = with_overrides(gm, value(i))
        t0 = time.perf_counter()
        result = pipe.run(scene)
        times.append(time.perf_counter() - t0)
        stages.append(result.timings_s)
    out[name] = {"s": times, "stages_s": stages}
    pipe.run(gm)  # back to the session's scene (cached: nothing recomputed)
sys.stdout.write("\n" + json.dumps(out) + "\n")
"""

SIMULATE = ["simulate", "--set", "gm.pulses=100", "--set", "pixels=256"]


# this code's checkout (the folder holding the simcore package): A's PYTHONPATH
HERE = str(Path(__file__).resolve().parents[3])


def _env(path: str, extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = path + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra or {})
    return env


def _cold_s(path: str, argv: list[str], extra: dict[str, str] | None = None) -> float:
    """Wall time [s] of ``lmapd ARGV`` in a fresh process on the code in ``path`` (run from an
    empty folder: ``-m`` would put the working folder's code first)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "simcore.cli", *argv, "--out", str(Path(tmp) / "c.ply")]
        t0 = time.perf_counter()
        subprocess.run(cmd, env=_env(path, extra), check=True, capture_output=True, cwd=tmp)
        return time.perf_counter() - t0


def _session(path: str, pixels: int, repeats: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run(
            [sys.executable, "-c", SESSION_PROBE, str(pixels), str(repeats)],
            env=_env(path),
            check=True,
            capture_output=True,
            text=True,
            cwd=tmp,
        )
    return json.loads(done.stdout.strip().splitlines()[-1])


def _numba_dir() -> str:
    """The numba cache folder a plain run uses (so that an empty table cache keeps it)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return os.environ["NUMBA_CACHE_DIR"]
    from ...cache import cache_dir  # noqa: PLC0415

    folder = cache_dir()
    return str(folder / "numba") if folder is not None else ""


def run(rounds: int, repeats: int, before: str | None, sizes: tuple[int, ...]) -> dict:
    """The figures of ``rounds`` rounds (module docstring)."""
    versions = {"A": HERE} if before is None else {"A": HERE, "B": str(Path(before).resolve())}
    numba_dir = _numba_dir()
    raw: dict = {v: {"cold_gm": [], "cold_gm_empty": [], "cold_lm": []} for v in versions}
    for v in versions:
        for px in sizes:
            raw[v][f"session_{px}"] = []
    load = [os.getloadavg()[0]]
    for path in versions.values():  # a warm-up run each: numba's kernels and tables cached
        _cold_s(path, [*SIMULATE, "--set", "receiver.kind=gm_apd"])
        _cold_s(path, SIMULATE)
    for _ in range(rounds):
        for v, path in versions.items():
            raw[v]["cold_gm"].append(_cold_s(path, [*SIMULATE, "--set", "receiver.kind=gm_apd"]))
            with tempfile.TemporaryDirectory() as empty:
                extra = {"LMAPD_CACHE_DIR": empty}
                if numba_dir:
                    extra["NUMBA_CACHE_DIR"] = numba_dir
                raw[v]["cold_gm_empty"].append(
                    _cold_s(path, [*SIMULATE, "--set", "receiver.kind=gm_apd"], extra)
                )
            raw[v]["cold_lm"].append(_cold_s(path, SIMULATE))
            for px in sizes:
                raw[v][f"session_{px}"].append(_session(path, px, repeats))
        load.append(os.getloadavg()[0])
    return {"raw": raw, "load": load, "rounds": rounds, "repeats": repeats, "before": before}


def _spread(values) -> str:
    values = list(values)
    return f"{statistics.median(values):.3f} ({min(values):.3f}-{max(values):.3f})"


def format_table(fig: dict) -> str:
    """The figures as a table: one row per measure, one column per code version."""
    versions = list(fig["raw"])
    head = "| measure [s] | " + " | ".join(
        "A: this code" if v == "A" else f"B: {fig['before']}" for v in versions
    )
    lines = [head + " |", "|---" * (len(versions) + 1) + "|"]

    def row(label, get):
        cells = [_spread(get(fig["raw"][v])) for v in versions]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    row("cold lmapd simulate, Geiger mode, 256 x 256", lambda r: r["cold_gm"])
    row("... empty table cache", lambda r: r["cold_gm_empty"])
    row("cold lmapd simulate, linear mode, 256 x 256", lambda r: r["cold_lm"])
    sizes = sorted(int(k.split("_")[1]) for k in fig["raw"]["A"] if k.startswith("session_"))
    for px in sizes:
        key = f"session_{px}"
        row(f"{px} x {px}: first Geiger-mode frame", lambda r, k=key: [s["first_s"] for s in r[k]])
        for change in ("pitch", "energy", "tnr", "pulses"):
            row(
                f"{px} x {px}: {change} change",
                lambda r, k=key, c=change: [t for s in r[k] for t in s[c]["s"]],
            )
    lines.append(
        f"\n{fig['rounds']} rounds, {fig['repeats']} changes of each kind a round; load "
        f"average {min(fig['load']):.1f}-{max(fig['load']):.1f} ({os.cpu_count()} cores)"
    )
    return "\n".join(lines)


def main(rounds: int, repeats: int, json_path: str | None, before: str | None, quick: bool) -> int:
    """Run the Geiger-mode bench and print it."""
    from ..common import say  # noqa: PLC0415

    sizes = (128,) if quick else (128, 256)
    fig = run(rounds, repeats, before, sizes)
    say(format_table(fig))
    if json_path:
        from ...io import write_json  # noqa: PLC0415

        write_json(json_path, fig)
    return 0
