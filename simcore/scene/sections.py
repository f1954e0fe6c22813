"""The scene's sections: one frozen dataclass per TOML table (``[laser]``, ``[detector]``, ...).

Every key carries its unit in its name (``distance_m``, ``pulse_energy_j``). Each field declares
its valid range and a one-line doc in its metadata (``fields.key``), so validation, error messages
and the README's key reference all come from this one place (``lmapd keys`` prints the table).

The defaults are the paper's Table 4 ("paper" scene) plus documented choices for what the paper
leaves out (docs/physics.md#table-4).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from ..plugins import registry
from .fields import key
from .trajectory_section import MAX_TRAJECTORY_FRAMES as MAX_TRAJECTORY_FRAMES
from .trajectory_section import Trajectory


@dataclass(frozen=True)
class Laser:
    wavelength_m: float = key(1064e-9, "m", 200e-9, 20e-6, "laser wavelength (not in the paper)")
    pulse_energy_j: float = key(5e-3, "J", 0.0, 100.0, "energy per pulse (Table 4)", lo_open=True)
    pulse_width_s: float = key(
        5e-9,
        "s",
        10e-12,
        1e-6,
        "pulse width tau of Eq. 1 (the FWHM in our convention); a 10-30 ps pulse needs a wider "
        "detector.bandwidth_hz (10 ps: 5 GHz, 30 ps: 200 MHz): at 120 MHz its step, tau/10, "
        "makes the statistical model's gross-error table minutes of work, refused (see "
        "detector.bandwidth_hz)",
    )
    divergence_rad: float = key(2e-3, "rad", 1e-6, 1.0, "laser full divergence before the expander")


@dataclass(frozen=True)
class TransmitOptics:
    beam_expansion_ratio: float = key(
        1 / 15, "1", 1e-3, 1000.0, "divergence ratio out/in (1/15 widens 2 -> 30 mrad)"
    )
    transmittance: float = key(
        0.95, "1", 0.0, 1.0, "transmit optics transmittance eta_t", lo_open=True
    )
    illumination: str = key(
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
    aperture_diameter_m: float = key(
        0.5, "m", 0.0, 20.0, "receiver aperture diameter", lo_open=True
    )
    transmittance: float = key(
        0.95, "1", 0.0, 1.0, "receive optics transmittance eta_r (not given)", lo_open=True
    )
    fov_rad: float = key(
        0.03, "rad", 0.0, 1.0, "full field of view of the array (Eq. 22)", lo_open=True
    )
    filter_width_m: float = key(
        1e-9,
        "m",
        0.0,
        MAX_FILTER_WIDTH_M,
        "band-pass filter full width, a flat top centred on the laser line (background light); "
        "with a Sun the band must lie inside the shipped solar spectrum, 900-1700 nm",
        lo_open=True,
    )
    filter_transmittance: float = key(
        0.9, "1", 0.0, 1.0, "band-pass filter transmittance in its band", lo_open=True
    )


@dataclass(frozen=True)
class Detector:
    pixels: int = key(256, "px", 1, 1024, "pixels per side of the square LM-APD array")
    pixel_pitch_m: float = key(
        150e-6, "m", 0.0, 1e-2, "pixel pitch (sets f_r = pixels*pitch/fov)", lo_open=True
    )
    gain_from: str = key(
        "responsivity",
        "-",
        doc="how the APD gain M is given: responsivity, gain, or bias (Eq. 9)",
        choices=("responsivity", "gain", "bias"),
    )
    responsivity_a_w: float = key(
        25.0, "A/W", 0.0, 1e4, "responsivity with gain (Eq. 8, Table 4)", lo_open=True
    )
    gain: float = key(100.0, "1", 1.0, 1e4, "APD gain M when gain_from = gain")
    bias_voltage_v: float = key(380.0, "V", 0.0, 1e4, "bias voltage when gain_from = bias")
    breakdown_voltage_v: float = key(
        400.0, "V", 0.0, 1e4, "breakdown voltage V_B (Eq. 9)", lo_open=True
    )
    miller_exponent: float = key(2.0, "1", 1.0, 10.0, "Miller exponent n (Eq. 9; Si 1.8-4)")
    quantum_efficiency: float = key(
        0.4, "1", 0.0, 1.0, "quantum efficiency eta_q at the wavelength", lo_open=True
    )
    excess_noise_k: float = key(0.02, "1", 0.0, 1.0, "ionisation ratio k of Eq. 11 (Si 0.02)")
    bandwidth_hz: float = key(
        120e6,
        "Hz",
        1e3,
        1e11,
        "noise-equivalent bandwidth B; far from 1 / (2 tau) the work grows (a band limit wide "
        "against the time step, a step fine against a 2.5 m gate): a frame whose echo windows "
        "(2^28 samples) or gross-error table (2^41 samples x taps) would pass its limit is "
        "refused before either is computed",
    )
    temperature_k: float = key(298.15, "K", 0.0, 1000.0, "detector temperature", lo_open=True)
    load_ohm: float = key(50.0, "ohm", 0.0, 1e9, "load resistance R_L (Eq. 13)", lo_open=True)
    dark_surface_a: float = key(1e-9, "A", 0.0, 1e-3, "surface dark current I_ds (not multiplied)")
    dark_bulk_a: float = key(1e-11, "A", 0.0, 1e-3, "bulk dark current I_db (primary)")
    snr_max: float = key(
        math.inf, "1", 0.0, math.inf, "saturation: SNR ceiling (inf = none)", lo_open=True
    )
    linear_max_a: float = key(
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
    noise_factors: tuple[float, ...] = key(
        (1.05, 1.15, 1.15), "1", 1.0, 100.0, "noise factor of each stage (TIA, AGC, AGC; Table 4)"
    )
    power_gains: tuple[float, ...] = key(
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
    tnr: float = key(5.0, "1", 0.0, 50.0, "threshold-to-noise ratio: V_T = tnr * sigma_n")
    resolution_s: float = key(100e-12, "s", 0.0, 1e-6, "timing circuit resolution T_t (Eq. 26)")
    cfd_fraction: float = key(0.5, "1", 0.0, 1.0, "CFD attenuation k_att (Eq. 19)", lo_open=True)
    cfd_delay_s: float = key(
        0.0, "s", 0.0, 1e-6, "CFD delay t_d; 0 = auto (peak minus half-max time of the pulse)"
    )
    range_gate_m: float = key(1000.0, "m", 0.0, 1e6, "range gate length R_gate", lo_open=True)
    gate_center_m: float = key(
        0.0, "m", 0.0, 1e6, "range gate centre R_st; 0 = the target distance"
    )
    max_stops: int = key(
        1,
        "1",
        1,
        MAX_STOPS,
        "stops each pixel records per pulse (1 = first stop); noise stops before the echo mask it",
    )
    rearm_holdoff_fwhm: float = key(
        1.0, "1", 0.0, 100.0, "dead time after a stop, in FWHMs of the emitted pulse (0 = none)"
    )
    threshold_mode: str = key(
        "global",
        "-",
        doc="arming threshold TNR x the signal-free noise of a dark pixel, one for the array "
        "(global), or of each pixel, its background included (per_pixel)",
        choices=("global", "per_pixel"),
    )


@dataclass(frozen=True)
class Target:
    mesh: str = key(
        "mro",
        "-",
        doc="built-in target (`lmapd targets`: NASA spacecraft, plate, sphere, cube, cylinder) "
        "or a path to a glTF (Draco too)/OBJ/STL/PLY mesh",
    )
    scale_m_per_unit: float = key(
        0.0, "m", 0.0, 1e6, "metres per mesh unit; 0 = the target's own default (MRO: 15/89.74)"
    )
    size_m: float = key(
        0.0,
        "m",
        1e-3,
        1e4,
        "the target's real size, its longest bounding-box side (instead of scale_m_per_unit); "
        "0 = the target's own size (a mesh file: 1 m per unit)",
        zero_or=True,
    )
    material_map: str = key("", "-", doc="material map TOML; empty = the target's own")
    materials: tuple[tuple[str, str], ...] = key(
        (), "-", doc="per-part material overrides: [target.materials] part = material"
    )
    alpha_threshold: float = key(
        0.5,
        "1",
        0.0,
        1.0,
        "parts whose glTF opacity (base colour alpha, alphaMode BLEND or MASK) is below this "
        "are transparent to the lidar; 0 = every part is seen",
    )


@dataclass(frozen=True)
class Pose:
    pitch_deg: float = key(0.0, "deg", -180.0, 180.0, "rotation about the array's horizontal axis")
    azimuth_deg: float = key(0.0, "deg", -360.0, 360.0, "rotation about the array's vertical axis")
    roll_deg: float = key(0.0, "deg", -360.0, 360.0, "rotation about the boresight")
    distance_m: float = key(500.0, "m", 0.0, 1e6, "lidar to target centre", lo_open=True)
    offset_x_m: float = key(0.0, "m", -1e6, 1e6, "target centre off the boresight, image right")
    offset_y_m: float = key(0.0, "m", -1e6, 1e6, "target centre off the boresight, image down")
    quaternion_wxyz: tuple[float, ...] = key(
        (), "-", doc="if given: target-body to sensor rotation, replaces pitch/azimuth/roll"
    )


@dataclass(frozen=True)
class Fidelity:
    subrays: int = key(4, "1", 1, 1024, "sub-rays per pixel (a square number: 1, 4, 16, 64)")
    time_step_s: float = key(
        0.0,
        "s",
        0.0,
        1e-7,
        "waveform time step; 0 = auto min(tau/10, 1/(20 B)); else at least 10 ps and "
        "tau/1000 (a pulse spans at most 1000 samples); with the montecarlo and photon noise "
        "models the range gate and the band limit's taps span at most 65536 samples (photon: "
        "at most 2^30 over the array)",
    )
    refine_subrays: int = key(
        0, "1", 0, 1024, "sub-rays for mixed pixels (edges, depth steps); 0 = no refinement"
    )
    refine_step_m: float = key(
        0.02,
        "m",
        0.0,
        100.0,
        "depth step (range second difference) that marks a mixed pixel",
        lo_open=True,
    )
    merge_window: float = key(
        0.0,
        "1",
        0.0,
        1.0,
        "sub-ray echoes arriving within this fraction of the band-limited pulse's 10-90 % rise "
        "time merge into two with the same energy, mean delay, spread and skew (0: never)",
    )
    probe_corners: bool = key(
        False,
        "-",
        doc="with refinement: also cast a ray through every pixel corner to find mixed pixels "
        "(thin parts between pixel centres; the silhouette without its outer ring)",
    )
    cell_spread: bool = key(
        False,
        "-",
        doc="each base sub-ray stands for its cell of the pixel: its echo is spread by the range "
        "change across the cell (slope from the pixel corners or the sub-ray plane), so one ray "
        "per pixel still sees a tilted surface broaden the pulse",
    )
    noise_model: str = key(
        "statistical",
        "-",
        doc="statistical (Section 4: Eqs. 27-28 drawn), montecarlo (Section 5: noisy "
        "waveforms through the discriminator) or photon (the waveform Monte Carlo with Poisson "
        "photoelectrons, each multiplied by a gain drawn from McIntyre's distribution)",
        choices=("statistical", "montecarlo", "photon"),
    )


EARTH_RADIUS_M = 6378137.0  # [m] WGS84 semi-major axis (= orbit.R_EARTH_M)
TABLE3_ALTITUDE_M = 7073.22e3 - EARTH_RADIUS_M  # [m] Table 3's target: a - R_E, 695 km


@dataclass(frozen=True)
class Sun:
    mode: str = key(
        "none",
        "-",
        doc="the Sun: none (the paper: no background light), manual (sun.azimuth_deg, "
        "sun.elevation_deg) or orbit (from orbit.epoch_utc, orbit.time_s and the target's orbit)",
        choices=("none", "manual", "orbit"),
    )
    azimuth_deg: float = key(
        0.0,
        "deg",
        -360.0,
        360.0,
        "manual: the Sun's azimuth in the target body frame, from +x towards +y",
    )
    elevation_deg: float = key(
        30.0,
        "deg",
        -90.0,
        90.0,
        "manual: the Sun's elevation above the target body's x-y plane, towards -z (away from "
        "the Earth: the body's z axis points at the Earth's centre)",
    )


@dataclass(frozen=True)
class Orbit:
    epoch_utc: str = key(
        "2024-03-20T12:00:00Z",
        "-",
        doc="UTC epoch (ISO 8601) of the orbits' t = 0: the Sun from the JPL DE421 ephemeris "
        "(sun.mode = orbit and fly-arounds); 1900 to 2050",
    )
    time_s: float = key(
        0.0,
        "s",
        0.0,
        1e9,
        "time since the epoch of this frame (sun.mode = orbit; a fly-around sets it per frame)",
    )
    j2: bool = key(False, "-", doc="propagate the Table 3 orbits with the secular J2 rates")
    target_tle: str = key(
        "",
        "-",
        doc="the target's two-line element set (two lines; propagated by SGP4); empty: the "
        "Table 3 elements",
    )
    imaging_tle: str = key(
        "",
        "-",
        doc="the imaging satellite's two-line element set (fly-arounds; with orbit.target_tle)",
    )


@dataclass(frozen=True)
class Background:
    earth: bool = key(
        True, "-", doc="the sunlit Earth behind the target adds its light (a Lambertian disc)"
    )
    earth_albedo: float = key(
        0.3, "1", 0.0, 1.0, "the Earth's Lambertian albedo at the laser wavelength"
    )
    target_altitude_m: float = key(
        TABLE3_ALTITUDE_M,
        "m",
        0.0,
        1e9,
        "sun.mode = manual: the target's altitude above the (spherical) Earth, which lies along "
        "its body z axis (orbit mode: from the orbit)",
        lo_open=True,
    )


# The valid values of ``receiver.kind`` are the receivers' registry's
# (``simcore.plugins.registry``, which loads only the standard library until a receiver runs): the
# scene holds only the names.
DEFAULT_RECEIVER = registry.DEFAULT_KIND


@dataclass(frozen=True)
class ReceiverSelection:
    kind: str = key(
        DEFAULT_RECEIVER,
        "-",
        doc="the receiver behind the optics: lm_apd (the linear-mode APD chain, Eqs. 7-28) or "
        "gm_apd (a Geiger-mode single-photon array, the gm.* keys)",
        choices=registry.kinds,
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


@dataclass(frozen=True)
class Quality:
    tau_m: float = key(
        0.05,
        "m",
        0.0,
        100.0,
        "distance tolerance tau of the imaging-quality metrics (quality.*: precision, recall, "
        "F-score; a target point farther than tau from its surface is a ground-truth outlier)",
        lo_open=True,
    )


# The shared sections, then each receiver's own (``registry.sections()``: ``gm`` of the
# Geiger-mode array), then the imaging-quality metrics'.
_SHARED_SECTIONS = {
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
    "trajectory": Trajectory,
}
_LAST_SECTIONS = {"quality": Quality}


class Sections(Mapping[str, type]):
    """Every section of a scene, table name -> the dataclass of its keys, in the order of the
    key reference and the dumps: the shared ones, the receivers' own (read from the registry at
    each use, so that a receiver registered later is there), the quality metrics'."""

    _own: object = None  # the registry's sections when _merged was made
    _merged: dict[str, type] = {}

    def _all(self) -> dict[str, type]:
        own = registry.sections()  # the same object until a receiver is (un)registered
        if own is not self._own:
            self._merged = {**_SHARED_SECTIONS, **own, **_LAST_SECTIONS}
            self._own = own
        return self._merged

    def __getitem__(self, name: str) -> type:
        return self._all()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


SECTIONS = Sections()
# the sections a receiver declares (the SceneKeys hold them apart from the shared ones)
RECEIVER_SECTIONS = registry.sections


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
