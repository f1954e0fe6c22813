"""Scene files: the paper scene's values, TOML round trip, clear errors naming the key."""

import math

import pytest

import simcore
from simcore.scene import SceneError, dump_scene, load_scene, parse_assignment, scene_from_dict


def test_the_built_in_paper_scene_has_table_4s_values():
    s = load_scene("paper")
    assert s.laser.pulse_energy_j == 5e-3 and s.laser.pulse_width_s == 5e-9
    assert s.illumination_angle_rad == pytest.approx(0.030)
    assert s.transmit.transmittance == 0.95
    assert s.receive.aperture_diameter_m == 0.5 and s.receive.fov_rad == 0.03
    assert s.detector.pixels == 256 and s.detector.pixel_pitch_m == 150e-6
    assert s.focal_length_m == pytest.approx(1.28)
    assert s.ifov_rad == pytest.approx(117.2e-6, abs=0.05e-6)
    assert s.detector.responsivity_a_w == 25.0 and s.detector.bandwidth_hz == 120e6
    assert s.amplifiers.noise_factors == (1.05, 1.15, 1.15)
    assert s.timing.resolution_s == 100e-12 and s.pose.distance_m == 500.0


def test_a_scene_survives_a_toml_round_trip(tmp_path):
    scene = simcore.with_overrides(
        load_scene(),
        {
            "pitch_deg": 12.5,
            "target.materials": {"foil": "lambertian"},
            "paper_forms": ["eq30_4pi"],
            "amplifiers.power_gains": [10.0, 20.0, 30.0],
        },
    )
    path = tmp_path / "s.toml"
    path.write_text(dump_scene(scene))
    again = load_scene(path)
    assert again == scene.__class__(**{**scene.__dict__, "name": again.name})


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"pitch_deg": 500}, r"pose.pitch_deg = 500.* valid range \[-180, 180\] deg"),
        ({"pixels": 0}, r"detector.pixels = 0 .* \[1, 1024\]"),
        ({"pixels": 2.5}, r"detector.pixels: expected a whole number"),
        ({"distance_m": float("nan")}, r"pose.distance_m: NaN"),
        ({"pulse_energy_j": float("inf")}, r"pose|laser.pulse_energy_j"),
        ({"tnr": "high"}, r"timing.tnr: expected a number"),
        ({"colour": 3}, r"unknown scene key 'colour'"),
        ({"laser.pulse_widht_s": 1e-9}, r"did you mean laser.pulse_width_s"),
        ({"transmit.illumination": "laser"}, r"choose from flat_top, square, gaussian"),
        ({"fidelity.subrays": 8}, r"square number"),
        ({"amplifiers.power_gains": [1.0]}, r"one of each per stage"),
    ],
)
def test_bad_values_give_one_clear_message_naming_the_key(overrides, message):
    with pytest.raises(SceneError, match=message):
        simcore.with_overrides(load_scene(), overrides)


def test_unknown_section_in_a_file_is_named(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[lazer]\npulse_energy_j = 1e-3\n")
    with pytest.raises(SceneError, match=r"unknown scene section \[lazer\]; did you mean laser"):
        load_scene(path)


def test_malformed_toml_and_missing_files_are_named(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[laser\n")
    with pytest.raises(SceneError, match="broken.toml: not valid TOML"):
        load_scene(path)
    with pytest.raises(SceneError, match="scene file not found: nowhere.toml"):
        load_scene("nowhere.toml")


def test_command_line_assignments_are_read_as_toml_values():
    assert parse_assignment("pitch_deg=12.5") == ("pitch_deg", 12.5)
    assert parse_assignment("pixels=128") == ("pixels", 128)
    assert parse_assignment("transmit.illumination=square") == ("transmit.illumination", "square")
    assert parse_assignment("amplifiers.power_gains=[10, 10]") == (
        "amplifiers.power_gains",
        [10, 10],
    )
    with pytest.raises(SceneError, match="NAME=VALUE"):
        parse_assignment("pitch_deg")


def test_every_key_is_documented_with_a_unit():
    rows = simcore.key_reference()
    assert len(rows) > 40
    assert all(r["doc"] and r["unit"] for r in rows)
    assert not math.isnan(len(scene_from_dict({}).to_dict()))
