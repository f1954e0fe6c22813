"""A session's memory is bounded: a frame whose estimated memory exceeds the budget is refused
before any stage runs, the estimate bounds the measured peak of real frames, and a session
process under its address-space limit fails an allocation beyond it alone."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import simcore
from app.engine import Engine, FrameRefused, Request, check_memory, frame_bytes

ROOT = Path(__file__).resolve().parents[2]
PROBE = ROOT / "tests" / "support" / "frame_memory.py"
MIB = 2**20


def test_a_frame_over_the_memory_budget_is_refused_before_any_stage_runs():
    scene = simcore.load_scene()
    heavy = simcore.with_overrides(scene, {"preset": "reference"}, pixels=512, distance_m=20)
    assert frame_bytes(heavy) > 5e9  # 512 x 512 pixels of 64 sub-rays each
    engine = Engine(scene, frame_budget_bytes=512 * MIB)
    with pytest.raises(FrameRefused, match="Pixels") as refused:
        engine.compute(Request(heavy))
    assert "GB of memory" in str(refused.value)
    assert engine.pipeline.stages_to_run(heavy)[0] == "target"  # nothing was computed
    with pytest.raises(FrameRefused):  # 1024 x 1024 previews (one ray a pixel): about 1 GB
        engine.compute_preview(Request(simcore.with_overrides(heavy, pixels=1024)))
    assert engine.preview_pipeline.stages_to_run(engine.preview_scene(heavy))[0] == "target"
    check_memory(simcore.with_overrides(heavy, pixels=64), 512 * MIB)  # within it: no refusal


@pytest.mark.slow
@pytest.mark.parametrize(
    ("pixels", "preset", "distance_m"),
    [(64, "reference", 20.0), (256, "interactive", 20.0)],
)
def test_the_estimate_bounds_the_measured_peak_of_a_frame(pixels, preset, distance_m):
    out = subprocess.run(
        [sys.executable, str(PROBE), str(pixels), preset, str(distance_m)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    measured = json.loads(out.stdout.splitlines()[-1])
    peak, estimate = measured["peak_bytes"], measured["estimate_bytes"]
    assert peak > 16 * MIB  # a frame of some size was measured
    assert peak <= estimate <= 2.5 * peak, measured


def test_a_session_over_its_address_space_limit_fails_alone():
    code = (
        "from app.server.process import limit_address_space\n"
        "assert limit_address_space(256 * 2**20)\n"
        "small = bytearray(64 * 2**20)\n"
        "try:\n"
        "    bytearray(2**30)\n"
        "except MemoryError:\n"
        "    print('refused')\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0 and out.stdout.strip() == "refused", out.stderr[-2000:]
