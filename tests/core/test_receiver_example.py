"""The example receiver of docs/receivers.md, an ideal photon counter written outside the
simulator (docs/examples/ideal_counter/), plugs in with no edit anywhere else: by
``simcore.receivers.register`` in a program, and as an installed package by its entry point (its
pyproject's, written here as the installed distribution's metadata). It runs through the key
reference, the scene, ``lmapd simulate`` and the app's logic (its controls, the scene they set,
its stats rows and the engine's frame)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import simcore
from simcore import io, receivers

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "ideal_counter"
SMALL = {"pixels": 24, "fidelity.subrays": 1}


def _example():
    spec = importlib.util.spec_from_file_location("ideal_counter", EXAMPLE / "ideal_counter.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclass's annotations are resolved there)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def counter():
    example = _example()
    receivers.register(example.RECEIVER)
    yield example.RECEIVER
    receivers.unregister("ideal_counter")


def test_registered_it_is_a_kind_with_its_section_in_the_key_reference(counter):
    assert receivers.kinds()[-1] == "ideal_counter"
    rows = {r["key"]: r for r in simcore.key_reference()}
    assert rows["counter.qe"]["valid"] == "(0, 1] 1" and rows["counter.threshold_pe"]["unit"] == "1"
    assert "ideal_counter" in rows["receiver.kind"]["valid"]
    scene = simcore.with_overrides(simcore.Scene(), {"receiver.kind": "ideal_counter"})
    assert scene.counter.qe == 0.5 and simcore.Scene().counter.threshold_pe == 1.0
    with pytest.raises(simcore.SceneError, match="counter.qe = 2.0 is out of range"):
        simcore.with_overrides(scene, {"counter.qe": 2.0})
    # its section is dumped and read back like any other
    changed = simcore.with_overrides(scene, {"counter.qe": 0.25})
    assert simcore.scene.scene_from_dict(tomllib.loads(simcore.dump_scene(changed))) == changed


def test_unregistered_it_is_no_kind_and_its_section_no_section(counter):
    receivers.unregister("ideal_counter")
    with pytest.raises(simcore.SceneError, match="receiver.kind = 'ideal_counter' is not valid"):
        simcore.with_overrides(simcore.Scene(), {"receiver.kind": "ideal_counter"})
    with pytest.raises(simcore.SceneError, match="unknown scene key 'counter.qe'"):
        simcore.with_overrides(simcore.Scene(), {"counter.qe": 0.3})
    receivers.register(counter)  # (the fixture unregisters it)


def test_it_runs_through_lmapd_simulate(counter, plate_scene, tmp_path):
    from simcore.cli import main

    scene_file = tmp_path / "plate.toml"
    scene_file.write_text(simcore.dump_scene(plate_scene(**SMALL)))
    out, summary = tmp_path / "cloud.ply", tmp_path / "summary.json"
    argv = ["simulate", str(scene_file), "--set", "receiver.kind=ideal_counter"]
    argv += ["--set", "counter.qe=0.3", "--out", str(out), "--summary", str(summary)]
    assert main(argv) == 0
    s = json.loads(summary.read_text())
    assert s["receiver_kind"] == "ideal_counter" and s["scene"]["counter"]["qe"] == 0.3
    assert s["n_points"] == s["n_target_points"] > 0 and s["n_outliers"] == 0
    assert s["counter.signal_pe_median"] > 1.0  # its own figure
    cloud = io.read_cloud(out)
    assert len(cloud) == s["n_points"] and np.all(cloud.attributes["photoelectrons"] > 0)


def test_its_controls_scene_and_stats_in_the_app(counter, plate_scene):
    from app.engine import Engine, Request
    from app.logic.scene_map import scene_from_controls
    from app.state import SPECS, Controls, sanitize_controls, state_keys

    assert SPECS["counter_qe"].label == "Counter QE" and "counter_threshold_pe" in state_keys()
    controls, messages = sanitize_controls(
        {"receiver_kind": "ideal_counter", "counter_qe": 0.7, "counter_threshold_pe": 500},
        Controls(),
    )
    assert controls.counter_qe == 0.7 and controls.counter_threshold_pe == 100.0
    assert messages == ["Count threshold 500 is outside 1 to 100 pe; set to 100 pe"]
    scene = scene_from_controls(plate_scene(**SMALL), controls)
    assert scene.receiver.kind == "ideal_counter" and scene.counter.qe == 0.7
    frame = Engine(scene).compute(Request(scene))
    stats = {row["label"]: row["value"] for row in frame.stats}
    assert stats["Receiver"] == "ideal photon counter, QE 0.7"
    pe = frame.result.receiver.snr**2
    assert stats["Echo photoelectrons / pulse"] == f"{np.median(pe):.3g}"
    assert stats["Median count SNR √S"] == f"{np.median(frame.result.receiver.snr):.3g}"
    assert not frame.snr_histogram["layout"].get("shapes")  # no TNR line on its count SNR axis
    assert frame.waveforms["data"]  # the default pixel's echo, on the waveform chart


def test_installed_its_entry_point_makes_it_a_kind_of_the_lmapd_command(tmp_path):
    """The example's pyproject declares the entry point; an installed distribution's metadata
    (written here) makes ``lmapd`` find it in a fresh process, with no register() call."""
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())
    points = project["project"]["entry-points"]["lmapd_sim.receivers"]
    dist = tmp_path / "site" / "lmapd_ideal_counter-0.1.0.dist-info"
    dist.mkdir(parents=True)
    dist.joinpath("METADATA").write_text(
        "Metadata-Version: 2.1\nName: lmapd-ideal-counter\nVersion: 0.1.0\n"
    )
    lines = "".join(f"{name} = {value}\n" for name, value in points.items())
    dist.joinpath("entry_points.txt").write_text(f"[lmapd_sim.receivers]\n{lines}")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "site"), str(EXAMPLE)])}
    lmapd = [sys.executable, "-m", "simcore.cli"]
    keys = subprocess.run([*lmapd, "keys"], env=env, capture_output=True, text=True, check=True)
    assert "counter.threshold_pe" in keys.stdout and "ideal_counter" in keys.stdout
    summary = tmp_path / "summary.json"
    argv = ["simulate", "--set", "receiver.kind=ideal_counter", "--set", "pixels=16"]
    argv += ["--set", "fidelity.subrays=1", "--summary", str(summary)]
    argv += ["--out", str(tmp_path / "cloud.ply")]
    done = subprocess.run([*lmapd, *argv], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads(summary.read_text())["receiver_kind"] == "ideal_counter"


def test_the_app_started_with_it_shows_its_button_and_sliders_and_runs_it(counter):
    from support.app_helpers import change, small_app, stat

    with small_app(pixels=24) as app:
        page = app.ui.html
        assert "receiver-counter" in page and "Ideal counter" in page  # its button
        assert "slider-counter_qe" in page and "slider-counter_threshold_pe" in page
        assert "info-counter_threshold_pe" in page and "the only chance is" in page  # glossary
        change(app, receiver_kind="ideal_counter", counter_qe=0.4)
        scene = app.logic.last_frame.result.scene
        assert scene.receiver.kind == "ideal_counter" and scene.counter.qe == 0.4
        assert stat(app, "Receiver") == "ideal photon counter, QE 0.4"
        assert "counter.qe=0.4" in app.state.share_query
