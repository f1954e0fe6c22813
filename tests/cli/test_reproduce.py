"""`lmapd reproduce`: the quick run end to end, its report, the conventions table and determinism.

The quick run (64 x 64 pixels, a few hundred Monte Carlo trials) is made twice with the same seed:
once through the command-line entry point, once through the Python function.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

import simcore
from simcore.cli import CliError
from simcore.cli.reproduce import add_parser, run_cli
from simcore.cli.reproduce.report import ITEMS, REPORT_NAME, run_reproduction
from simcore.receivers.lm_apd import apd as receiver

pytestmark = pytest.mark.slow  # two quick runs, ~8 s each

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SEED = 3
DOC = Path(__file__).resolve().parents[2] / "docs" / "reproduction.md"
ITEM_KEYS = {
    "brdf": {"angle_deg", "brdf_per_sr", "parameters"},
    "detection": {"p_detect", "false_alarms", "gate_m", "paper_df_hz", "sigma_n_a"},
    "waveforms": {"pixels", "summary"},
    "attitude": {"pitch", "azimuth"},
    "resolution": {"point_counts", "fov_rule"},
    "flyaround": {"records", "frames", "distance_stats_m", "paper_period_s", "two_body_period_s"},
    "conventions": {"rows", "columns"},
    "daylight": {"rows", "columns"},
}
COMMON_KEYS = {"item", "paper_figure", "figures", "scenes"}
TABLE1 = {"ideal_diffuse", "ideal_specular", "solar_panel", "coating_1", "coating_2"}


def _parse(argv):
    parser = argparse.ArgumentParser(prog="lmapd")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(argv)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two quick runs with the same seed: (folder, report) through the CLI, then the function."""
    first = tmp_path_factory.mktemp("repro_cli") / "out"
    args = _parse(["reproduce", "--out", str(first), "--quick", "--seed", str(SEED)])
    assert args.func is run_cli
    assert run_cli(args) == 0
    report = json.loads((first / REPORT_NAME).read_text(encoding="utf-8"))
    second = tmp_path_factory.mktemp("repro_fn")
    again = run_reproduction(second, quick=True, seed=SEED, progress=False)
    return (first, report), (second, json.loads(json.dumps(again)))


@pytest.fixture(scope="module")
def report(runs):
    return runs[0][1]


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_every_figure_is_written_as_a_real_png(runs):
    folder, report = runs[0]
    names = report["figures"]
    assert len(names) == len(set(names)) == 10
    for name in names:
        width, height = _png_size(folder / name)
        assert width >= 600 and height >= 300, name
    on_disk = {p.name for p in folder.glob("*.png")}
    assert on_disk == set(names)


def test_the_report_holds_all_eight_items_with_their_numbers(report):
    assert list(report["items"]) == list(ITEMS)
    for number, name in enumerate(ITEMS, start=1):
        item = report["items"][name]
        assert item["item"] == number
        missing = (COMMON_KEYS | ITEM_KEYS[name]) - set(item)
        assert not missing, f"item {name} lacks {missing}"
        for scene in item["scenes"].values():
            assert scene["seed"] == SEED
    assert report["seed"] == SEED and report["quick"] is True
    assert report["simulator"]["version"] == simcore.__version__
    commit = report["simulator"]["git_commit"]
    assert commit is None or re.fullmatch(r"[0-9a-f]{40}", commit)


def test_each_item_carries_what_its_figure_shows(report):
    items = report["items"]
    assert TABLE1 <= set(items["brdf"]["brdf_per_sr"])
    det = items["detection"]
    assert det["gate_m"] == 1000.0 and det["paper_df_hz"] == 12e6
    n_snr, n_tnr = len(det["p_detect"]["snr"]), len(det["p_detect"]["tnr_mc"])
    assert np.shape(det["p_detect"]["montecarlo"]) == (n_snr, n_tnr)
    assert len(det["false_alarms"]["montecarlo_count"]) == len(det["false_alarms"]["tnr_mc"])
    pixels = items["waveforms"]["pixels"]
    assert pixels["double_peak"]["n_peaks"] >= 2
    assert pixels["dish"]["n_peaks"] == 1 and pixels["dish"]["parts"] == ["cover"]
    counts = items["resolution"]["point_counts"]
    assert {(r["distance_m"], r["pixels"]) for r in counts} == {
        (d, p) for d in (500.0, 1000.0) for p in (32, 64, 128, 256)
    }
    frames = items["flyaround"]["frames"]
    assert [f["t_s"] for f in frames] == [3000.0, 4200.0, 5400.0]
    assert all(150.0 < f["distance_m"] < 250.0 for f in frames)  # Table 3: ~200 m, not 500 m


def test_the_conventions_table_has_one_row_per_paper_form_with_finite_numbers(report):
    conv = report["items"]["conventions"]
    forms = [row["form"] for row in conv["rows"]]
    assert forms == ["ours", *simcore.PAPER_FORMS, "paper (all)"]
    for row in conv["rows"]:
        for column in conv["columns"]:
            assert math.isfinite(row[column]), (row["form"], column)


def test_eq30_4pi_lowers_the_snr_as_shot_and_thermal_noise_predict(report):
    """Eq. 30 as printed divides every weight by 4 pi and drops cos(theta): the peak current of
    each pixel becomes i / (4 pi cos theta) >= i / (4 pi), so the median current falls to
    1/(4 pi) of ours (a bit more where the median pixel is not at normal incidence), and the
    median SNR follows Eqs. 10-18 at that current: between the thermal-limited ratio 1/(4 pi)
    and the shot-limited 1/sqrt(4 pi)."""
    rows = {row["form"]: row for row in report["items"]["conventions"]["rows"]}
    ours, paper = rows["ours"], rows["eq30_4pi"]
    scene = simcore.load_scene("paper")
    rx = receiver.receiver_model(scene.detector, scene.amplifiers, scene.laser.wavelength_m)
    four_pi = 4.0 * np.pi
    i_ours = ours["peak_current_median_a"]
    assert rx.snr(i_ours) == pytest.approx(ours["snr_median"], rel=1e-3)
    current_ratio = paper["peak_current_median_a"] / i_ours
    assert 1.0 / four_pi * (1 - 1e-3) <= current_ratio <= 1.25 / four_pi
    expected = float(rx.snr(i_ours / four_pi))
    assert expected * (1 - 1e-3) <= paper["snr_median"] <= float(rx.snr(1.25 * i_ours / four_pi))
    snr_ratio = paper["snr_median"] / ours["snr_median"]
    assert 1.0 / four_pi < snr_ratio < 1.0 / np.sqrt(four_pi)


def test_eq29_one_way_delays_halve_the_relief(report):
    """One-way delays of the relief along the boresight map a depth z to z / 2."""
    rows = {row["form"]: row for row in report["items"]["conventions"]["rows"]}
    ratio = rows["eq29_one_way"]["depth_extent_m"] / rows["ours"]["depth_extent_m"]
    assert ratio == pytest.approx(0.5, abs=0.05)


def _without_timings(report: dict) -> dict:
    return {k: v for k, v in report.items() if k != "timings_s"}


def test_the_same_seed_gives_identical_numbers(runs):
    (_, first), (_, second) = runs
    assert _without_timings(first) == _without_timings(second)


def test_bad_arguments_are_user_errors(tmp_path):
    file = tmp_path / "a_file"
    file.write_text("x", encoding="utf-8")
    with pytest.raises(CliError, match="not a folder"):
        run_cli(_parse(["reproduce", "--out", str(file), "--quick"]))
    with pytest.raises(CliError, match="--seed"):
        run_cli(_parse(["reproduce", "--out", str(tmp_path / "new"), "--seed", "-1"]))
    assert not (tmp_path / "new").exists()


def test_the_doc_shows_every_figure_of_the_run(report):
    """docs/reproduction.md shows each figure the run writes, from docs/img/repro/."""
    text = DOC.read_text(encoding="utf-8")
    shown = set(re.findall(r"\]\(img/repro/([\w.-]+\.png)\)", text))
    assert shown == set(report["figures"])
    for name in shown:
        _png_size(DOC.parent / "img" / "repro" / name)
    assert "lmapd reproduce --out" in text
    assert "NASA" in text


def test_the_daylight_item_adds_background_by_day_and_a_wider_filter_more(report):
    rows = {r["case"]: r for r in report["items"]["daylight"]["rows"]}
    assert rows["night"]["background_power_w_median"] == 0
    assert 0 < rows["day, 1 nm filter"]["background_power_w_median"]
    ratio = (
        rows["day, 10 nm filter"]["background_power_w_median"]
        / rows["day, 1 nm filter"]["background_power_w_median"]
    )
    assert 5 < ratio < 15  # ten times the band, the solar spectrum nearly flat over it
    assert abs(rows["day, 1 nm filter"]["sun_angle_deg"] - 30.0) < 1.0
