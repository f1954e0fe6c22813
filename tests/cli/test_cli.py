"""The `lmapd simulate` contract of DESIGN.md section 3, and its errors."""

import json

import numpy as np
import pytest

from simcore import cli
from simcore.io import read_ply

SUMMARY_KEYS = {
    "n_pixels",
    "n_hit_pixels",
    "n_points",
    "n_outliers",
    "n_dropped",
    "snr_median",
    "range_sigma_m_median",
    "timings_s",
    "scene",
}


def test_simulate_writes_the_cloud_the_summary_and_the_waveforms(tmp_path, capsys):
    out, summary, waves = tmp_path / "c.ply", tmp_path / "s.json", tmp_path / "w.npz"
    argv = [
        "simulate",
        "--set",
        "pixels=64",
        "--set",
        "pitch_deg=15",
        "--set",
        "seed=3",
        "--out",
        str(out),
        "--summary",
        str(summary),
        "--waveforms",
        str(waves),
    ]
    assert cli.main(argv) == 0
    assert "points" in capsys.readouterr().out
    s = json.loads(summary.read_text())
    assert SUMMARY_KEYS <= set(s)
    assert s["scene"]["pose"]["pitch_deg"] == 15.0 and s["scene"]["seed"] == 3
    assert set(s["timings_s"]) == {
        "target",
        "rays",
        "hits",
        "echo",
        "background",
        "receiver",
        "detection",
        "cloud",
        "quality",  # the imaging-quality figures' stage: the summary asks for it
    }
    cloud = read_ply(out)
    assert len(cloud) == s["n_points"]
    assert set(cloud.attributes) == {
        "row",
        "col",
        "range_m",
        "intensity_w",
        "snr",
        "material_id",
        "facet_id",
        "is_outlier",
        "part_id",  # the ground truth
        "true_range_m",
        "range_error_m",
        "incidence_deg",
        "outlier",
    }
    assert int(cloud.attributes["is_outlier"].sum()) == s["n_outliers"]
    cube = np.load(waves)
    assert cube["filtered_w"].shape[0] == s["n_lit_pixels"]
    assert np.all(np.isfinite(cube["filtered_w"]))


def test_the_ply_round_trips_exactly(tmp_path):
    import simcore

    res = simcore.simulate(pixels=32)
    from simcore.io import write_ply

    write_ply(tmp_path / "a.ply", res.cloud)
    back = read_ply(tmp_path / "a.ply")
    assert np.array_equal(back.points, res.points)
    for name, values in res.attributes.items():  # NaN where a false alarm has no truth
        assert np.array_equal(back.attributes[name], values, equal_nan=values.dtype.kind == "f")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--set", "pixels=5000"], "detector.pixels = 5000 is out of range"),
        (["--set", "bogus=1"], "unknown scene key 'bogus'"),
        (["--set", "target.mesh=/nonexistent/x.obj"], "file not found: /nonexistent/x.obj"),
        (
            ["--set", "detector.gain_from=bias", "--set", "detector.bias_voltage_v=450"],
            "must be below",
        ),
        (["missing_scene.toml"], "scene file not found"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, extra, message):
    out = tmp_path / "c.ply"
    assert cli.main(["simulate", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_broken_mesh_file_is_named(tmp_path, capsys):
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv nan 1 0\nv 0 1 0\nf 1 2 3\n")
    assert (
        cli.main(["simulate", "--set", f"target.mesh={bad}", "--out", str(tmp_path / "c.ply")]) == 2
    )
    assert "broken.obj" in capsys.readouterr().err
    assert not (tmp_path / "c.ply").exists()


def test_an_unsupported_output_format_is_refused_before_any_work(tmp_path, capsys):
    assert cli.main(["simulate", "--out", str(tmp_path / "c.xyz")]) == 2
    assert "unsupported format" in capsys.readouterr().err


def test_keys_lists_every_key(capsys):
    assert cli.main(["keys", "--markdown"]) == 0
    out = capsys.readouterr().out
    assert "`laser.pulse_energy_j` | J |" in out and "`detector.pixels` | px |" in out


def test_an_internal_error_is_one_line_unless_debugging(monkeypatch, tmp_path, capsys):
    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr("simcore.pipeline.Pipeline.run", broken)
    assert cli.main(["simulate", "--set", "pixels=8", "--out", str(tmp_path / "c.ply")]) == 1
    err = capsys.readouterr().err
    assert "internal error: RuntimeError: boom" in err and "Traceback" not in err
    monkeypatch.setenv("LMAPD_DEBUG", "1")
    with pytest.raises(RuntimeError, match="boom"):
        cli.main(["simulate", "--set", "pixels=8", "--out", str(tmp_path / "c.ply")])


def test_the_constants_the_help_shows_without_loading_the_library_are_the_librarys():
    from simcore import flyaround, orbit, sweep
    from simcore.cli import flyaround as fly_cli
    from simcore.cli import sweep as sweep_cli

    assert fly_cli.DEFAULT_INTERVAL_S == flyaround.DEFAULT_INTERVAL_S
    assert fly_cli.PAPER_PERIOD_S == orbit.PAPER_PERIOD_S
    assert sweep_cli.CLOUD_FORMATS == sweep.spec.CLOUD_FORMATS


def test_compare_runs_both_receivers_and_writes_its_table_and_figure(tmp_path):
    import json

    from simcore.cli import main

    assert main(["compare", "--quick", "--set", "pixels=16", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert {r["receiver"] for r in rows} == {"lm_apd", "gm_apd"} and len(rows) == 20
    # both receivers' false points on one basis: the cloud's, observed and expected per frame
    assert all(r["n_false_points_expected"] >= 0 and r["n_outliers"] >= 0 for r in rows)
    assert (tmp_path / "compare.png").stat().st_size > 10_000
    assert main(["compare", "--p-detect", "1.5", "--out", str(tmp_path)]) == 2
