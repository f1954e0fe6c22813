"""The app's state: control ranges, the sanitiser (clamp or refuse, never raise) and the mapping
from controls in display units to a simcore Scene in SI units."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.app_helpers import ANYTHING

import simcore
from app.logic.scene_map import resolved_materials, scene_from_controls, scene_overrides
from app.state import (
    PRESET_CHOICES,
    SPECS,
    SUBRAY_CHOICES,
    Controls,
    controls_from_scene,
    preset_of,
    sanitize_controls,
)

PARTS = {"foil": "coating_1", "solar_L": "solar_panel"}


def test_the_control_ranges_are_the_issues_ranges_with_units_in_the_labels():
    ranges = {key: (spec.lo, spec.hi, spec.unit) for key, spec in SPECS.items()}
    assert ranges["pitch_deg"] == (-90, 90, "deg")
    assert ranges["azimuth_deg"] == (-180, 180, "deg")
    assert ranges["distance_m"] == (20, 5000, "m")
    assert ranges["pixels"][:2] == (16, 512)
    assert ranges["pulse_energy_mj"] == (0.01, 50, "mJ")
    assert ranges["tnr"][:2] == (1, 10)
    labels = [SPECS[k].label for k in ("pitch_deg", "azimuth_deg", "distance_m", "pixels")]
    assert labels == ["Pitch", "Azimuth", "Distance", "Pixels"]
    assert SPECS["pulse_energy_mj"].label == "Pulse energy" and SPECS["tnr"].label == "TNR"


def test_the_paper_scene_maps_to_controls_and_back_to_the_same_scene():
    paper = simcore.load_scene()
    model = simcore.load_target(paper.target)
    model_materials = dict(zip(model.part_names, model.part_materials, strict=True))
    controls, messages = controls_from_scene(paper, model_materials)
    assert messages == []
    assert (controls.distance_m, controls.pixels, controls.tnr) == (500.0, 256, 5.0)
    assert controls.pulse_energy_mj == pytest.approx(5.0)
    scene = scene_from_controls(paper, controls)
    assert scene.pose == paper.pose
    assert scene.detector == paper.detector
    assert scene.laser == paper.laser
    assert scene.timing == paper.timing
    assert scene.seed == paper.seed
    # the paper scene has the core's default fidelity: the app runs it with its own default
    assert controls.preset == "interactive" and scene.preset == "interactive"
    assert scene.fidelity == simcore.with_overrides(paper, {"preset": "interactive"}).fidelity
    assert dict(scene.target.materials) == model_materials


def test_a_scene_that_sets_every_part_with_a_star_keeps_it_in_the_app():
    scene = simcore.with_overrides(
        simcore.load_scene(), {"target.materials": {"*": "lambertian", "foil": "coating_1"}}
    )
    model = simcore.load_target(scene.target)
    controls, _ = controls_from_scene(scene, resolved_materials(model, scene))
    assert controls.materials["foil"] == "coating_1"
    assert {m for p, m in controls.materials.items() if p != "foil"} == {"lambertian"}
    rebuilt = resolved_materials(model, scene_from_controls(scene, controls))
    assert rebuilt == resolved_materials(model, scene)


def test_controls_in_display_units_become_si_scene_values():
    controls = Controls(
        pitch_deg=10,
        azimuth_deg=-30,
        distance_m=800,
        pixels=128,
        pulse_energy_mj=0.5,
        tnr=4,
        seed=7,
        subrays=16,
        preset="custom",
        materials={"foil": "lambertian"},
    )
    scene = scene_from_controls(simcore.load_scene(), controls)
    assert scene.laser.pulse_energy_j == pytest.approx(5e-4)
    assert (scene.pose.pitch_deg, scene.pose.azimuth_deg, scene.pose.distance_m) == (10, -30, 800)
    assert (scene.detector.pixels, scene.timing.tnr, scene.seed) == (128, 4, 7)
    assert scene.fidelity.subrays == 16
    assert dict(scene.target.materials) == {"foil": "lambertian"}
    assert scene_overrides(controls)["pulse_energy_j"] == pytest.approx(5e-4)


def test_values_outside_a_range_are_clamped_with_a_message_naming_the_control_and_unit():
    previous = Controls(materials=dict(PARTS))
    raw = {"distance_m": 1e9, "pitch_deg": -400, "pixels": 4, "pulse_energy_mj": 0, "tnr": 11}
    controls, messages = sanitize_controls(raw, previous)
    assert (controls.distance_m, controls.pitch_deg, controls.pixels) == (5000, -90, 16)
    assert (controls.pulse_energy_mj, controls.tnr) == (0.01, 10)
    assert "Distance 1e+09 is outside 20 to 5000 m; set to 5000 m" in messages
    assert any(m.startswith("Pitch -400 is outside -90 to 90 deg") for m in messages)
    assert len(messages) == 5


@pytest.mark.parametrize("bad", ["abc", "", None, float("nan"), True, [1], {"a": 1}])
def test_values_that_are_no_number_are_refused_and_the_previous_value_kept(bad):
    previous = Controls(distance_m=640.0)
    controls, messages = sanitize_controls({"distance_m": bad}, previous)
    assert controls.distance_m == 640.0
    assert len(messages) == 1 and messages[0].startswith("Distance")
    assert "kept 640 m" in messages[0]


def test_numbers_typed_as_text_are_accepted_and_whole_numbers_rounded():
    controls, messages = sanitize_controls(
        {"distance_m": "750", "pixels": "100.4", "seed": 3.0}, Controls()
    )
    assert (controls.distance_m, controls.pixels, controls.seed) == (750.0, 100, 3)
    assert isinstance(controls.pixels, int) and messages == []


def test_choices_outside_their_lists_are_refused():
    previous = Controls(subrays=4, color_by="snr", materials=dict(PARTS))
    raw = {
        "subrays": 5,
        "color_by": "rainbow",
        "image_kind": None,
        "materials": {"foil": "unobtainium", "nose": "lambertian", "solar_L": "lambertian"},
    }
    controls, messages = sanitize_controls(raw, previous)
    assert (controls.subrays, controls.color_by, controls.image_kind) == (4, "snr", "range")
    assert controls.materials == {"foil": "coating_1", "solar_L": "lambertian"}
    assert len(messages) == 5
    assert sanitize_controls({"subrays": "16"}, previous)[0].subrays == 16


def test_materials_that_are_not_a_mapping_are_refused():
    previous = Controls(materials=dict(PARTS))
    controls, messages = sanitize_controls({"materials": "gold"}, previous)
    assert controls.materials == PARTS and len(messages) == 1


@settings(max_examples=200, deadline=None)
@given(
    raw=st.fixed_dictionaries({key: ANYTHING for key in [*SPECS, "subrays", "preset", "color_by"]})
)
def test_any_websocket_values_give_valid_controls_and_a_valid_scene(raw):
    controls, _ = sanitize_controls(raw, Controls())
    for key, spec in SPECS.items():
        value = getattr(controls, key)
        assert spec.lo <= value <= spec.hi and math.isfinite(value)
    assert controls.subrays in SUBRAY_CHOICES and controls.preset in PRESET_CHOICES
    scene_from_controls(simcore.load_scene(), controls)  # never raises for sanitised controls


@pytest.mark.parametrize("name", ["interactive", "balanced", "reference"])
def test_a_fidelity_preset_reaches_the_scene_with_its_knobs(name):
    scene = scene_from_controls(simcore.load_scene(), Controls(preset=name, subrays=16))
    knobs = simcore.PRESETS[name]
    assert scene.preset == name
    for key, value in knobs.items():
        assert getattr(scene.fidelity, key.split(".", 1)[1]) == value  # subrays=16 is ignored
    assert preset_of(scene) == name


def test_custom_fidelity_keeps_the_scenes_knobs_with_the_chosen_subrays():
    paper = simcore.load_scene()
    scene = scene_from_controls(paper, Controls(preset="custom", subrays=16))
    assert scene.fidelity.subrays == 16
    assert scene.fidelity.refine_subrays == paper.fidelity.refine_subrays
    assert preset_of(scene) == "custom"


def test_a_scene_with_its_own_fidelity_opens_as_custom_and_a_bad_preset_is_refused():
    scene = simcore.with_overrides(simcore.load_scene(), {"fidelity.subrays": 16})
    model = simcore.load_target(scene.target)
    controls, messages = controls_from_scene(scene, resolved_materials(model, scene))
    assert (controls.preset, controls.subrays, messages) == ("custom", 16, [])
    kept, messages = sanitize_controls({"preset": "ultra"}, controls)
    assert kept.preset == "custom" and messages[0].startswith("Fidelity preset: 'ultra'")
