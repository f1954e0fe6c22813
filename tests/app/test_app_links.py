"""Shareable scenes (app.logic.links): a link carries every setting in the names of
``lmapd simulate --set`` and restores the same frame; a tampered link falls back to defaults with
a message, never an error."""

from __future__ import annotations

import dataclasses
import urllib.parse

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.app_helpers import settle

import simcore
from app.engine import Engine
from app.logic.links import MAX_LINK_SETTINGS, controls_from_link, link_query, link_settings
from app.logic.scene_map import resolved_materials, scene_from_controls
from app.main import LmapdApp
from app.state import Controls, controls_from_scene

SMALL = {"pixels": 48, "fidelity.subrays": 1}


@pytest.fixture(scope="module")
def model():
    return simcore.load_target(simcore.load_scene().target)


@pytest.fixture(scope="module")
def initial(model) -> Controls:
    scene = simcore.load_scene()
    return controls_from_scene(scene, resolved_materials(model, scene))[0]


def new_app(model) -> LmapdApp:
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    app = LmapdApp(scene, engine=Engine(scene, model=model), flow_control=False, debounce_s=0.0)
    app.state.ready()
    settle(app)
    return app


def test_a_link_uses_the_command_lines_names_in_si_units(initial):
    controls = dataclasses.replace(initial, pitch_deg=30.0, pulse_energy_mj=2.5, tnr=4.1)
    query = dict(urllib.parse.parse_qsl(link_query(controls, initial)))
    assert query["pitch_deg"] == "30" and query["tnr"] == "4.1"
    assert query["pulse_energy_j"] == "0.0025"  # joules, as --set takes them
    # only what differs from the initial controls
    assert set(query) == {"pitch_deg", "pulse_energy_j", "tnr"}
    assert link_query(initial, initial) == ""


def test_a_link_is_short_and_its_values_carry_no_float_noise(initial):
    controls = initial.replace(receiver_kind="gm_apd", gm_dead_time_ns=1001.0, distance_m=730.0)
    query = link_query(controls, initial)
    assert query == "distance_m=730&gm.dead_time_s=1.001e-06&receiver.kind=gm_apd"
    back, messages = controls_from_link(dict(urllib.parse.parse_qsl(query)), initial)
    assert messages == [] and back == controls


def test_a_link_restores_the_same_scene_and_the_same_points(model):
    teacher = new_app(model)
    part = teacher.engine.model.part_names[0]
    with teacher.state:
        teacher.state.update(
            {
                "pitch_deg": 23.0,
                "azimuth_deg": -41.0,
                "distance_m": 730.0,
                "pulse_energy_mj": 0.07,
                "tnr": 4.3,
                "seed": 99,
                "materials": {**teacher.state.materials, part: "lambertian"},
            }
        )
    settle(teacher)
    query = teacher.state.share_query
    assert f"target.materials.{urllib.parse.quote(part)}=lambertian" in query
    student = new_app(model)
    student.logic.open_link(dict(urllib.parse.parse_qsl(query)))
    settle(student)
    assert student.state.input_message == ""
    a, b = teacher.logic.last_frame.result, student.logic.last_frame.result
    assert a.scene == b.scene
    assert len(a.cloud) > 100 and np.array_equal(a.cloud.points, b.cloud.points)
    teacher.logic.runner.close()
    student.logic.runner.close()


@pytest.mark.parametrize(
    ("key", "lo", "hi", "si"),
    [
        ("pulse_energy_mj", 0.01, 50.0, "laser.pulse_energy_j"),
        ("filter_width_nm", 0.1, 100.0, "receive.filter_width_m"),
        ("gm_dead_time_ns", 1.0, 1e5, "gm.dead_time_s"),
    ],
)
def test_every_slider_value_gives_the_same_scene_after_the_round_trip(initial, key, lo, hi, si):
    base = simcore.load_scene()
    rng = np.random.default_rng(3)
    for value in (float(f"{v:.3g}") for v in 10 ** rng.uniform(np.log10(lo), np.log10(hi), 2000)):
        controls = initial.replace(**{key: value})
        back, messages = controls_from_link(link_settings(controls, initial), initial)
        section, name = si.split(".")
        want = getattr(getattr(scene_from_controls(base, controls), section), name)
        got = getattr(getattr(scene_from_controls(base, back), section), name)
        assert messages == [] and got == want


@pytest.mark.parametrize(
    ("settings", "message", "field", "value"),
    [
        ({"pitch_deg": "abc"}, "Pitch: 'abc' is not a number; kept 0 deg", "pitch_deg", 0.0),
        ({"distance_m": "1e9"}, "Distance 1e+09 is outside 20 to 5000 m", "distance_m", 5000.0),
        ({"tnr": "nan"}, "TNR: not a number; kept 5", "tnr", 5.0),
        ({"preset": "turbo"}, "Fidelity preset: 'turbo' is not one of", "preset", "interactive"),
        ({"rm -rf": "1"}, "Link: unknown setting 'rm -rf'; ignored", "pixels", 256),
        ({"target.materials.nope": "lambertian"}, "the target has no part 'nope'", "tnr", 5.0),
    ],
)
def test_a_tampered_setting_falls_back_with_a_message_naming_it(
    initial, settings, message, field, value
):
    controls, messages = controls_from_link(settings, initial)
    assert any(message in m for m in messages), messages
    assert getattr(controls, field) == value


def test_a_link_with_too_many_settings_or_no_mapping_is_ignored_whole(initial):
    many = {f"k{i}": "1" for i in range(MAX_LINK_SETTINGS + 1)}
    assert controls_from_link(many, initial) == (
        initial,
        [f"Link: {len(many)} settings is too many; ignored"],
    )
    assert controls_from_link(["pitch_deg", 3], initial)[0] == initial


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    st.dictionaries(
        st.one_of(
            st.sampled_from(
                ["pitch_deg", "pixels", "pulse_energy_j", "preset", "fidelity.subrays", "seed"]
            ),
            st.text(max_size=30),
        ),
        st.one_of(st.text(max_size=60), st.integers(), st.floats(), st.none(), st.booleans()),
        max_size=12,
    )
)
def test_any_query_gives_valid_controls_and_never_raises(initial, settings):
    controls, messages = controls_from_link(settings, initial)
    assert isinstance(controls, Controls) and all(
        isinstance(m, str) and len(m) < 300 for m in messages
    )
    scene = scene_from_controls(simcore.load_scene(), controls)  # the core accepts it
    assert 16 <= scene.detector.pixels <= 512
