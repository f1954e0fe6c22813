"""The scene's checks: every key against its declared range, and the rules between keys (the
time step, the orbit epoch, the TLEs and the Sun's band, and those the selected receiver
declares: the Geiger-mode histogram's size); a SceneError names the key to change. Run by
``Scene`` on construction."""

from __future__ import annotations

import datetime
import math

from ..errors import SceneError
from ..orbit.epoch import EPHEMERIS_FIRST_UTC, EPHEMERIS_LAST_UTC, parse_utc
from ..orbit.tle import check_tle
from ..plugins import registry
from .fields import check_fields
from .keys import SceneKeys
from .sections import MAX_TRAJECTORY_FRAMES, SECTIONS

MIN_TIME_STEP_S = 1e-11  # [s] the finest waveform time step (a 256 x 256 frame: ~3 s, ~0.6 GB)
MAX_SAMPLES_PER_PULSE = 1000  # [-] pulse width / time step at most
MAX_GATE_SAMPLES = 2**16  # [-] Monte Carlo samples per pixel over the gate (1 km at auto: 16k)
# [-] photon-noise model: samples over the whole array (every one drawn; 256 px over 1 km at auto:
# 1.05e9, about 2 minutes on two busy cores; 1,024 px: 1.7e10, past 120 s before this limit)
MAX_PHOTON_FRAME_SAMPLES = 2**30
SPEED_OF_LIGHT_M_S = 299_792_458.0  # [m/s] exact (SI)


def auto_time_step_s(scene: SceneKeys) -> float:
    """The waveform time step of ``fidelity.time_step_s = 0``: min(tau / 10, 1 / (20 B)) [s]
    (= ``echo.default_time_step_s``, which this module does not import: it loads no numpy)."""
    return min(scene.laser.pulse_width_s / 10.0, 1.0 / (20.0 * scene.detector.bandwidth_hz))


def _check_time_step(scene: SceneKeys) -> None:
    """fidelity.time_step_s is 0 (auto) or at least MIN_TIME_STEP_S and tau / 1000, and the
    Monte Carlo model's waveform over the range gate has at most MAX_GATE_SAMPLES samples: no
    value in range can make the echo windows exhaust memory or time."""
    dt = scene.fidelity.time_step_s
    tau = scene.laser.pulse_width_s
    floor_s = max(MIN_TIME_STEP_S, tau / MAX_SAMPLES_PER_PULSE)
    if 0.0 < dt < floor_s:
        raise SceneError(
            f"fidelity.time_step_s = {dt:g} s is too fine: give 0 (auto) or at least "
            f"{floor_s:g} s (10 ps, and laser.pulse_width_s / {MAX_SAMPLES_PER_PULSE})"
        )
    if scene.fidelity.noise_model not in ("montecarlo", "photon"):
        return
    step_s = dt or auto_time_step_s(scene)
    # the gate and the band limit's taps either side of it (6 sigma_h each, sigma_h = 1 / (4
    # sqrt(pi) B)): detector.bandwidth_hz = 1e3 adds 3.4e6 samples to every pixel's waveform
    sigma_h_s = 1.0 / (4.0 * math.sqrt(math.pi) * scene.detector.bandwidth_hz)
    samples = (2.0 * scene.timing.range_gate_m / SPEED_OF_LIGHT_M_S + 12.0 * sigma_h_s) / step_s
    if samples > MAX_GATE_SAMPLES:
        raise SceneError(
            f"timing.range_gate_m = {scene.timing.range_gate_m:g} m at a time step of "
            f"{step_s:.3g} s is {samples:.3g} samples per pixel for fidelity.noise_model = "
            f"{scene.fidelity.noise_model} with the band limit's taps (at most "
            f"{MAX_GATE_SAMPLES}): shorten the gate, give a coarser fidelity.time_step_s or a "
            "wider detector.bandwidth_hz"
        )
    frame = samples * scene.detector.pixels**2
    if scene.fidelity.noise_model == "photon" and frame > MAX_PHOTON_FRAME_SAMPLES:
        raise SceneError(
            f"detector.pixels = {scene.detector.pixels} with fidelity.noise_model = photon is "
            f"{frame:.3g} waveform samples a frame, each drawn photon by photon (at most "
            f"{MAX_PHOTON_FRAME_SAMPLES:.3g}, minutes of work): give fewer detector.pixels, a "
            "shorter timing.range_gate_m or fidelity.noise_model = montecarlo"
        )


SOLAR_TABLE_M = (900e-9, 1700e-9)


def _check_sun(scene: SceneKeys) -> None:
    """The orbit epoch inside the ephemeris's span, the TLEs parse, and with a Sun the laser
    line inside the solar table."""
    o = scene.orbit
    epoch = parse_utc("orbit.epoch_utc", o.epoch_utc)
    first = datetime.datetime.fromisoformat(EPHEMERIS_FIRST_UTC)
    last = datetime.datetime.fromisoformat(EPHEMERIS_LAST_UTC)
    span = f"the JPL DE421 ephemeris covers {first:%Y-%m-%d} to {last:%Y-%m-%d}"
    if not first <= epoch <= last:
        raise SceneError(f"orbit.epoch_utc = {o.epoch_utc!r} is outside the ephemeris: {span}")
    if o.time_s > (last - epoch).total_seconds():
        raise SceneError(
            f"orbit.time_s = {o.time_s:g} s after orbit.epoch_utc = {o.epoch_utc!r} is past the "
            f"ephemeris: {span}"
        )
    if o.imaging_tle and not o.target_tle:
        raise SceneError("orbit.imaging_tle is given without orbit.target_tle: give both or none")
    for key in ("orbit.target_tle", "orbit.imaging_tle"):
        text = getattr(o, key.split(".")[1])
        if text:
            check_tle(key, text, epoch + datetime.timedelta(seconds=o.time_s))
    if scene.sun.mode == "none":
        return
    lam, width = scene.laser.wavelength_m, scene.receive.filter_width_m
    lo, hi = SOLAR_TABLE_M
    if not (lo <= lam - width / 2 and lam + width / 2 <= hi):
        raise SceneError(
            f"laser.wavelength_m = {lam:g} m with receive.filter_width_m = {width:g} m: the "
            f"solar spectrum this simulator ships (ASTM E-490) covers {lo:g} to {hi:g} m; with "
            "sun.mode other than none the filter band must lie inside it"
        )


def _check_trajectory(scene: SceneKeys) -> None:
    """The tumble axis not zero, the initial attitude a quaternion, an approach or hold of at
    most MAX_TRAJECTORY_FRAMES frames, and no tumble under an orbit-lit Sun (the Sun's direction
    in the body frame there assumes the LVLH attitude)."""
    tr = scene.trajectory
    axis = tr.tumble_axis
    if len(axis) != 3 or math.hypot(*axis) < 1e-12:
        raise SceneError(
            f"trajectory.tumble_axis = {list(axis)!r}: give 3 numbers x, y, z, not all 0 "
            "(the body axis the target spins about)"
        )
    q = tr.initial_quaternion_wxyz
    if len(q) != 4 or math.hypot(*q) < 1e-9:
        raise SceneError(
            f"trajectory.initial_quaternion_wxyz = {list(q)!r}: give 4 numbers w, x, y, z, "
            "not all 0"
        )
    if tr.kind != "orbit":
        frames = math.floor(tr.duration_s * tr.frame_rate_hz * (1.0 + 1e-9)) + 1
        if frames > MAX_TRAJECTORY_FRAMES:
            raise SceneError(
                f"trajectory.frame_rate_hz = {tr.frame_rate_hz:g} Hz over trajectory.duration_s "
                f"= {tr.duration_s:g} s makes {frames} frames (at most "
                f"{MAX_TRAJECTORY_FRAMES}): lower the rate or shorten the duration"
            )
    turned = tr.tumble_rate_deg_s != 0.0 or any(
        abs(a - b) > 1e-12 for a, b in zip(q, (1.0, 0.0, 0.0, 0.0), strict=True)
    )
    if turned and scene.sun.mode == "orbit":
        raise SceneError(
            "trajectory.tumble_rate_deg_s / initial_quaternion_wxyz turn the target away from "
            "its LVLH attitude, which sun.mode = orbit assumes: use sun.mode = manual or none, "
            "or no tumble"
        )


def validate(scene: SceneKeys) -> None:
    """Check every value and the cross-field rules; raise SceneError naming the key."""
    check_fields(scene, "", names=("preset", "seed", "conventions", "paper_forms"))
    for section in SECTIONS:
        check_fields(getattr(scene, section), f"{section}.")
    for name, _ in scene.receiver_sections:
        if name not in SECTIONS:
            raise SceneError(f"[{name}] is no receiver's section")
    d = scene.detector
    if d.gain_from == "bias" and d.bias_voltage_v >= d.breakdown_voltage_v:
        raise SceneError(
            f"detector.bias_voltage_v = {d.bias_voltage_v:g} V must be below "
            f"detector.breakdown_voltage_v = {d.breakdown_voltage_v:g} V (Miller's law, Eq. 9)"
        )
    t = scene.target
    if t.size_m > 0 and t.scale_m_per_unit > 0:
        raise SceneError(
            f"target.size_m = {t.size_m:g} m and target.scale_m_per_unit = "
            f"{t.scale_m_per_unit:g} m are both set: give the size or the scale, not both"
        )
    fid = scene.fidelity
    kr = math.isqrt(fid.refine_subrays)
    if fid.refine_subrays and (kr * kr != fid.refine_subrays or fid.refine_subrays < fid.subrays):
        raise SceneError(
            f"fidelity.refine_subrays = {fid.refine_subrays} must be 0 or a square number "
            f"(4, 16, 64, ...) not below fidelity.subrays = {fid.subrays}"
        )
    k = math.isqrt(scene.fidelity.subrays)
    if k * k != scene.fidelity.subrays:
        raise SceneError(
            f"fidelity.subrays = {scene.fidelity.subrays} must be a square number "
            "(1, 4, 9, 16, ...)"
        )
    _check_time_step(scene)
    a = scene.amplifiers
    if len(a.noise_factors) != len(a.power_gains):
        raise SceneError(
            f"amplifiers.noise_factors has {len(a.noise_factors)} stages but "
            f"amplifiers.power_gains has {len(a.power_gains)}: give one of each per stage"
        )
    _check_sun(scene)
    _check_trajectory(scene)
    check = registry.get(scene.receiver.kind).check_scene  # the receiver's own rules
    if check is not None:
        registry.resolve(check)(scene)
    q = scene.pose.quaternion_wxyz
    if q and (len(q) != 4 or not all(math.isfinite(x) for x in q) or math.hypot(*q) < 1e-9):
        raise SceneError(
            f"pose.quaternion_wxyz = {q!r}: give 4 finite numbers w, x, y, z, not all 0"
        )
