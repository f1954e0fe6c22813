"""Scene description: frozen dataclasses, validation, TOML load and dump.

Every key carries its unit in its name (``distance_m``, ``pulse_energy_j``). Each field declares
its valid range and a one-line doc in its metadata, so validation, error messages and the README's
key reference all come from this one place (``lmapd keys`` prints the table).

The defaults are the paper's Table 4 ("paper" scene) plus documented choices for what the paper
leaves out (docs/physics.md#table-4).
"""

from __future__ import annotations

import dataclasses
import datetime
import difflib
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from ._assets import ASSETS_DIR
from .tomlfile import clip, read_toml_file

SCENES_DIR = ASSETS_DIR / "scenes"


class SceneError(ValueError):
    """A scene key, value or file is invalid. The message names the key and its valid range."""


def _f(
    default,
    unit: str,
    lo=None,
    hi=None,
    doc: str = "",
    choices=None,
    lo_open=False,
    zero_or=False,
):
    """A dataclass field with unit, valid range [lo, hi] (or (lo, hi] if lo_open) and a doc line.
    ``choices``: the valid values, or a function that returns them (a registry's). ``zero_or``:
    0 (meaning "auto" or "the default") is valid besides the range."""
    meta = {
        "unit": unit,
        "lo": lo,
        "hi": hi,
        "doc": doc,
        "choices": choices,
        "lo_open": lo_open,
        "zero_or": zero_or,
    }
    if isinstance(default, (list, dict)):
        raise TypeError("mutable default")
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class Laser:
    wavelength_m: float = _f(1064e-9, "m", 200e-9, 20e-6, "laser wavelength (not in the paper)")
    pulse_energy_j: float = _f(5e-3, "J", 0.0, 100.0, "energy per pulse (Table 4)", lo_open=True)
    pulse_width_s: float = _f(
        5e-9, "s", 10e-12, 1e-6, "pulse width tau of Eq. 1 (the FWHM in our convention)"
    )
    divergence_rad: float = _f(2e-3, "rad", 1e-6, 1.0, "laser full divergence before the expander")


@dataclass(frozen=True)
class TransmitOptics:
    beam_expansion_ratio: float = _f(
        1 / 15, "1", 1e-3, 1000.0, "divergence ratio out/in (1/15 widens 2 -> 30 mrad)"
    )
    transmittance: float = _f(
        0.95, "1", 0.0, 1.0, "transmit optics transmittance eta_t", lo_open=True
    )
    illumination: str = _f(
        "flat_top",
        "-",
        doc="illuminated spot: flat_top disc (Eq. 5), square, gaussian (Eq. 4)",
        choices=("flat_top", "square", "gaussian"),
    )


# The widest band-pass filter: 300 nm (a filter is tens of nm at most; wider is no filter). With a
# Sun the band must lie inside the shipped solar table, 900-1700 nm (SOLAR_TABLE_M), which
# 1064 +- 150 nm does; other laser lines are checked against the table (_check_sun).
MAX_FILTER_WIDTH_M = 300e-9


@dataclass(frozen=True)
class ReceiveOptics:
    aperture_diameter_m: float = _f(0.5, "m", 0.0, 20.0, "receiver aperture diameter", lo_open=True)
    transmittance: float = _f(
        0.95, "1", 0.0, 1.0, "receive optics transmittance eta_r (not given)", lo_open=True
    )
    fov_rad: float = _f(
        0.03, "rad", 0.0, 1.0, "full field of view of the array (Eq. 22)", lo_open=True
    )
    filter_width_m: float = _f(
        1e-9,
        "m",
        0.0,
        MAX_FILTER_WIDTH_M,
        "band-pass filter full width, a flat top centred on the laser line (background light); "
        "with a Sun the band must lie inside the shipped solar spectrum, 900-1700 nm",
        lo_open=True,
    )
    filter_transmittance: float = _f(
        0.9, "1", 0.0, 1.0, "band-pass filter transmittance in its band", lo_open=True
    )


@dataclass(frozen=True)
class Detector:
    pixels: int = _f(256, "px", 1, 1024, "pixels per side of the square LM-APD array")
    pixel_pitch_m: float = _f(
        150e-6, "m", 0.0, 1e-2, "pixel pitch (sets f_r = pixels*pitch/fov)", lo_open=True
    )
    gain_from: str = _f(
        "responsivity",
        "-",
        doc="how the APD gain M is given: responsivity, gain, or bias (Eq. 9)",
        choices=("responsivity", "gain", "bias"),
    )
    responsivity_a_w: float = _f(
        25.0, "A/W", 0.0, 1e4, "responsivity with gain (Eq. 8, Table 4)", lo_open=True
    )
    gain: float = _f(100.0, "1", 1.0, 1e4, "APD gain M when gain_from = gain")
    bias_voltage_v: float = _f(380.0, "V", 0.0, 1e4, "bias voltage when gain_from = bias")
    breakdown_voltage_v: float = _f(
        400.0, "V", 0.0, 1e4, "breakdown voltage V_B (Eq. 9)", lo_open=True
    )
    miller_exponent: float = _f(2.0, "1", 1.0, 10.0, "Miller exponent n (Eq. 9; Si 1.8-4)")
    quantum_efficiency: float = _f(
        0.4, "1", 0.0, 1.0, "quantum efficiency eta_q at the wavelength", lo_open=True
    )
    excess_noise_k: float = _f(0.02, "1", 0.0, 1.0, "ionisation ratio k of Eq. 11 (Si 0.02)")
    bandwidth_hz: float = _f(120e6, "Hz", 1e3, 1e11, "noise-equivalent bandwidth B")
    temperature_k: float = _f(298.15, "K", 0.0, 1000.0, "detector temperature", lo_open=True)
    load_ohm: float = _f(50.0, "ohm", 0.0, 1e9, "load resistance R_L (Eq. 13)", lo_open=True)
    dark_surface_a: float = _f(1e-9, "A", 0.0, 1e-3, "surface dark current I_ds (not multiplied)")
    dark_bulk_a: float = _f(1e-11, "A", 0.0, 1e-3, "bulk dark current I_db (primary)")
    snr_max: float = _f(
        math.inf, "1", 0.0, math.inf, "saturation: SNR ceiling (inf = none)", lo_open=True
    )
    linear_max_a: float = _f(
        math.inf,
        "A",
        0.0,
        math.inf,
        "largest APD output current (echo peak + background) the chain answers linearly; a "
        "pixel above it is flagged saturated and gives no point (inf = no limit)",
        lo_open=True,
    )


@dataclass(frozen=True)
class Amplifiers:
    noise_factors: tuple[float, ...] = _f(
        (1.05, 1.15, 1.15), "1", 1.0, 100.0, "noise factor of each stage (TIA, AGC, AGC; Table 4)"
    )
    power_gains: tuple[float, ...] = _f(
        (100.0, 100.0, 100.0),
        "1",
        0.0,
        1e9,
        "linear available power gain of each stage",
        lo_open=True,
    )


# The most stops per pixel and pulse ``timing.max_stops`` may ask for: multi-hit LM-APD readouts
# record a few (first stop is the common case); 16 bounds the false alarms of a frame at 16 per
# pixel whatever the TNR (docs/physics.md#limited-stops).
MAX_STOPS = 16


@dataclass(frozen=True)
class Timing:
    tnr: float = _f(5.0, "1", 0.0, 50.0, "threshold-to-noise ratio: V_T = tnr * sigma_n")
    resolution_s: float = _f(100e-12, "s", 0.0, 1e-6, "timing circuit resolution T_t (Eq. 26)")
    cfd_fraction: float = _f(0.5, "1", 0.0, 1.0, "CFD attenuation k_att (Eq. 19)", lo_open=True)
    cfd_delay_s: float = _f(
        0.0, "s", 0.0, 1e-6, "CFD delay t_d; 0 = auto (peak minus half-max time of the pulse)"
    )
    range_gate_m: float = _f(1000.0, "m", 0.0, 1e6, "range gate length R_gate", lo_open=True)
    gate_center_m: float = _f(0.0, "m", 0.0, 1e6, "range gate centre R_st; 0 = the target distance")
    max_stops: int = _f(
        1,
        "1",
        1,
        MAX_STOPS,
        "stops each pixel records per pulse (1 = first stop); noise stops before the echo mask it",
    )
    rearm_holdoff_fwhm: float = _f(
        1.0, "1", 0.0, 100.0, "dead time after a stop, in FWHMs of the emitted pulse (0 = none)"
    )
    threshold_mode: str = _f(
        "global",
        "-",
        doc="arming threshold TNR x the signal-free noise of a dark pixel, one for the array "
        "(global), or of each pixel, its background included (per_pixel)",
        choices=("global", "per_pixel"),
    )


@dataclass(frozen=True)
class Target:
    mesh: str = _f(
        "mro",
        "-",
        doc="built-in target (`lmapd targets`: NASA spacecraft, plate, sphere, cube, cylinder) "
        "or a path to a glTF (Draco too)/OBJ/STL/PLY mesh",
    )
    scale_m_per_unit: float = _f(
        0.0, "m", 0.0, 1e6, "metres per mesh unit; 0 = the target's own default (MRO: 15/89.74)"
    )
    size_m: float = _f(
        0.0,
        "m",
        1e-3,
        1e4,
        "the target's real size, its longest bounding-box side (instead of scale_m_per_unit); "
        "0 = the target's own size (a mesh file: 1 m per unit)",
        zero_or=True,
    )
    material_map: str = _f("", "-", doc="material map TOML; empty = the target's own")
    materials: tuple[tuple[str, str], ...] = _f(
        (), "-", doc="per-part material overrides: [target.materials] part = material"
    )
    alpha_threshold: float = _f(
        0.5,
        "1",
        0.0,
        1.0,
        "parts whose glTF opacity (base colour alpha, alphaMode BLEND or MASK) is below this "
        "are transparent to the lidar; 0 = every part is seen",
    )


@dataclass(frozen=True)
class Pose:
    pitch_deg: float = _f(0.0, "deg", -180.0, 180.0, "rotation about the array's horizontal axis")
    azimuth_deg: float = _f(0.0, "deg", -360.0, 360.0, "rotation about the array's vertical axis")
    roll_deg: float = _f(0.0, "deg", -360.0, 360.0, "rotation about the boresight")
    distance_m: float = _f(500.0, "m", 0.0, 1e6, "lidar to target centre", lo_open=True)
    offset_x_m: float = _f(0.0, "m", -1e6, 1e6, "target centre off the boresight, image right")
    offset_y_m: float = _f(0.0, "m", -1e6, 1e6, "target centre off the boresight, image down")
    quaternion_wxyz: tuple[float, ...] = _f(
        (), "-", doc="if given: target-body to sensor rotation, replaces pitch/azimuth/roll"
    )


@dataclass(frozen=True)
class Fidelity:
    subrays: int = _f(4, "1", 1, 1024, "sub-rays per pixel (a square number: 1, 4, 16, 64)")
    time_step_s: float = _f(
        0.0,
        "s",
        0.0,
        1e-7,
        "waveform time step; 0 = auto min(tau/10, 1/(20 B)); else at least 10 ps and "
        "tau/1000 (a pulse spans at most 1000 samples); with the montecarlo noise model the "
        "range gate spans at most 65536 samples",
    )
    refine_subrays: int = _f(
        0, "1", 0, 1024, "sub-rays for mixed pixels (edges, depth steps); 0 = no refinement"
    )
    refine_step_m: float = _f(
        0.02,
        "m",
        0.0,
        100.0,
        "depth step (range second difference) that marks a mixed pixel",
        lo_open=True,
    )
    merge_window: float = _f(
        0.0,
        "1",
        0.0,
        1.0,
        "sub-ray echoes arriving within this fraction of the band-limited pulse's 10-90 % rise "
        "time merge into two with the same energy, mean delay, spread and skew (0: never)",
    )
    probe_corners: bool = _f(
        False,
        "-",
        doc="with refinement: also cast a ray through every pixel corner to find mixed pixels "
        "(thin parts between pixel centres; the silhouette without its outer ring)",
    )
    cell_spread: bool = _f(
        False,
        "-",
        doc="each base sub-ray stands for its cell of the pixel: its echo is spread by the range "
        "change across the cell (slope from the pixel corners or the sub-ray plane), so one ray "
        "per pixel still sees a tilted surface broaden the pulse",
    )
    noise_model: str = _f(
        "statistical",
        "-",
        doc="statistical (Section 4: Eqs. 27-28 drawn), montecarlo (Section 5: noisy "
        "waveforms through the discriminator) or photon (the waveform Monte Carlo with Poisson "
        "photoelectrons, each multiplied by a gain drawn from McIntyre's distribution)",
        choices=("statistical", "montecarlo", "photon"),
    )


# The most pulses one Geiger-mode frame may accumulate: 10^4 pulses of a 256 x 256 array are
# 6.6e8 pixel-pulses (minutes on two cores); more is a different instrument (a long dwell).
MAX_GM_PULSES = 10_000


@dataclass(frozen=True)
class GeigerMode:
    pde: float = _f(
        0.3,
        "1",
        0.0,
        1.0,
        "Geiger-mode photon detection efficiency (InGaAs GM-APD at 1064 nm)",
        lo_open=True,
    )
    dark_count_rate_hz: float = _f(
        10e3, "Hz", 0.0, 1e9, "Geiger-mode dark count rate per pixel (armed)"
    )
    dead_time_s: float = _f(
        1e-6,
        "s",
        0.0,
        1.0,
        "Geiger-mode dead time after each avalanche: non-paralysable, re-armed at each gate "
        "opening (longer than the gate: first photon only)",
    )
    jitter_s: float = _f(
        200e-12, "s", 0.0, 1e-6, "Geiger-mode timing jitter (rms, Gaussian)", lo_open=True
    )
    bin_s: float = _f(
        250e-12,
        "s",
        0.0,
        10e-9,
        "Geiger-mode TDC bin width of the histogram (a coarse TDC: at most 10 ns, 1.5 m)",
        lo_open=True,
    )
    pulses: int = _f(
        100, "1", 1, MAX_GM_PULSES, "Geiger-mode pulses per frame, histogrammed per pixel"
    )
    crosstalk: float = _f(
        0.0, "1", 0.0, 0.5, "Geiger-mode crosstalk: chance an avalanche fires a 4-neighbour"
    )
    afterpulsing: float = _f(
        0.0, "1", 0.0, 0.5, "Geiger-mode afterpulsing: chance an avalanche fires again on re-arm"
    )
    coates: bool = _f(
        True, "-", doc="Geiger-mode range from the Coates-corrected histogram (false: raw counts)"
    )
    attenuation_db: float = _f(
        50.0,
        "dB",
        0.0,
        200.0,
        "Geiger-mode transmit attenuation: the frame's pulses carry laser.pulse_energy_j x "
        "10^(-attenuation_db / 10) (50 dB: the paper's 5 mJ becomes 50 nJ, under one "
        "photoelectron per pixel per pulse on the paper scene, where single-photon receivers "
        "operate; 0: the full pulse, piled up)",
    )
    pileup_correction: str = _f(
        "none",
        "-",
        doc="Geiger-mode first-photon (pile-up) correction: none (the centroid of the "
        "histogram) or fit (the first-photon model fitted to each pixel's first avalanches "
        "per armed pulse: echo start and photoelectrons per pulse)",
        choices=("none", "fit"),
    )


# The span of the JPL DE421 ephemeris this simulator uses for the Sun (the `de421` package; its
# documented span, "1900 through 2050"): the UTC dates orbit.epoch_utc (and epoch + time) may take.
EPHEMERIS_FIRST_UTC = "1900-01-01T00:00:00+00:00"
EPHEMERIS_LAST_UTC = "2050-12-31T00:00:00+00:00"
EARTH_RADIUS_M = 6378137.0  # [m] WGS84 semi-major axis (= orbit.R_EARTH_M)
TABLE3_ALTITUDE_M = 7073.22e3 - EARTH_RADIUS_M  # [m] Table 3's target: a - R_E, 695 km


@dataclass(frozen=True)
class Sun:
    mode: str = _f(
        "none",
        "-",
        doc="the Sun: none (the paper: no background light), manual (sun.azimuth_deg, "
        "sun.elevation_deg) or orbit (from orbit.epoch_utc, orbit.time_s and the target's orbit)",
        choices=("none", "manual", "orbit"),
    )
    azimuth_deg: float = _f(
        0.0,
        "deg",
        -360.0,
        360.0,
        "manual: the Sun's azimuth in the target body frame, from +x towards +y",
    )
    elevation_deg: float = _f(
        30.0,
        "deg",
        -90.0,
        90.0,
        "manual: the Sun's elevation above the target body's x-y plane, towards -z (away from "
        "the Earth: the body's z axis points at the Earth's centre)",
    )


@dataclass(frozen=True)
class Orbit:
    epoch_utc: str = _f(
        "2024-03-20T12:00:00Z",
        "-",
        doc="UTC epoch (ISO 8601) of the orbits' t = 0: the Sun from the JPL DE421 ephemeris "
        "(sun.mode = orbit and fly-arounds); 1900 to 2050",
    )
    time_s: float = _f(
        0.0,
        "s",
        0.0,
        1e9,
        "time since the epoch of this frame (sun.mode = orbit; a fly-around sets it per frame)",
    )
    j2: bool = _f(False, "-", doc="propagate the Table 3 orbits with the secular J2 rates")
    target_tle: str = _f(
        "",
        "-",
        doc="the target's two-line element set (two lines; propagated by SGP4); empty: the "
        "Table 3 elements",
    )
    imaging_tle: str = _f(
        "",
        "-",
        doc="the imaging satellite's two-line element set (fly-arounds; with orbit.target_tle)",
    )


@dataclass(frozen=True)
class Background:
    earth: bool = _f(
        True, "-", doc="the sunlit Earth behind the target adds its light (a Lambertian disc)"
    )
    earth_albedo: float = _f(
        0.3, "1", 0.0, 1.0, "the Earth's Lambertian albedo at the laser wavelength"
    )
    target_altitude_m: float = _f(
        TABLE3_ALTITUDE_M,
        "m",
        0.0,
        1e9,
        "sun.mode = manual: the target's altitude above the (spherical) Earth, which lies along "
        "its body z axis (orbit mode: from the orbit)",
        lo_open=True,
    )


# The valid values of ``receiver.kind``: the built-in receivers (``simcore.receivers.BUILT_IN``
# names the module of each), then those a module registers (``simcore.receivers.register`` adds
# them here). The scene holds only the names, so it depends on no receiver.
DEFAULT_RECEIVER = "lm_apd"
RECEIVER_KINDS: list[str] = [DEFAULT_RECEIVER, "gm_apd"]


def receiver_kinds() -> tuple[str, ...]:
    """The valid values of ``receiver.kind``: the built-in receivers, then the registered ones."""
    return tuple(RECEIVER_KINDS)


@dataclass(frozen=True)
class ReceiverSelection:
    kind: str = _f(
        DEFAULT_RECEIVER,
        "-",
        doc="the receiver behind the optics: lm_apd (the linear-mode APD chain, Eqs. 7-28) or "
        "gm_apd (a Geiger-mode single-photon array, the gm.* keys)",
        choices=receiver_kinds,
    )


PAPER_FORMS = (
    "pulse_constant",  # Eq. 1: a = 3.5 instead of 2.446 (tau is then not the FWHM)
    "eq30_4pi",  # Eq. 30: extra 1/(4 pi) and no cos(theta)
    "eq25_risetime",  # Eq. 25: c * tau_r * sqrt(1+k^2) / (SNR (1-k))
    # Eq. 25 (ours until issue 16): the peak's noise at both CFD samples, (c/2) sqrt(1 + k^2 -
    # 2 k rho_n) / (SNR |ds/dt|); pessimistic where shot noise matters (eq25_risetime wins over it)
    "eq25_equal_noise",
    "eq29_one_way",  # Eq. 29: one-way delays of the relief along the boresight
    "eq28_paper",  # Eq. 28: 2.2 * (2 R_gate / c) * df * 0.5 erfc(TNR / sqrt 2)
    "eq27_paper",  # Eq. 27: single-look, thermal-only 0.5 + 0.5 erf((SNR - TNR)/sqrt 2)
    "unfiltered_peak",  # Eq. 14: SNR from the unfiltered peak
    "qe_paper",  # quantum efficiency 0.6 ("about 0.6 for Si")
)


# Fidelity presets: the knobs each sets (explicit keys given with it take precedence).
# The echo timing is refined on exact values, so the time step mostly matters for resolving close
# double peaks; the sub-rays per pixel decide how well each pixel's depth profile is sampled.
PRESETS: dict[str, dict[str, Any]] = {
    # one sub-ray per pixel; pixels that one ray cannot represent (silhouettes, depth steps)
    # are re-cast with the reference's 64
    "interactive": {
        "fidelity.subrays": 1,
        "fidelity.refine_subrays": 64,
        "fidelity.refine_step_m": 0.02,
        "fidelity.probe_corners": True,
        "fidelity.cell_spread": True,
        "fidelity.merge_window": 0.25,
        "fidelity.time_step_s": 0.0,
    },
    "balanced": {
        "fidelity.subrays": 1,
        "fidelity.refine_subrays": 64,
        "fidelity.refine_step_m": 0.01,
        "fidelity.probe_corners": True,
        "fidelity.cell_spread": True,
        "fidelity.merge_window": 0.25,
        "fidelity.time_step_s": 0.0,
    },
    # every pixel sampled by 8 x 8 sub-rays, a finer time grid
    "reference": {
        "fidelity.subrays": 64,
        "fidelity.refine_subrays": 0,
        "fidelity.refine_step_m": 0.02,
        "fidelity.probe_corners": False,
        "fidelity.cell_spread": False,
        "fidelity.merge_window": 0.0,
        "fidelity.time_step_s": 1e-10,
    },
}


@dataclass(frozen=True)
class Quality:
    tau_m: float = _f(
        0.05,
        "m",
        0.0,
        100.0,
        "distance tolerance tau of the imaging-quality metrics (quality.*: precision, recall, "
        "F-score; a target point farther than tau from its surface is a ground-truth outlier)",
        lo_open=True,
    )


@dataclass(frozen=True)
class Scene:
    name: str = "paper"
    preset: str = _f(
        "",
        "-",
        doc="fidelity preset applied before the other keys: interactive, balanced, "
        "reference (empty: none)",
        choices=("", *PRESETS),
    )
    seed: int = _f(0, "1", 0, 2**63 - 1, "seed of every random draw")
    conventions: str = _f(
        "ours",
        "-",
        doc="ours (docs/physics.md#corrections, default) or paper (all the paper's literal forms)",
        choices=("ours", "paper"),
    )
    paper_forms: tuple[str, ...] = _f(
        (),
        "-",
        doc=f"individual paper forms on top of 'ours': {', '.join(PAPER_FORMS)}",
        choices=PAPER_FORMS,
    )
    laser: Laser = field(default_factory=Laser)
    transmit: TransmitOptics = field(default_factory=TransmitOptics)
    receive: ReceiveOptics = field(default_factory=ReceiveOptics)
    detector: Detector = field(default_factory=Detector)
    amplifiers: Amplifiers = field(default_factory=Amplifiers)
    timing: Timing = field(default_factory=Timing)
    target: Target = field(default_factory=Target)
    pose: Pose = field(default_factory=Pose)
    fidelity: Fidelity = field(default_factory=Fidelity)
    receiver: ReceiverSelection = field(default_factory=ReceiverSelection)
    sun: Sun = field(default_factory=Sun)
    orbit: Orbit = field(default_factory=Orbit)
    background: Background = field(default_factory=Background)
    gm: GeigerMode = field(default_factory=GeigerMode)
    quality: Quality = field(default_factory=Quality)

    def __post_init__(self):
        validate(self)

    def uses(self, form: str) -> bool:
        """True if the paper's literal form ``form`` (one of PAPER_FORMS) is in force."""
        return self.conventions == "paper" or form in self.paper_forms

    # -- derived quantities used by several stages ------------------------------------------------
    @property
    def illumination_angle_rad(self) -> float:
        """Full angle of the illuminated disc: divergence / expansion ratio (Eq. 5)."""
        return self.laser.divergence_rad / self.transmit.beam_expansion_ratio

    @property
    def ifov_rad(self) -> float:
        """Angular size of one pixel (Eq. 23)."""
        return self.receive.fov_rad / self.detector.pixels

    @property
    def focal_length_m(self) -> float:
        """Receiver focal length f_r = D_array / theta_fov (Eq. 22)."""
        return self.detector.pixels * self.detector.pixel_pitch_m / self.receive.fov_rad

    @property
    def gate_center_m(self) -> float:
        return self.timing.gate_center_m or self.pose.distance_m

    def to_dict(self) -> dict[str, Any]:
        """Every resolved parameter as a plain, JSON- and TOML-ready dict (the receiver section
        only for a receiver other than the default lm_apd: LM-APD scenes read as before the key
        existed)."""
        return _to_plain(self)


SECTIONS = {
    "laser": Laser,
    "transmit": TransmitOptics,
    "receive": ReceiveOptics,
    "detector": Detector,
    "amplifiers": Amplifiers,
    "timing": Timing,
    "target": Target,
    "pose": Pose,
    "fidelity": Fidelity,
    "receiver": ReceiverSelection,
    "sun": Sun,
    "orbit": Orbit,
    "background": Background,
    "gm": GeigerMode,
    "quality": Quality,
}

# The quick parameters shared by the CLI --set, the app state and the Python keyword API.
QUICK = {
    "pitch_deg": "pose.pitch_deg",
    "azimuth_deg": "pose.azimuth_deg",
    "distance_m": "pose.distance_m",
    "pixels": "detector.pixels",
    "pulse_energy_j": "laser.pulse_energy_j",
    "tnr": "timing.tnr",
    "seed": "seed",
}


# ----------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------
def _range_text(meta) -> str:
    lo, hi = meta["lo"], meta["hi"]
    left = "(" if meta["lo_open"] else "["
    zero = "0 or " if meta.get("zero_or") else ""
    return f"{zero}{left}{lo:g}, {hi:g}] {meta['unit']}".rstrip()


def _check_number(key: str, value, meta, integer: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{key}: expected a number, got {value!r}")
    if integer and not float(value).is_integer():
        raise SceneError(f"{key}: expected a whole number, got {value!r}")
    if math.isnan(value):
        raise SceneError(f"{key}: NaN is not a valid value; valid range {_range_text(meta)}")
    lo, hi = meta["lo"], meta["hi"]
    too_low = value <= lo if meta["lo_open"] else value < lo
    if meta.get("zero_or") and value == 0:
        return
    if (lo is not None and too_low) or (hi is not None and value > hi):
        raise SceneError(f"{key} = {value!r} is out of range; valid range {_range_text(meta)}")
    if math.isinf(value) and not math.isinf(hi):
        raise SceneError(f"{key}: infinite value; valid range {_range_text(meta)}")


def _validate_fields(obj, prefix: str, names=None) -> None:
    for f in dataclasses.fields(obj):
        meta = f.metadata
        if not meta or (names is not None and f.name not in names):
            continue
        key = f"{prefix}{f.name}"
        value = getattr(obj, f.name)
        values = value if isinstance(value, tuple) else (value,)
        if meta["choices"] is not None:
            choices = _choices(meta)
            for v in values:
                if v not in choices:
                    raise SceneError(
                        f"{key} = {v!r} is not valid; choose from {', '.join(choices)}"
                    )
        elif meta["lo"] is not None:
            if not values:
                raise SceneError(f"{key}: needs at least one value")
            for v in values:
                _check_number(key, v, meta, integer=isinstance(f.default, int))


def _choices(meta) -> tuple:
    choices = meta["choices"]
    return tuple(choices()) if callable(choices) else choices


MIN_TIME_STEP_S = 1e-11  # [s] the finest waveform time step (a 256 x 256 frame: ~3 s, ~0.6 GB)
MAX_SAMPLES_PER_PULSE = 1000  # [-] pulse width / time step at most
MAX_GATE_SAMPLES = 2**16  # [-] Monte Carlo samples per pixel over the gate (1 km at auto: 16k)
SPEED_OF_LIGHT_M_S = 299_792_458.0  # [m/s] exact (SI)


def auto_time_step_s(scene: Scene) -> float:
    """The waveform time step of ``fidelity.time_step_s = 0``: min(tau / 10, 1 / (20 B)) [s]
    (= ``echo.default_time_step_s``, which this module does not import: it loads no numpy)."""
    return min(scene.laser.pulse_width_s / 10.0, 1.0 / (20.0 * scene.detector.bandwidth_hz))


def _check_time_step(scene: Scene) -> None:
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
    samples = 2.0 * scene.timing.range_gate_m / SPEED_OF_LIGHT_M_S / step_s
    if samples > MAX_GATE_SAMPLES:
        raise SceneError(
            f"timing.range_gate_m = {scene.timing.range_gate_m:g} m at a time step of "
            f"{step_s:.3g} s is {samples:.3g} samples per pixel for fidelity.noise_model = "
            f"{scene.fidelity.noise_model} (at most {MAX_GATE_SAMPLES}): shorten the gate or "
            "give a coarser fidelity.time_step_s"
        )


# Geiger-mode histogram sizes (simcore/receivers/gm_apd.py): bins are int32 in the event records;
# each detected pixel's centroid reads a dense analysis window of
# (s + 4 jitter) + (12 s + 4 jitter) bins (s = tau / 2.446, the pulse's Gamma(2) scale), in
# blocks of GM_WINDOW_BLOCK_VALUES values (32 MB of float64); over the whole array at most
# GM_MAX_WINDOW_VALUES values (about 2 GB of float64 passes, seconds on two cores).
GM_MAX_GATE_BINS = 2**31 - 1
GM_WINDOW_BLOCK_VALUES = 1 << 22
GM_MAX_WINDOW_VALUES = 1 << 28
GM_PULSE_SCALE_OVER_TAU = 1.0 / 2.446386  # s / tau for Eq. 1 with tau the FWHM (the larger s)


def gm_analysis_window_bins(scene: Scene) -> float:
    """Bins of one Geiger-mode pixel's dense analysis window: one pulse scale s and four
    jitter sigmas before the peak window, twelve s and four sigmas after it (an upper bound of
    ``gm_apd.detect``'s, clipped to the gate)."""
    g = scene.gm
    s = scene.laser.pulse_width_s * GM_PULSE_SCALE_OVER_TAU
    reach = 4.0 * g.jitter_s
    window = (s + reach) / g.bin_s + (12.0 * s + reach) / g.bin_s + 3.0  # the ceils
    return min(window, gm_gate_bins(scene))


def gm_gate_bins(scene: Scene) -> float:
    """TDC bins of the Geiger-mode range gate (a float: it may exceed any integer type)."""
    lo = max(0.0, scene.gate_center_m - scene.timing.range_gate_m / 2.0)
    hi = scene.gate_center_m + scene.timing.range_gate_m / 2.0
    bins = 2.0 * (hi - lo) / SPEED_OF_LIGHT_M_S / scene.gm.bin_s
    return float(math.ceil(bins)) if math.isfinite(bins) else math.inf


def _check_gm_bins(scene: Scene) -> None:
    """The Geiger-mode gate fits int32 bins and the analysis windows stay within
    GM_WINDOW_BLOCK_VALUES per pixel and GM_MAX_WINDOW_VALUES over the array: refused before
    any ray is cast, naming the keys to change."""
    g = scene.gm
    n_bins = gm_gate_bins(scene)
    if n_bins > GM_MAX_GATE_BINS:
        raise SceneError(
            f"gm.bin_s = {g.bin_s:g} s splits the gate (timing.range_gate_m = "
            f"{scene.timing.range_gate_m:g} m) into {n_bins:.3g} bins (at most "
            f"{GM_MAX_GATE_BINS:,}): give a coarser gm.bin_s or a shorter timing.range_gate_m"
        )
    window = gm_analysis_window_bins(scene)
    total = window * scene.detector.pixels**2
    if window > GM_WINDOW_BLOCK_VALUES or total > GM_MAX_WINDOW_VALUES:
        floor_s = g.bin_s * max(window / GM_WINDOW_BLOCK_VALUES, total / GM_MAX_WINDOW_VALUES)
        raise SceneError(
            f"gm.bin_s = {g.bin_s:g} s is too fine for gm.jitter_s = {g.jitter_s:g} s and "
            f"laser.pulse_width_s = {scene.laser.pulse_width_s:g} s: each pixel's analysis "
            f"window is {window:.3g} bins, {total:.3g} over the {scene.detector.pixels}^2 "
            f"pixels (at most {GM_WINDOW_BLOCK_VALUES:,} and {GM_MAX_WINDOW_VALUES:,}): give "
            f"gm.bin_s of at least {floor_s:.2g} s, a smaller gm.jitter_s or fewer "
            "detector.pixels"
        )


# The band the shipped solar spectrum covers (simcore/data/astm_e490_am0_900_1700nm.csv)
SOLAR_TABLE_M = (900e-9, 1700e-9)


def parse_utc(key: str, text: str) -> datetime.datetime:
    """An ISO 8601 date and time as an aware UTC datetime (no zone given: UTC); SceneError
    naming ``key`` if it does not parse."""
    try:
        when = datetime.datetime.fromisoformat(text.strip())
    except (ValueError, AttributeError):
        raise SceneError(
            f"{key} = {text!r} is not an ISO 8601 date and time (e.g. 2024-03-20T12:00:00Z)"
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.UTC)
    try:
        return when.astimezone(datetime.UTC)
    except OverflowError:  # e.g. 0001-01-01T00:00+01:00 is before year 1 in UTC
        raise SceneError(
            f"{key} = {text!r} is outside the dates this simulator reads (years 1 to 9999 UTC)"
        ) from None


def _check_sun(scene: Scene) -> None:
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


def tle_lines(key: str, text: str) -> tuple[str, str]:
    """The two lines of a two-line element set (a title line before them is dropped), each
    checked for its line number, length and checksum (modulo 10); SceneError naming ``key``."""
    lines = [line.rstrip() for line in text.strip().splitlines() if line.strip()]
    if len(lines) == 3:
        lines = lines[1:]
    if len(lines) != 2:
        raise SceneError(f"{key}: a TLE is two lines (1 ... and 2 ...), got {len(lines)}")
    for number, line in zip("12", lines, strict=True):
        if not line.isascii():
            raise SceneError(f"{key}: line {number} has a character that is not ASCII")
        if len(line) != 69 or line[0] != number or line[1] != " ":
            raise SceneError(
                f"{key}: line {number} must be 69 characters starting with '{number} ', got "
                f"{line[:20]!r}... ({len(line)} characters)"
            )
        digits = sum(int(c) for c in line[:68] if c in DIGITS) + line[:68].count("-")
        if line[68] not in DIGITS or digits % 10 != int(line[68]):
            raise SceneError(f"{key}: line {number} fails its checksum (column 69)")
    return lines[0], lines[1]


DIGITS = "0123456789"
# What SGP4's error codes mean (python-sgp4, ``sgp4.api``: SGP4_ERRORS)
SGP4_ERRORS = {
    1: "its mean eccentricity is outside [0, 1) or its semi-major axis below 0.95 Earth radii",
    2: "its mean motion is negative",
    3: "its perturbed eccentricity is outside [0, 1]",
    4: "its semi-latus rectum is negative",
    5: "its orbit is sub-orbital",
    6: "its orbit lies inside the Earth (the satellite has decayed)",
}


def check_tle(key: str, text: str, when: datetime.datetime) -> None:
    """The TLE parses (SGP4) and its satellite is still in orbit at ``when`` (UTC)."""
    line1, line2 = tle_lines(key, text)
    from sgp4.api import Satrec, jday  # noqa: PLC0415  (only when a TLE is given)

    sat = Satrec.twoline2rv(line1, line2)
    if sat.error:
        why = SGP4_ERRORS.get(sat.error, "SGP4 cannot propagate it")
        raise SceneError(
            f"{key}: SGP4 cannot use this TLE: {why} (mean motion "
            f"{sat.no_kozai * 1440 / (2 * math.pi):.4g} rev/day; SGP4 error {sat.error})"
        )
    jd, fr = jday(when.year, when.month, when.day, when.hour, when.minute, when.second)
    error, r_km, _ = sat.sgp4(jd, fr + when.microsecond / 86400e6)
    if error:
        what = "has decayed" if error == 6 else f"fails to propagate (SGP4 error {error})"
        raise SceneError(
            f"{key}: the satellite {what} at {when:%Y-%m-%dT%H:%M:%SZ} (orbit.epoch_utc + "
            "orbit.time_s)"
        )


def validate(scene: Scene) -> None:
    """Check every value and the cross-field rules; raise SceneError naming the key."""
    _validate_fields(scene, "", names=("preset", "seed", "conventions", "paper_forms"))
    for section in SECTIONS:
        _validate_fields(getattr(scene, section), f"{section}.")
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
    if scene.receiver.kind == "gm_apd":
        _check_gm_bins(scene)
    q = scene.pose.quaternion_wxyz
    if q and (len(q) != 4 or not all(math.isfinite(x) for x in q) or math.hypot(*q) < 1e-9):
        raise SceneError(
            f"pose.quaternion_wxyz = {q!r}: give 4 finite numbers w, x, y, z, not all 0"
        )


# ----------------------------------------------------------------------------------------------
# building scenes from dicts, TOML and overrides
# ----------------------------------------------------------------------------------------------
def _coerce(key: str, f: dataclasses.Field, value):
    """Bring a TOML/CLI value to the field's type; raise SceneError with the key on mismatch."""
    default = f.default if f.default is not dataclasses.MISSING else None
    if isinstance(default, tuple):
        if f.name == "materials":
            if isinstance(value, dict):
                return tuple(sorted((str(k), str(v)) for k, v in value.items()))
            if isinstance(value, (list, tuple)) and all(
                isinstance(p, (list, tuple)) and len(p) == 2 for p in value
            ):
                return tuple((str(k), str(v)) for k, v in value)
            raise SceneError(f"{key}: expected a table part = material, got {value!r}")
        if isinstance(value, (int, float, str)) and not isinstance(value, bool):
            value = [value]
        if not isinstance(value, (list, tuple)):
            raise SceneError(f"{key}: expected a list, got {value!r}")
        if f.name == "paper_forms":
            return tuple(str(v) for v in value)
        return tuple(_coerce_scalar(key, 0.0, v) for v in value)
    return _coerce_scalar(key, default, value)


def _coerce_scalar(key: str, default, value):
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise SceneError(f"{key}: expected true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{key}: expected a whole number, got {value!r}")
        if isinstance(value, float) and not value.is_integer():
            raise SceneError(f"{key}: expected a whole number, got {value!r}")
        return int(value)
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise SceneError(f"{key}: expected a string, got {value!r}")
        return value
    return value


def _known_keys() -> list[str]:
    keys = [f"{s}.{f.name}" for s, cls in SECTIONS.items() for f in dataclasses.fields(cls)]
    return ["name", "preset", "seed", "conventions", "paper_forms", *keys, *QUICK]


def _unknown(key: str, what: str | None = None, candidates=None) -> SceneError:
    close = difflib.get_close_matches(key.strip("[]"), candidates or _known_keys(), n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else "; `lmapd keys` lists every key"
    return SceneError(f"{what or f'unknown scene key {key!r}'}{hint}")


def scene_from_dict(data: dict[str, Any], base: Scene | None = None) -> Scene:
    """Build a Scene from nested dicts (as read from TOML) on top of ``base`` (default: paper)."""
    base = base or Scene()
    flat: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict) and key not in SECTIONS:
            raise _unknown(f"[{key}]", f"unknown scene section [{key}]", list(SECTIONS))
        if key in SECTIONS:
            if not isinstance(value, dict):
                raise SceneError(f"[{key}] must be a table of keys, got {value!r}")
            for sub, v in value.items():
                flat[f"{key}.{sub}"] = v
        else:
            flat[key] = value
    return with_overrides(base, flat)


def with_overrides(scene: Scene, overrides: dict[str, Any] | None = None, **quick) -> Scene:
    """Return a copy of ``scene`` with dotted keys (``laser.pulse_width_s``) or quick names
    (``pitch_deg``) replaced. Unknown keys and invalid values raise SceneError naming the key."""
    items = {**(overrides or {}), **quick}
    if not items:
        return scene
    preset = items.get("preset")
    if preset:
        if not isinstance(preset, str) or preset not in PRESETS:
            raise SceneError(f"preset = {preset!r} is not valid; choose from {', '.join(PRESETS)}")
        items = {**PRESETS[preset], **items}
    top: dict[str, Any] = {}
    sections: dict[str, dict[str, Any]] = {}
    for key, value in items.items():
        dotted = QUICK.get(key, key)
        if "." in dotted:
            section, name = dotted.split(".", 1)
            cls = SECTIONS.get(section)
            if cls is None:
                raise _unknown(key)
            fields = {f.name: f for f in dataclasses.fields(cls)}
            if name not in fields:
                raise _unknown(key)
            sections.setdefault(section, {})[name] = _coerce(dotted, fields[name], value)
        else:
            fields = {f.name: f for f in dataclasses.fields(Scene) if f.name not in SECTIONS}
            if dotted not in fields:
                raise _unknown(key)
            f = fields[dotted]
            if dotted == "name":
                top[dotted] = str(value)
            else:
                top[dotted] = _coerce(dotted, f, value)
    for section, changes in sections.items():
        top[section] = dataclasses.replace(getattr(scene, section), **changes)
    return dataclasses.replace(scene, **top)


def parse_assignment(text: str) -> tuple[str, Any]:
    """Parse ``NAME=VALUE`` from the command line; VALUE is read as TOML (numbers, strings,
    lists), falling back to a bare string."""
    if "=" not in text:
        raise SceneError(f"--set expects NAME=VALUE, got {text!r}")
    key, raw = text.split("=", 1)
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except (ValueError, RecursionError):  # not TOML (or a number of more than 4300 digits)
        value = raw.strip()
    return key, value


def builtin_scenes() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def read_toml(path: Path, error: type[SceneError] = SceneError) -> dict[str, Any]:
    """The tables of a TOML file; ``error`` (a SceneError) names the file if it is missing, not a
    file, larger than ``tomlfile.MAX_TOML_BYTES`` or not TOML."""
    return read_toml_file(path, "scene file", error)


def _is_builtin(name: str) -> bool:
    """Whether ``name`` is a built-in scene (``paper``); False for anything not a plain name."""
    return name in builtin_scenes()


def load_scene(source: str | Path | None = None) -> Scene:
    """Load a scene: None or a built-in name (``paper``) or a path to a TOML file."""
    if source is None:
        source = "paper"
    path = Path(source)
    if not path.suffix and _is_builtin(str(source)):
        path = SCENES_DIR / f"{source}.toml"
    if not os.path.lexists(path):  # never raises (a path too long for the system is not there)
        names = ", ".join(builtin_scenes())
        raise SceneError(f"scene file not found: {clip(source)} (built-in scenes: {names})")
    data = read_toml(path)
    data.setdefault("name", path.stem)
    scene = scene_from_dict(data)
    # a relative mesh path in a scene file is relative to that file
    mesh = scene.target.mesh
    if any(mesh.lower().endswith(ext) for ext in MESH_SUFFIXES) and not Path(mesh).is_absolute():
        scene = with_overrides(scene, {"target.mesh": str((path.parent / mesh).resolve())})
    return scene


MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".stl", ".ply")


def _to_plain(obj, inf_as_text: bool = True):
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            out[f.name] = dict(v) if f.name == "materials" else _to_plain(v, inf_as_text)
        return out
    if isinstance(obj, tuple):
        return [_to_plain(v, inf_as_text) for v in obj]
    if inf_as_text and isinstance(obj, float) and math.isinf(obj):
        return "inf"  # strict JSON has no infinity
    return obj


def dump_scene(scene: Scene) -> str:
    """The scene as TOML text that load_scene reads back to an equal Scene (TOML has inf)."""
    return tomli_w.dumps(_to_plain(scene, inf_as_text=False))


def key_reference() -> list[dict[str, str]]:
    """One row per scene key: key, unit, default, valid range, doc (for `lmapd keys`, README)."""
    rows = []
    for name in ("preset", "seed", "conventions", "paper_forms"):
        f = next(f for f in dataclasses.fields(Scene) if f.name == name)
        rows.append(_row(name, f))
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            rows.append(_row(f"{section}.{f.name}", f))
    return rows


def _row(key, f):
    m = f.metadata
    if m["choices"] is not None:
        valid = " / ".join(_choices(m))
    elif m["lo"] is not None:
        valid = _range_text(m)
    else:
        valid = ""
    default = f.default
    return {
        "key": key,
        "unit": m["unit"],
        "default": repr(default) if isinstance(default, str) else str(default),
        "valid": valid,
        "doc": m["doc"],
    }
