"""Golden outputs: refactors keep behaviour.

For fixed seeds, the ``lmapd`` commands' outputs of a few scenes (the paper scene, an oblique pose
with the interactive preset, the waveform Monte Carlo, two fly-around frames) are reduced to a
fingerprint: the summary without its timings; for every point-cloud file and every array of the
waveform file, its size and each column's sum, sum of squares, minimum and maximum; and the SHA-256
of each file and array.

Where the golden run was made (the same CPU model, instruction set and library versions: the
fingerprint's ``platform``) everything must match bit for bit, hashes included. On another machine
the hashes are not compared and floating-point figures must agree to ``RTOL``: Embree casts rays in
single precision with code chosen for the CPU (AVX2, AVX-512), so hit distances differ in their
last float32 bits between CPUs, about 1e-8 relative downstream (measured: range sigma medians
4e-8 apart, P_d means 1e-11, between the machine of the golden run of 2026-11-23 and an AMD
EPYC of 2026-11-25). RTOL = 1e-6 is eight float32 ulps: on another machine a change of the
ranges by more than about 0.5 mm at 500 m, and any change of a count, pixel, material or facet,
still fails; on the golden's own platform every bit counts. A figure that is a difference of
ranges (a point's range error, a part's bias: a few millimetres) carries the ranges' last bits,
not its own: between an AVX-512 and an AVX2 EPYC (2026-12-02) a part's 0.2 mm bias moved 1e-9 m
(5e-6 of itself) and a range-error column's sum 5e-5 m. Those are compared to RTOL of a 1 km
range (1 mm a point, n times it for a column's sum).

The fingerprints were written by this file on main at 60a3e29, before the code was reorganised
("One house"), and the reorganisation kept them bit for bit. They were written again once, on
purpose, for the receiver's new physics (Eq. 25 per
sample, first-stop readout, n_dropped over lit pixels, the Monte Carlo's bias removed) and the
summary's receiver.kind; with the old forms selected the old outputs are reproduced
(tests/core/test_stops.py). They took this form (column sums beside the hashes, the platform)
on 2026-11-25, from unchanged code: its summaries agreed with the previous golden ones within RTOL
and every count exactly. Written again on 2026-11-26 for new figures and columns: every existing
column of every cloud and every summary figure agreed with the previous fingerprints within RTOL
(point positions unchanged), but for the changes meant: the MRO's credit ("Courtesy
NASA/JPL-Caltech"), n_false_expected now the false points expected in the cloud (the crossings
it was are n_false_crossings_expected), and the oblique case's x column moved 3 mm in sum by the
statistical model's gross errors at low SNR (docs/physics.md#gross-errors); the new ones are
the ground truth's columns and the summary's quality, false-points and gm.* keys. Written again
on 2026-11-26 for the Monte Carlo's new noise draw (one stream per pixel, white noise on every
second sample: docs/physics.md#mc-noise-draw): the montecarlo case's draws change (its counts
move by a few: 7 -> 12 outliers, 14 -> 19 dropped), and through the gross-error tables the Monte
Carlo makes, the paper and oblique cases' gross errors (one fewer in the oblique case; range sums
within 0.4 m of 1.7e6 m); the Monte Carlo's statistical tests are the guard. On 2026-12-02 the
scene's new ``[trajectory]`` section (its defaults) was added to every case's summary, and the
fly-around's ground truth (``truth`` per frame, ``trajectory``, ``conventions``), and the quality
block's new figures (recall_sd, recall_projected, recall_cap, recall_projected_cap,
seen_projected_area_m2): those entries only; every other figure, column and hash agreed, but one
fly-around Sun angle in its 16th digit (the run was on another CPU: an AMD EPYC, where the
previous one was an Intel Xeon). Written again the same day (issue 43) for the figures renamed:
quality.range_rmse_m now along each point's line of sight (the old figure, equal to it, is
range_rmse_surface_m), outlier_fraction split into target_outlier_fraction and
false_alarm_fraction, the distance_to_mesh_* figures new; and for the continuous arming's
sub-samples now passing through the samples, which moves the Monte Carlo's gross-error tables:
the oblique case's range_error_m sum by 0.9 mm over 5,801 points; and the geiger_day case's
snr_median 9.4e-16 -> 0 (a count SNR under 1e-6 expected echo counts is 0). And for Geiger
mode's compiled Coates sums (the same terms added in another order): geiger_day's
gm.range_bias_m by 7.7e-14 relative, gm.range_sigma_m by 4.9e-15.

Regenerate only for a change that is meant to alter results, and say so in its commit:

    .venv/bin/python tests/cli/test_golden.py --write
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import re
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("golden") / "fingerprints.json"
RTOL = 1e-6  # floats on another platform: eight float32 ulps (see above)

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
    # the Geiger-mode receiver: events with crosstalk and afterpulsing, the histogram, the
    # first-photon fit and the pile-up prediction (its own figures and per-point attributes)
    "geiger": [
        "simulate",
        "--set",
        "receiver.kind=gm_apd",
        "--set",
        "pixels=64",
        "--set",
        "pitch_deg=10",
        "--set",
        "gm.crosstalk=0.01",
        "--set",
        "gm.afterpulsing=0.01",
        "--set",
        "gm.pileup_correction=fit",
        "--set",
        "seed=3",
    ],
    # ... by day, without attenuation: background counts, false points and pile-up
    "geiger_day": [
        "simulate",
        "--set",
        "receiver.kind=gm_apd",
        "--set",
        "pixels=48",
        "--set",
        "sun.mode=manual",
        "--set",
        "gm.attenuation_db=20",
        "--set",
        "seed=4",
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


def platform_tag() -> str:
    """What decides the last bits of a run: CPU model and vector extensions, library versions."""
    cpu = ""
    try:
        info = Path("/proc/cpuinfo").read_text()
        model = next((ln for ln in info.splitlines() if ln.startswith("model name")), "")
        flags = next((ln for ln in info.splitlines() if ln.startswith("flags")), "").split()
        cpu = (
            model.partition(":")[2].strip()
            + " "
            + ",".join(sorted(f for f in flags if f.startswith(("avx", "sse4", "fma"))))
        )
    except OSError:
        cpu = platform.processor()
    versions = [f"{d}=={metadata.version(d)}" for d in ("numpy", "scipy", "embreex", "trimesh")]
    return f"{platform.machine()} {cpu} " + " ".join(versions)


def _column_stats(values: np.ndarray) -> list:
    """[n, sum, sum of squares, min, max] of one column (Python ints for integer columns)."""
    v = np.asarray(values)
    if v.size == 0:
        return [0]
    if v.dtype.kind in "biu":
        w = v.astype(np.int64)
        return [int(w.size), int(w.sum()), int((w * w).sum()), int(w.min()), int(w.max())]
    w = v.astype(np.float64).ravel()
    finite = w[np.isfinite(w)]
    n_nan = int(np.isnan(w).sum())
    if finite.size == 0:
        return [int(w.size), n_nan]
    return [
        int(w.size),
        n_nan,
        float(finite.sum()),
        float((finite * finite).sum()),
        float(finite.min()),
        float(finite.max()),
    ]


def _ply(path: Path) -> dict:
    from plyfile import PlyData

    vertex = PlyData.read(str(path))["vertex"].data
    return {
        "sha256": _sha256(path),
        "columns": {name: _column_stats(vertex[name]) for name in vertex.dtype.names},
    }


def _arrays(path: Path) -> dict[str, dict]:
    with np.load(path) as npz:
        return {
            name: {
                "dtype_shape": f"{npz[name].dtype.str} {npz[name].shape}",
                "sha256": hashlib.sha256(np.ascontiguousarray(npz[name]).tobytes()).hexdigest(),
                "stats": _column_stats(npz[name]),
            }
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
            "cloud": _ply(out),
            "waveforms": _arrays(waves),
        }
    out_dir = tmp / "fly"
    assert main([*argv, "--out", str(out_dir)]) == 0
    return {
        "summary": _without_timings(json.loads((out_dir / "flyaround.json").read_text())),
        "frames": {p.name: _ply(p) for p in sorted(out_dir.glob("frame_*.ply"))},
    }


# figures that are differences of ranges (a point's range error, a part's bias): their last bits
# are those of the ranges, not their own, so on another platform they may move by RTOL of the
# range itself (RANGE_SCALE_M: the cases' gates end within it), however small the difference is
RANGE_DIFFERENCES = re.compile(r"range_error|range_bias|bias_m")
RANGE_SCALE_M = 1000.0
COLUMN_SUM = re.compile(r"/columns/[^/]*\[(\d)\]$")


def _abs_tol(path: str, rtol: float) -> float:
    """The absolute tolerance of the float at ``path`` on another platform: none but for figures
    that are differences of ranges, RTOL of the range scale, or for the [n, n_nan, sum, sum of
    squares, min, max] of such a column, what that bound on each point gives its statistic
    (n times it for the sum; the sum of squares is left to RTOL, min and max one point's)."""
    if not RANGE_DIFFERENCES.search(path):
        return 1e-300
    per_point = rtol * RANGE_SCALE_M
    column = COLUMN_SUM.search(path)
    if column and column.group(1) == "2":
        return per_point * _column_n.get(path.rsplit("[", 1)[0], 1)
    return per_point


_column_n: dict[str, int] = {}  # a column's path -> its n, noted as differences() walks it


def differences(got, want, rtol: float, path: str = "") -> list[str]:
    """Where ``got`` departs from ``want``: floats beyond ``rtol`` (exact if 0), anything else
    unequal; SHA-256 figures skipped unless ``rtol`` is 0."""
    if isinstance(want, dict) and isinstance(got, dict):
        found = [f"{path}/{k}: missing" for k in want if k not in got]
        found += [f"{path}/{k}: unexpected" for k in got if k not in want]
        for k in want.keys() & got.keys():
            if k == "sha256" and rtol > 0:
                continue
            found += differences(got[k], want[k], rtol, f"{path}/{k}")
        return found
    if isinstance(want, list) and isinstance(got, list) and len(want) == len(got):
        if "/columns/" in path and want and isinstance(want[0], int):
            _column_n[path] = want[0]
        return [
            d
            for i, (g, w) in enumerate(zip(got, want, strict=True))
            for d in differences(g, w, rtol, f"{path}[{i}]")
        ]
    if isinstance(want, float) and isinstance(got, float) and not isinstance(want, bool):
        if got == want or (
            rtol > 0 and math.isclose(got, want, rel_tol=rtol, abs_tol=_abs_tol(path, rtol))
        ):
            return []
    elif type(got) is type(want) and got == want:
        return []
    return [f"{path}: {got!r} != golden {want!r}"]


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_outputs_match_the_golden_run(case, tmp_path):
    golden = json.loads(GOLDEN.read_text())
    same_platform = golden["platform"] == platform_tag()
    got = fingerprint(case, tmp_path)
    assert differences(got, golden["cases"][case], 0.0 if same_platform else RTOL) == []


def test_a_range_difference_is_compared_at_the_ranges_own_resolution():
    """A range error of a few millimetres moved by a float32 ulp of its 500 m range (3e-5 m) is
    noise on another platform; moved by 5 mm, or its column's sum over 800 points by 1 m, not."""
    want = {"range_bias_m": 0.0021, "columns": {"range_error_m": [800, 0, 0.094, 2.0, -0.1, 0.1]}}
    noise = {
        "range_bias_m": 0.0021 + 3e-5,
        "columns": {"range_error_m": [800, 0, 0.0941, 2.0, -0.1, 0.1]},
    }
    assert differences(noise, want, RTOL) == []
    assert differences(noise, want, 0.0)  # on the golden's own platform every bit counts
    moved = {"range_bias_m": 0.0071, "columns": {"range_error_m": [800, 0, 1.094, 2.0, -0.1, 0.1]}}
    assert len(differences(moved, want, RTOL)) == 2


def test_the_comparison_tells_float32_noise_from_a_real_change():
    want = {"n": 3, "x": [0.1234567891, 2.0], "sha256": "ab"}
    assert (
        differences({"n": 3, "x": [0.1234567891 * (1 + 4e-8), 2.0], "sha256": "cd"}, want, RTOL)
        == []
    )
    assert differences({"n": 3, "x": [0.1234567891 * (1 + 4e-8), 2.0], "sha256": "ab"}, want, 0.0)
    assert differences({"n": 3, "x": [0.1234567891 * (1 + 1e-5), 2.0], "sha256": "ab"}, want, RTOL)
    assert differences({"n": 4, "x": [0.1234567891, 2.0], "sha256": "ab"}, want, RTOL)
    assert differences({"n": 3.0, "x": [0.1234567891, 2.0], "sha256": "ab"}, want, RTOL)


if __name__ == "__main__":
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/cli/test_golden.py --write")
    prints = {}
    for name in sorted(CASES):
        with tempfile.TemporaryDirectory() as d:
            prints[name] = fingerprint(name, Path(d))
    GOLDEN.parent.mkdir(exist_ok=True)
    golden = {"platform": platform_tag(), "cases": prints}
    GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN}")
