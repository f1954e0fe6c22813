"""The receiver interface: a receiver is one module and one registration. A test-only ideal,
noiseless receiver (tests/support/ideal_receiver.py) runs through the pipeline, the CLI summary
and the app's stats with no other edit to simcore or app."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support.ideal_receiver import IDEAL, KIND, THRESHOLD_W

import simcore
from simcore import io, receivers
from simcore.plugins import registry

SMALL = {"pixels": 24, "fidelity.subrays": 1}


@pytest.fixture
def ideal():
    receivers.register(IDEAL)
    yield IDEAL
    receivers.unregister(KIND)


def test_receiver_kind_defaults_to_the_lm_apd_and_refuses_an_unknown_kind():
    assert simcore.Scene().receiver.kind == "lm_apd"
    assert receivers.kinds() == ("lm_apd", "gm_apd")
    row = next(r for r in simcore.key_reference() if r["key"] == "receiver.kind")
    assert row["valid"] == "lm_apd / gm_apd" and row["default"] == "'lm_apd'"
    with pytest.raises(simcore.SceneError, match="receiver.kind = 'ideal' is not valid"):
        simcore.with_overrides(simcore.Scene(), {"receiver.kind": "ideal"})


def test_a_registered_receiver_is_a_valid_kind_and_listed_in_the_key_reference(ideal):
    assert receivers.kinds() == ("lm_apd", "gm_apd", KIND)
    row = next(r for r in simcore.key_reference() if r["key"] == "receiver.kind")
    assert row["valid"] == "lm_apd / gm_apd / ideal"
    scene = simcore.with_overrides(simcore.Scene(), {"receiver.kind": KIND})
    assert scene.to_dict()["receiver"] == {"kind": KIND}
    assert simcore.Scene().to_dict()["receiver"] == {"kind": "lm_apd"}  # every key, default too


def test_the_ideal_receiver_runs_through_the_pipeline(ideal, plate_scene):
    pipe = simcore.Pipeline()
    scene = plate_scene(**SMALL)  # writes the plate's mesh file once
    lm = pipe.run(scene)
    res = pipe.run(simcore.with_overrides(scene, {"receiver.kind": KIND}))
    ran = {s for s in simcore.STAGES if res.timings_s[s] > 0}
    assert ran == {"receiver", "detection", "cloud"}  # the echoes are the LM-APD run's
    assert res.echo is lm.echo
    d = res.detection
    np.testing.assert_array_equal(d.detected, res.receiver.peak_power_w >= THRESHOLD_W)
    assert d.detected.any()
    np.testing.assert_array_equal(d.range_m[d.detected], d.range_true_m[d.detected])
    assert len(res.cloud) == d.detected.sum() and not res.attributes["is_outlier"].any()
    np.testing.assert_array_equal(res.attributes["snr"], res.receiver.snr[d.detected])
    assert np.all(res.receiver.snr[d.detected] >= 1.0)
    w = res.waveform(*[int(v) for v in divmod(int(res.echo.pixel[d.detected][0]), 24)])
    assert w.detected and w.range_m == w.range_true_m and w.threshold_w == THRESHOLD_W
    with pytest.raises(ValueError):  # its arrays are read-only, like every stage output
        d.range_m[0] = 1.0


def test_the_ideal_receiver_runs_through_the_cli_summary(ideal, plate_scene, tmp_path):
    from simcore.cli import main

    scene_file = tmp_path / "plate.toml"
    scene_file.write_text(simcore.dump_scene(plate_scene(**SMALL)))
    out, summary = tmp_path / "cloud.ply", tmp_path / "summary.json"
    argv = ["simulate", str(scene_file), "--set", f"receiver.kind={KIND}"]
    assert main([*argv, "--out", str(out), "--summary", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["scene"]["receiver"] == {"kind": KIND}
    assert s["n_outliers"] == 0 and s["n_false_expected"] == 0.0
    assert s["n_points"] == s["n_target_points"] > 0 and s["range_sigma_m_median"] == 0.0
    assert s["p_detect_mean"] == pytest.approx(s["n_points"] / s["n_lit_pixels"])
    assert len(io.read_cloud(out)) == s["n_points"]


def test_the_ideal_receiver_runs_through_the_app_stats(ideal, plate_scene):
    from app.engine import Engine, Request

    scene = plate_scene(**SMALL, **{"receiver.kind": KIND})
    frame = Engine(scene).compute(Request(scene))
    stats = {row["label"]: row["value"] for row in frame.stats}
    snr = frame.result.receiver.snr
    assert stats["Outliers (false alarms)"] == "0"
    assert stats["Median SNR"] == f"{np.median(snr):.3g}"
    assert stats["Median range σ"] == "0 cm"
    assert sum(frame.snr_histogram["data"][0]["y"]) == len(snr)
    assert frame.waveforms["data"]  # the default pixel's echo is drawn


@pytest.mark.parametrize("kind", receivers.BUILT_IN)
def test_a_built_in_receiver_gives_what_its_declaration_says(kind, plate_scene):
    """The declaration is no wish list: its summary figures are in the summary (and the
    receiver gives no other), its point attributes are the cloud's extra columns, its stats
    rows format from a real summary, and its controls set keys of its sections within range."""
    declared = receivers.get(kind)
    scene = plate_scene(**SMALL, **{"receiver.kind": kind})
    result = simcore.Pipeline().run(scene)
    summary = result.summary(quality=False)
    figures = {f.name for f in declared.summary_figures}
    given = set(result.detection.summary_figures) - {"warnings"}
    assert given <= figures and figures <= set(summary), (given, figures)
    attributes = {a.name for a in declared.point_attributes}
    assert set(result.detection.point_attributes) == attributes
    assert attributes <= set(result.attributes)
    noise = result.receiver.noise_figures  # (the app's stats add them to the summary)
    fields = {"scene": summary["scene"], "noise": noise, "summary": summary}
    assert declared.description.format(**fields)
    for row in declared.stats_rows:
        assert row.text.format(**fields)
    for control in declared.controls:
        section, name = control.key.split(".", 1)
        default = getattr(getattr(scene, section), name) / control.scale
        assert control.lo <= default <= control.hi, control.name
        simcore.with_overrides(scene, {control.key: control.hi * control.scale})  # valid


def test_the_design_studies_total_energy_counts_a_frames_pulses():
    from simcore.design.study import cost_figure

    gm = simcore.with_overrides(simcore.Scene(), {"receiver.kind": "gm_apd", "gm.pulses": 37})
    assert cost_figure("laser.pulse_energy_total_j", gm) == 37 * gm.laser.pulse_energy_j
    lm = simcore.Scene()
    assert cost_figure("laser.pulse_energy_total_j", lm) == lm.laser.pulse_energy_j


def test_an_installed_receiver_that_does_not_load_is_left_out_with_a_warning(monkeypatch):
    monkeypatch.setattr(registry, "_installed", {"broken": "no_such_package.nowhere:RECEIVER"})
    monkeypatch.setattr(registry, "_broken", {})
    monkeypatch.setattr(registry, "_known", {})
    with pytest.warns(UserWarning, match="installed receiver 'broken'.*does not load"):
        assert [r.kind for r in receivers.receivers()] == ["lm_apd", "gm_apd"]
    assert receivers.kinds() == ("lm_apd", "gm_apd")
    assert simcore.with_overrides(simcore.Scene(), {"gm.pulses": 7}).gm.pulses == 7
    with pytest.raises(ModuleNotFoundError):  # named, it says why
        receivers.get("broken")
