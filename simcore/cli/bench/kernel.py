"""``lmapd bench --kernel``: the compiled echo kernel (A) against the numpy path (B,
``LMAPD_NO_NUMBA=1``), in fresh processes taken in turn, so that a busy spell of a shared machine
slows both; prints figures (never asserted).

    lmapd bench --kernel [--rounds 3] [--repeats 7] [--before DIR] [--json FILE] [--quick]

Each round runs, for A then B, two fresh processes on the paper scene (the MRO):

- ``default``: the first frame of a 256 x 256 x 4 run, as ``lmapd simulate`` computes it (the
  stages after the target: rays, hits, echo, background, receiver, detection, cloud; the kernel
  loads on a background thread meanwhile, as in ``Pipeline.run``), then ``repeats`` warm frames
  at 256 x 256 x 4 and at 512 x 512 x 4 (the pose nudged between frames, so that every stage after
  the rays re-runs), each followed by the ray cast alone of the same sub-rays (the floor);
- ``reference``: the same for the ``reference`` preset at 256 x 256 (64 sub-rays per pixel).

A process reports the median of its warm frames (frame, echo stage, ray cast, frame / ray cast);
the table gives, for each figure, the median over the rounds and its range (min-max), and the
ratio B / A round by round. With ``before`` (a folder: an older checkout, put first on
PYTHONPATH) a third process runs each time, on the code in it: the speed-up against it. The load
average is printed before and after: other processes take cores from the frames.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

PROBE = r"""
import json, statistics, sys, time
from simcore import geometry, parallel
from simcore.geometry import RayCaster, stage_rays
from simcore.pipeline import Pipeline
from simcore.scene import load_scene, with_overrides
from simcore.target import load_target

# self-contained (no simcore.cli.bench), so that it also runs on older code (--before)
FRAME_STAGES = ("hits", "echo", "background", "receiver", "detection", "cloud")


def ray_cast_s(caster, rays, scene):
    model = caster.model
    pose = geometry.target_pose(scene.pose, model.extents_m, model.body_from_mesh)
    with parallel.blas_serial():
        t0 = time.perf_counter()
        geometry.cast_ranges(caster, rays.directions.reshape(-1, 3), pose)
        return time.perf_counter() - t0


which, repeats = sys.argv[1], int(sys.argv[2])
base = load_scene()
configs = {
    "default": [("256x256x4", {"pixels": 256, "fidelity.subrays": 4}),
                ("512x512x4", {"pixels": 512, "fidelity.subrays": 4})],
    "reference": [("reference 256x256", {"pixels": 256, "preset": "reference"})],
}[which]
pipe = Pipeline()
out, caster = {}, None
for n, (name, keys) in enumerate(configs):
    scene = with_overrides(base, keys)
    result = pipe.run(scene)
    if n == 0:  # the process's first frame: what lmapd simulate computes after the target
        out["cold"] = {
            "target_s": result.timings_s["target"],
            "frame_s": sum(t for s, t in result.timings_s.items() if s != "target"),
            "echo_s": result.timings_s["echo"],
            "stages_s": result.timings_s,
        }
    if caster is None:  # the floor's own caster (the same mesh and BVH as the pipeline's)
        caster = RayCaster(load_target(scene.target))
    rays = stage_rays(scene)
    frames, echoes, casts = [], [], []
    for i in range(repeats):
        nudged = with_overrides(scene, {"pose.roll_deg": 1e-6 * ((i + 1) % 2)})
        result = pipe.run(nudged)
        timings = result.timings_s
        frames.append(sum(timings[s] for s in FRAME_STAGES if s in timings))
        echoes.append(timings["echo"])
        casts.append(ray_cast_s(caster, rays, nudged))
    out[name] = {
        "frame_s": statistics.median(frames),
        "echo_s": statistics.median(echoes),
        "ray_cast_s": statistics.median(casts),
        "ratio": statistics.median(f / c for f, c in zip(frames, casts, strict=True)),
        "n_lit": int(len(result.echo.pixel)),
    }
sys.stdout.write(json.dumps(out) + "\n")
"""

BACKENDS = {"A kernel": {}, "B numpy": {"LMAPD_NO_NUMBA": "1"}}
BEFORE = "C before"  # --before DIR: the code in DIR (an older checkout), in the same rounds


def probe(which: str, repeats: int, env_extra: dict[str, str]) -> dict:
    """One fresh process's figures (the PROBE's JSON) and its wall time ``process_s`` [s]."""
    env = {**os.environ, **env_extra}
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", PROBE, which, str(repeats)],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    fig = json.loads(done.stdout.strip().splitlines()[-1])
    fig["process_s"] = time.perf_counter() - t0
    return fig


def spread(values: list[float], scale: float = 1e3, fmt: str = ".0f") -> str:
    """'median (min-max)' of ``values`` times ``scale``."""
    v = [x * scale for x in values]
    return f"{statistics.median(v):{fmt}} ({min(v):{fmt}}-{max(v):{fmt}})"


def ratios(a: list[float], b: list[float]) -> list[float]:
    """b / a, round by round."""
    return [y / x for x, y in zip(a, b, strict=True)]


def main(
    rounds: int = 3, repeats: int = 7, json_path: str | None = None, before: str | None = None
) -> int:
    """Run ``rounds`` rounds of fresh processes (``repeats`` warm frames each) for A, B (and the
    code in ``before``); print the tables and optionally write the figures to ``json_path``."""
    backends = dict(BACKENDS)
    if before:
        backends[BEFORE] = {"PYTHONPATH": str(Path(before).resolve())}
        probe("default", 1, backends[BEFORE])  # its on-disk caches filled before the clock

    load_before = os.getloadavg()
    print(f"{os.cpu_count()} cores; load average {load_before[0]:.2f}", file=sys.stderr)
    runs: dict[str, dict[str, list[dict]]] = {b: {"default": [], "reference": []} for b in backends}
    for r in range(rounds):
        for which in ("default", "reference"):
            for backend, env in backends.items():
                runs[backend][which].append(probe(which, repeats, env))
        print(f"round {r + 1}/{rounds} done", file=sys.stderr)
    load_after = os.getloadavg()

    def series(backend, which, name, key):
        return [run[name][key] for run in runs[backend][which]]

    rows = [
        ("default", "256x256x4"),
        ("default", "512x512x4"),
        ("reference", "reference 256x256"),
    ]
    a, b = BACKENDS
    print(
        f"{rounds} rounds of fresh processes (A, B in turn); each process the median of "
        f"{repeats} warm frames; median (min-max) over the rounds [ms]"
    )
    print(
        "| frame | A: frame / echo / ray cast (ms) | A: frame / ray cast | "
        "B: frame / echo (ms) | B / A: echo, frame |"
    )
    print("|---|---|---|---|---|")
    for which, name in rows:
        ratio_echo = ratios(series(a, which, name, "echo_s"), series(b, which, name, "echo_s"))
        ratio_frame = ratios(series(a, which, name, "frame_s"), series(b, which, name, "frame_s"))
        print(
            f"| {name} | {spread(series(a, which, name, 'frame_s'))} / "
            f"{spread(series(a, which, name, 'echo_s'))} / "
            f"{spread(series(a, which, name, 'ray_cast_s'))} | "
            f"{spread(series(a, which, name, 'ratio'), 1, '.2f')} | "
            f"{spread(series(b, which, name, 'frame_s'))} / "
            f"{spread(series(b, which, name, 'echo_s'))} | "
            f"{spread(ratio_echo, 1, '.1f')}x, {spread(ratio_frame, 1, '.1f')}x |"
        )
    if before:
        print()
        print(f"{BEFORE} ({before}): frame / echo (ms), and before / A: echo, frame")
        for which, name in rows:
            c = BEFORE
            echo = ratios(series(a, which, name, "echo_s"), series(c, which, name, "echo_s"))
            frame = ratios(series(a, which, name, "frame_s"), series(c, which, name, "frame_s"))
            print(
                f"| {name} | {spread(series(c, which, name, 'frame_s'))} / "
                f"{spread(series(c, which, name, 'echo_s'))} | "
                f"{spread(echo, 1, '.1f')}x, {spread(frame, 1, '.1f')}x |"
            )
    print()
    print("The first frame of a fresh process (cold) against the warm frames' median:")
    print("| run | backend | cold frame (ms) | cold echo (ms) | warm frame (ms) | cold / warm |")
    print("|---|---|---|---|---|---|")
    for which, name in (("default", "256x256x4"), ("reference", "reference 256x256")):
        for backend in backends:
            cold = [run["cold"]["frame_s"] for run in runs[backend][which]]
            warm = series(backend, which, name, "frame_s")
            print(
                f"| {name} | {backend} | {spread(cold)} | "
                f"{spread([run['cold']['echo_s'] for run in runs[backend][which]])} | "
                f"{spread(warm)} | "
                f"{spread([c / w for c, w in zip(cold, warm, strict=True)], 1, '.2f')} |"
            )
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    if json_path:
        record = {
            "rounds": rounds,
            "repeats": repeats,
            "cores": os.cpu_count(),
            "load_before": load_before,
            "load_after": load_after,
            "runs": runs,
        }
        Path(json_path).write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return 0
