"""Every combination of the page's controls answers: a frame over the server's budget is refused
before its costly stages run, with a message naming the page's controls, and the controls go
back to the values of the frame shown; the avalanche estimate that decides it follows the real
runs; random combinations leave no traceback in the log."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.app_helpers import change, small_app

import simcore
from app.engine import MAX_FRAME_RECORD_BYTES
from app.state import PRESET_CHOICES, SPECS, SUN_MODES
from simcore import receivers
from simcore.receivers.gm_apd import frame as gm_frame
from simcore.receivers.gm_apd.limits import BYTES_PER_EVENT


@pytest.fixture(scope="module")
def app():
    with small_app(pixels=48) as lmapd:
        yield lmapd


def test_a_frame_over_the_budget_is_refused_and_the_sliders_return(app, caplog):
    change(app, receiver_kind="gm_apd", gm_dark_count_rate_hz=1e4, gm_pulses=100)
    assert app.state.error_message == ""
    shown = app.logic.last_frame
    with caplog.at_level(logging.INFO):
        change(app, gm_dark_count_rate_hz=1e8, gm_pulses=1000)
    message = app.state.error_message
    assert message.startswith("Refused: this frame would record about")
    # the figure refused and the limit are written alike: two digits, in full
    figures = re.search(r"about ([\d,.]+) .* at most ([\d,.]+) per frame", message)
    assert figures is not None, message
    assert all(re.fullmatch(r"\d{1,3}(,\d{3})*", f) for f in figures.groups()), figures.groups()
    assert "Pulses per frame" in message and "Dark count rate" in message
    assert "timing." not in message and "gm." not in message
    assert "back to the values of the frame shown" in message
    # the sliders hold the values of the frame shown, which is still the same scene
    assert app.state.gm_pulses == 100 and app.state.gm_dark_count_rate_hz == 1e4
    assert app.logic.last_frame.result.scene == shown.result.scene
    assert not [r for r in caplog.records if r.exc_info]  # a refusal is no fault
    # the refused scene's receiver never ran
    refused = simcore.with_overrides(
        shown.result.scene, {"gm.dark_count_rate_hz": 1e8, "gm.pulses": 1000}
    )
    assert app.logic.engine.pipeline.cached("receiver", refused) is None


@pytest.mark.parametrize(
    "overrides",
    [
        {},  # photon-starved (50 dB)
        {"gm.attenuation_db": 0.0},  # piled up: one avalanche per pulse
        {"gm.dark_count_rate_hz": 1e8},  # dark counts fill the gate
        {"gm.dead_time_s": 1e-9, "gm.attenuation_db": 10.0, "gm.pulses": 5},  # many per echo
        {"sun.mode": "manual", "receive.filter_width_m": 1e-7, "gm.attenuation_db": 20.0},
    ],
)
def test_the_avalanche_estimate_follows_the_real_runs(overrides):
    scene = simcore.with_overrides(
        simcore.load_scene(),
        {"pixels": 48, "fidelity.subrays": 1, "receiver.kind": "gm_apd", **overrides},
    )
    pipeline = simcore.Pipeline()
    with np.errstate(all="ignore"):
        result = pipeline.run(scene)
    recorded = len(result.receiver.events)
    echo, background = pipeline.cached("echo", scene), pipeline.cached("background", scene)
    estimate = gm_frame.frame_avalanches(scene, echo, background)
    assert estimate == pytest.approx(recorded, rel=0.2)
    worst, bound = gm_frame.frame_load(scene, echo, background)
    assert bound >= 0.95 * recorded  # the core's bound is one


# the page's controls: every slider over its whole range (pixels kept small), every choice
CONTROL_VALUES = {
    key: (
        st.integers(int(spec.lo), int(spec.hi))
        if spec.integer
        else st.floats(spec.lo, spec.hi, allow_nan=False)
    )
    for key, spec in SPECS.items()
    if key not in ("pixels", "seed")
} | {
    "pixels": st.sampled_from([16, 32, 48]),
    "seed": st.integers(0, 3),
    "receiver_kind": st.sampled_from(receivers.kinds()),
    "sun_mode": st.sampled_from(SUN_MODES),
    "preset": st.sampled_from([p for p in PRESET_CHOICES if p != "custom"]),
}


@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(values=st.fixed_dictionaries({}, optional=CONTROL_VALUES))
def test_any_combination_of_the_controls_answers_without_a_traceback(app, caplog, values):
    caplog.clear()
    with caplog.at_level(logging.INFO):
        change(app, **values)
    faults = [r for r in caplog.records if r.exc_info or r.levelno >= logging.ERROR]
    assert not faults, faults[0].getMessage()
    message = app.state.error_message
    assert not message.startswith("Simulation failed ("), message  # only users' messages
    if message:
        assert message.startswith(("Refused:", "Simulation failed:")), message
    frame = app.logic.last_frame
    if frame is not None and frame.result.scene.receiver.kind == "gm_apd":
        assert len(frame.result.receiver.events) < 1.2 * MAX_FRAME_RECORD_BYTES / BYTES_PER_EVENT


def test_a_frame_no_longer_wanted_stops_while_its_avalanches_are_drawn():
    """The runner's should_stop reaches into the Geiger-mode event simulation (between its
    chunks), not only between stages: a frame abandoned for a newer one ends there."""
    scene = simcore.with_overrides(
        simcore.load_scene(), {"pixels": 48, "fidelity.subrays": 1, "receiver.kind": "gm_apd"}
    )
    pipeline = simcore.Pipeline()
    calls = []

    def should_stop() -> bool:  # asked before each of the 6 stages up to the receiver, then in it
        calls.append(1)
        return len(calls) > 6

    with pytest.raises(simcore.Cancelled, match="while drawing the avalanches"):
        pipeline.run(scene, should_stop=should_stop)
    assert pipeline.cached("echo", scene) is not None
    assert pipeline.cached("receiver", scene) is None
