"""The stage cache, key by key: for every scene key of the key reference, a warm pipeline run
after changing only that key gives bit-identical arrays to a fresh pipeline on the changed scene.
A stage that forgets a scene value it reads (its Stage.reads) serves its stale output and fails
here; each change must also alter the result (else the case proves nothing), unless listed in
INERT with the reason."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from support.ideal_receiver import IDEAL, KIND

import simcore
from simcore import receivers
from simcore.scene import PAPER_FORMS

# two tilted plates, one 0.4 m behind the other, filling most of a 16 x 16 array (edges, a depth
# step, range slopes), 4 sub-rays per pixel, SNRs near the TNR
BASE = {
    "pulse_energy_j": 4e-8,
    "target.scale_m_per_unit": 1.0,
    "target.materials": {"*": "lambertian"},
    "pixels": 16,
    "fidelity.subrays": 4,
    "distance_m": 150.0,
    "seed": 3,
    "tnr": 3.0,
    "timing.range_gate_m": 60.0,
}
REFINE = {"fidelity.refine_subrays": 16}  # for the keys that only act when refining
# a Sun that lights the plates and the Earth behind them (background light in every pixel)
SUN = {"sun.mode": "manual", "sun.elevation_deg": 20.0, "sun.azimuth_deg": 30.0}
ORBIT = {"sun.mode": "orbit", "orbit.epoch_utc": "2024-03-20T12:00:00Z", "orbit.time_s": 2000.0}
TLE = (  # the ISS, 2024-03-19 (elements rounded; checksums computed)
    "1 25544U 98067A   24079.50000000  .00016717  00000-0  30180-3 0  999",
    "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.4981530844488",
)
GM = {"receiver.kind": "gm_apd"}  # for the Geiger-mode receiver's keys
GM_SHORT_DEAD = {**GM, "gm.dead_time_s": 20e-9}  # re-arming inside the 400 ns gate
# key -> (new value, extra base keys that make the key matter)
ALTERNATIVES = {
    "preset": ("interactive", {}),
    "seed": (11, {}),
    "conventions": ("paper", {}),
    "laser.wavelength_m": (1550e-9, {}),
    "laser.pulse_energy_j": (6e-8, {}),
    "laser.pulse_width_s": (3e-9, {}),
    "laser.divergence_rad": (1.5e-3, {}),
    "transmit.beam_expansion_ratio": (0.1, {}),
    "transmit.transmittance": (0.8, {}),
    "transmit.illumination": ("gaussian", {}),
    "receive.aperture_diameter_m": (0.3, {}),
    "receive.transmittance": (0.8, {}),
    "receive.fov_rad": (0.025, {}),
    "detector.pixels": (12, {}),
    "detector.pixel_pitch_m": (100e-6, {}),
    "detector.gain_from": ("gain", {}),
    "detector.responsivity_a_w": (15.0, {}),
    "detector.gain": (60.0, {"detector.gain_from": "gain"}),
    "detector.bias_voltage_v": (370.0, {"detector.gain_from": "bias"}),
    "detector.breakdown_voltage_v": (410.0, {"detector.gain_from": "bias"}),
    "detector.miller_exponent": (2.5, {"detector.gain_from": "bias"}),
    "detector.quantum_efficiency": (0.6, {}),
    "detector.excess_noise_k": (0.05, {}),
    "detector.bandwidth_hz": (80e6, {}),
    "detector.temperature_k": (350.0, {}),
    "detector.load_ohm": (20.0, {}),
    "detector.dark_surface_a": (1e-7, {}),
    "detector.dark_bulk_a": (1e-9, {}),
    "detector.snr_max": (5.0, {}),
    "amplifiers.noise_factors": ((1.5, 1.3, 1.3), {}),
    "amplifiers.power_gains": ((3.0, 100.0, 100.0), {}),
    "timing.tnr": (4.0, {}),
    "timing.resolution_s": (1e-9, {}),
    "timing.cfd_fraction": (0.3, {}),
    "timing.cfd_delay_s": (1e-9, {}),
    "timing.range_gate_m": (40.0, {}),
    "timing.gate_center_m": (160.0, {}),
    "timing.max_stops": (3, {}),
    "timing.rearm_holdoff_fwhm": (40.0, {"timing.max_stops": 3}),
    "target.mesh": ("other", {}),  # a single plate
    "target.scale_m_per_unit": (1.2, {}),
    "target.size_m": (3.0, {"target.scale_m_per_unit": 0.0}),
    "target.alpha_threshold": (0.0, {"target.mesh": "veiled"}),  # a translucent plate behind
    "target.material_map": ("map", {"target.materials": {}}),  # a map file
    "target.materials": ({"*": "coating_1"}, {}),
    "pose.pitch_deg": (10.0, {}),
    "pose.azimuth_deg": (-15.0, {}),
    "pose.roll_deg": (30.0, {}),
    "pose.distance_m": (140.0, {}),
    "pose.offset_x_m": (0.5, {}),
    "pose.offset_y_m": (-0.5, {}),
    "pose.quaternion_wxyz": ((0.98, 0.1, 0.15, 0.0), {}),
    "fidelity.subrays": (9, {}),
    "fidelity.time_step_s": (1e-10, {}),
    "fidelity.refine_subrays": (16, {}),
    "fidelity.refine_step_m": (0.5, REFINE),
    "fidelity.merge_window": (0.25, {}),
    "fidelity.probe_corners": (True, REFINE),
    "fidelity.cell_spread": (True, {}),
    "fidelity.noise_model": ("montecarlo", {}),
    "receiver.kind": (KIND, {}),
    "receive.filter_width_m": (3e-9, SUN),
    "receive.filter_transmittance": (0.5, SUN),
    "detector.linear_max_a": (1e-6, {}),
    "timing.threshold_mode": ("per_pixel", SUN),
    "sun.mode": ("manual", {}),
    "sun.azimuth_deg": (60.0, SUN),
    "sun.elevation_deg": (10.0, SUN),
    "orbit.epoch_utc": ("2024-06-21T00:00:00Z", ORBIT),
    "orbit.time_s": (900.0, ORBIT),
    "orbit.j2": (True, ORBIT),
    "orbit.target_tle": ("tle", ORBIT),
    "orbit.imaging_tle": ("tle", {"orbit.target_tle": "tle", **ORBIT}),
    "background.earth": (False, SUN),
    "background.earth_albedo": (0.1, SUN),
    "background.target_altitude_m": (400e3, SUN),
    "gm.pde": (0.5, GM),
    "gm.dark_count_rate_hz": (5e6, GM),
    "gm.dead_time_s": (20e-9, GM),
    "gm.jitter_s": (500e-12, GM),
    "gm.bin_s": (100e-12, GM),
    "gm.pulses": (30, GM),
    "gm.crosstalk": (0.2, GM),
    "gm.afterpulsing": (0.3, GM_SHORT_DEAD),
    "gm.coates": (False, GM),
    "gm.attenuation_db": (20.0, GM),
    "gm.pileup_correction": ("fit", {**GM, "gm.attenuation_db": 10.0}),
    "quality.tau_m": (0.002, {}),  # the ground-truth outlier flag of points 2 mm off
    "trajectory.kind": ("approach", {}),
    "trajectory.start_range_m": (300.0, {}),
    "trajectory.end_range_m": (50.0, {}),
    "trajectory.duration_s": (30.0, {}),
    "trajectory.frame_rate_hz": (2.0, {}),
    "trajectory.tumble_rate_deg_s": (5.0, {}),
    "trajectory.tumble_axis": ((1.0, 0.0, 0.0), {}),
    "trajectory.initial_quaternion_wxyz": ((0.0, 1.0, 0.0, 0.0), {}),
}
# keys whose change leaves this scene's arrays as they were, and why
INERT = {
    "detector.pixel_pitch_m": "sets only the focal length, which no stage uses",
    "orbit.imaging_tle": "the imaging satellite's orbit poses fly-around frames only",
    **{
        f"trajectory.{name}": "the trajectory poses fly-around frames only (each frame's pose keys)"
        for name in (
            "kind",
            "start_range_m",
            "end_range_m",
            "duration_s",
            "frame_rate_hz",
            "tumble_rate_deg_s",
            "tumble_axis",
            "initial_quaternion_wxyz",
        )
    },
}
CASES = [*(("paper_forms", (form,)) for form in PAPER_FORMS), *ALTERNATIVES.items()]


def test_every_key_of_the_reference_has_an_alternative_value():
    keys = {row["key"] for row in simcore.key_reference()}
    assert keys == set(ALTERNATIVES) | {"paper_forms"}


def write_plates(path, plates) -> str:
    """Square plates (size_m, z_offset_m, tilt_deg about y) facing the lidar, as one OBJ."""
    meshes = []
    for size_m, z_m, tilt_deg in plates:
        box = trimesh.creation.box(extents=(size_m, size_m, 1e-3))
        box.apply_transform(
            trimesh.transformations.rotation_matrix(np.radians(tilt_deg), (0, 1, 0))
        )
        box.apply_translation((0, 0, z_m))
        meshes.append(box)
    trimesh.util.concatenate(meshes).export(path)
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("keys")
    plate = write_plates(folder / "plate.obj", [(4.0, 0.0, 25.0), (1.5, -0.4, -10.0)])
    other = write_plates(folder / "other.obj", [(3.0, 0.0, -20.0)])
    material_map = folder / "map.toml"
    material_map.write_text('default = "solar_panel"\n')
    tle = "\n".join(line + str(_checksum(line)) for line in TLE)
    return {
        "plate": plate,
        "other": other,
        "map": str(material_map),
        "tle": tle,
        "veiled": write_veiled(folder / "veiled.glb"),
    }


def _checksum(line: str) -> int:
    """A TLE line's modulo-10 checksum (digits, and 1 for each minus sign)."""
    return (sum(int(c) for c in line if c.isdigit()) + line.count("-")) % 10


def write_veiled(path) -> str:
    """The two plates (opaque) and, 0.3 m behind them, a 6 m plate of glTF alpha 0.3 (BLEND)."""
    scene = trimesh.Scene()
    for name, plates, rgba, mode in (
        ("plates", [(4.0, 0.0, 25.0), (1.5, -0.4, -10.0)], [200, 200, 200, 255], None),
        ("veil", [(6.0, 0.3, 0.0)], [200, 200, 255, 77], "BLEND"),
    ):
        mesh = trimesh.load(write_plates(path.with_suffix(f".{name}.obj"), plates), force="mesh")
        mesh.visual = trimesh.visual.TextureVisuals(
            material=trimesh.visual.material.PBRMaterial(
                name=name, baseColorFactor=rgba, alphaMode=mode
            )
        )
        scene.add_geometry(mesh, geom_name=name)
    path.write_bytes(scene.export(file_type="glb"))
    return str(path)


@pytest.fixture(scope="module")
def ideal():
    receivers.register(IDEAL)
    yield
    receivers.unregister(KIND)


def arrays(result: simcore.Result) -> dict[str, np.ndarray]:
    """Every per-pixel and per-point product, and the echoes of a few pixels."""
    d, r, e = result.detection, result.receiver, result.echo
    out = {"points": result.points, "echo.pixel": e.pixel, "echo.weights": e.weights}
    out |= {f"attr.{k}": v for k, v in result.attributes.items()}
    for name in ("p_detect", "detected", "range_true_m", "range_sigma_m", "range_m"):
        out[f"detection.{name}"] = getattr(d, name)
    out["detection.threshold_w"] = np.array([d.threshold_w, d.n_false_expected])
    out["detection.n_false_per_pixel"] = np.atleast_1d(d.n_false_per_pixel)
    out["background.power_w"] = result.background.power_w
    out["receiver.peak_power_w"], out["receiver.snr"] = r.peak_power_w, r.snr
    out["echo.t_half_s"] = e.features.t_half_s
    out["echo.slope"] = e.features.cfd_slope_per_s
    n = result.pixels
    for row, col in ((n // 2, n // 2), (n // 2, n // 4), (n // 3, n // 2 + 1)):
        w = result.waveform(row, col)
        for name in ("t_s", "power_w", "filtered_w", "emitted_w"):
            out[f"waveform{row},{col}.{name}"] = getattr(w, name)
        marks = (w.t_half_s, w.threshold_w, w.range_m, w.range_true_m, w.p_detect, w.detected)
        out[f"waveform{row},{col}.marks"] = np.array(marks, dtype=np.float64)
    return out


def assert_bit_identical(got: dict, expected: dict) -> None:
    assert got.keys() == expected.keys()
    for name in expected:
        a, b = np.asarray(got[name]), np.asarray(expected[name])
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert a.tobytes() == b.tobytes(), f"{name} differs from a fresh pipeline's"


def differs(a: dict, b: dict) -> bool:
    return a.keys() != b.keys() or any(
        np.asarray(a[k]).shape != np.asarray(b[k]).shape
        or np.asarray(a[k]).tobytes() != np.asarray(b[k]).tobytes()
        for k in a
    )


@pytest.mark.parametrize(("key", "alternative"), CASES, ids=[c[0] for c in CASES])
def test_a_warm_run_after_changing_one_key_equals_a_fresh_run(key, alternative, files, ideal):
    value, extra = alternative if key != "paper_forms" else (alternative, {})
    value = files.get(value, value) if isinstance(value, str) else value
    extra = {k: files.get(v, v) if isinstance(v, str) else v for k, v in extra.items()}
    base = simcore.with_overrides(simcore.Scene(), {**BASE, "target.mesh": files["plate"], **extra})
    changed = simcore.with_overrides(base, {key: value})
    assert changed != base
    warm = simcore.Pipeline()
    before = arrays(warm.run(base))
    after = warm.run(changed)
    assert_bit_identical(arrays(after), arrays(simcore.Pipeline().run(changed)))
    assert differs(arrays(after), before) != (key in INERT), "the change must show (or be INERT)"
