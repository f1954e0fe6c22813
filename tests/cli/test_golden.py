"""Golden outputs: refactors keep behaviour bit for bit.

For fixed seeds, the ``lmapd`` commands' outputs of a few scenes (the paper scene, an oblique pose
with the interactive preset, the waveform Monte Carlo, two fly-around frames) are reduced to a
fingerprint: the summary without its timings, the SHA-256 of every point-cloud file and of every
array in the waveform file (with its dtype and shape). The fingerprints were written by this file
on main at 60a3e29, before the code was reorganised ("One house"), and the reorganisation kept them
bit for bit. They were written again once, on purpose, for the receiver's new physics (Eq. 25 per
sample, first-stop readout, n_dropped over lit pixels, the Monte Carlo's bias removed) and the
summary's receiver.kind; with the old forms selected the old outputs are reproduced
(tests/core/test_stops.py). Any change of a point, a range, a waveform sample or a summary
figure fails here.

Regenerate only for a change that is meant to alter results, and say so in its commit:

    .venv/bin/python tests/cli/test_golden.py --write
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("golden") / "fingerprints.json"

# (name, argv after the subcommand's output options are added)
CASES = {
    "paper": ["simulate"],
    "oblique": [
        "simulate",
        "--preset",
        "interactive",
        "--set",
        "pixels=128",
        "--set",
        "pitch_deg=35",
        "--set",
        "azimuth_deg=-50",
        "--set",
        "distance_m=300",
        "--set",
        "seed=7",
    ],
    "montecarlo": [
        "simulate",
        "--set",
        "fidelity.noise_model=montecarlo",
        "--set",
        "pixels=64",
        "--set",
        "pitch_deg=10",
        "--set",
        "seed=5",
    ],
    "flyaround": [
        "flyaround",
        "--set",
        "pixels=64",
        "--set",
        "seed=2",
        "--duration-s",
        "600",
        "--interval-s",
        "300",
    ],
}
_TIME_KEYS = {"timings_s", "wall_s", "elapsed_s", "time_s", "frame_s"}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _without_timings(value):
    """``value`` with every wall-clock figure removed (they differ from run to run)."""
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k not in _TIME_KEYS}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def _arrays(path: Path) -> dict[str, str]:
    with np.load(path) as npz:
        return {
            name: f"{npz[name].dtype.str} {npz[name].shape} "
            + hashlib.sha256(np.ascontiguousarray(npz[name]).tobytes()).hexdigest()
            for name in sorted(npz.files)
        }


def fingerprint(case: str, tmp: Path) -> dict:
    """Run ``case`` through the ``lmapd`` entry point into ``tmp``; its fingerprint."""
    from simcore.cli import main

    argv = list(CASES[case])
    if argv[0] == "simulate":
        out, summary, waves = tmp / "cloud.ply", tmp / "summary.json", tmp / "waveforms.npz"
        argv += ["--out", str(out), "--summary", str(summary), "--waveforms", str(waves)]
        assert main(argv) == 0
        return {
            "summary": _without_timings(json.loads(summary.read_text())),
            "cloud_sha256": _sha256(out),
            "waveforms": _arrays(waves),
        }
    out_dir = tmp / "fly"
    assert main([*argv, "--out", str(out_dir)]) == 0
    return {
        "summary": _without_timings(json.loads((out_dir / "flyaround.json").read_text())),
        "frames_sha256": {p.name: _sha256(p) for p in sorted(out_dir.glob("frame_*.ply"))},
    }


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_outputs_are_bit_identical_to_the_golden_run(case, tmp_path):
    golden = json.loads(GOLDEN.read_text())[case]
    got = fingerprint(case, tmp_path)
    assert got["summary"] == golden["summary"]
    assert {k: v for k, v in got.items() if k != "summary"} == {
        k: v for k, v in golden.items() if k != "summary"
    }


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/cli/test_golden.py --write")
    prints = {}
    for name in sorted(CASES):
        with tempfile.TemporaryDirectory() as d:
            prints[name] = fingerprint(name, Path(d))
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(prints, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN}")
