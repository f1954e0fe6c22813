"""The app's UI state: one typed dataclass in display units, the control ranges, and the
sanitiser that turns whatever arrives from the page (or the websocket) into valid controls.

Display units differ from the scene's SI units in three places: the pulse energy is shown in mJ
(``pulse_energy_mj``), the filter width and the Geiger-mode dead time in nm and ns
(``filter_width_nm``, ``gm_dead_time_ns``); every other name matches
the scene's quick parameters (``pitch_deg``, ``azimuth_deg``, ``distance_m``, ``pixels``, ``tnr``,
``seed``) or its keys with the section's dot as an underscore (``sun_azimuth_deg``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import simcore

COLOR_BY = ("range", "snr", "outlier", "range_error", "part")
IMAGE_KINDS = ("range", "peak_power", "background", "multi_peak")
SUN_MODES = ("none", "manual", "orbit")  # sun.mode: the paper's dark sky, given, from the orbit
RECEIVER_KINDS = ("lm_apd", "gm_apd")  # receiver.kind: linear-mode or Geiger-mode array
SUBRAY_CHOICES = (1, 4, 16, 64)
# fidelity presets of the core, plus "custom": the scene's fidelity with ``subrays`` sub-rays
PRESET_CHOICES = (*simcore.PRESETS, "custom")
DEFAULT_PRESET = "interactive"
MAX_SELECTED_PIXELS = 8
MAX_ECHO_CHARS = 40  # a refused value is quoted in its message at most this long
MAX_MATERIAL_ENTRIES = 256  # a materials mapping with more entries is refused whole


@dataclass(frozen=True)
class ControlSpec:
    """One numeric control: its visible label, unit, valid range and slider step."""

    label: str
    unit: str
    lo: float
    hi: float
    step: float
    integer: bool = False
    log_slider: bool = False

    def text(self, value: float) -> str:
        """The value with its unit, as the page shows it."""
        unit = f" {self.unit}" if self.unit else ""
        return f"{value:g}{unit}"


# The quick controls, in the order the page shows them.
SPECS: dict[str, ControlSpec] = {
    "pitch_deg": ControlSpec("Pitch", "deg", -90.0, 90.0, 1.0),
    "azimuth_deg": ControlSpec("Azimuth", "deg", -180.0, 180.0, 1.0),
    "distance_m": ControlSpec("Distance", "m", 20.0, 5000.0, 1.0, log_slider=True),
    "pixels": ControlSpec("Pixels", "per side", 16, 512, 16, integer=True),
    "pulse_energy_mj": ControlSpec("Pulse energy", "mJ", 0.01, 50.0, 0.01, log_slider=True),
    "tnr": ControlSpec("TNR", "", 1.0, 10.0, 0.1),
    "seed": ControlSpec("Seed", "", 0, 2**31 - 1, 1, integer=True),
    "sun_azimuth_deg": ControlSpec("Sun azimuth", "deg", -180.0, 180.0, 1.0),
    "sun_elevation_deg": ControlSpec("Sun elevation", "deg", -90.0, 90.0, 1.0),
    "filter_width_nm": ControlSpec("Filter width", "nm", 0.1, 100.0, 0.1, log_slider=True),
    "gm_pde": ControlSpec("Photon detection efficiency", "", 0.01, 1.0, 0.01),
    "gm_dark_count_rate_hz": ControlSpec("Dark count rate", "Hz", 1.0, 1e8, 1.0, log_slider=True),
    "gm_dead_time_ns": ControlSpec("Dead time", "ns", 1.0, 1e5, 1.0, log_slider=True),
    "gm_pulses": ControlSpec("Pulses per frame", "", 1, 1000, 1, integer=True),
    "gm_attenuation_db": ControlSpec("Transmit attenuation", "dB", 0.0, 100.0, 1.0),
}


@dataclass(frozen=True)
class Controls:
    """Everything the user can set, in display units. Valid by construction when built by
    :func:`sanitize_controls`."""

    pitch_deg: float = 0.0
    azimuth_deg: float = 0.0
    distance_m: float = 500.0
    pixels: int = 256
    pulse_energy_mj: float = 5.0
    tnr: float = 5.0
    seed: int = 0
    subrays: int = 4  # used by the "custom" preset only
    preset: str = DEFAULT_PRESET
    materials: dict[str, str] = field(default_factory=dict)  # part -> library material
    color_by: str = "range"
    image_kind: str = "range"
    sun_mode: str = "none"
    sun_azimuth_deg: float = 0.0
    sun_elevation_deg: float = 30.0
    filter_width_nm: float = 1.0
    receiver_kind: str = "lm_apd"
    gm_pde: float = 0.3
    gm_dark_count_rate_hz: float = 1e4
    gm_dead_time_ns: float = 1000.0
    gm_pulses: int = 100
    gm_attenuation_db: float = 50.0

    def as_state(self) -> dict[str, Any]:
        """The trame state entries of these controls."""
        out = dataclasses.asdict(self)
        out["materials"] = dict(self.materials)
        return out


STATE_KEYS = tuple(f.name for f in dataclasses.fields(Controls))


def controls_from_scene(
    scene: simcore.Scene, part_materials: dict[str, str]
) -> tuple[Controls, list[str]]:
    """The controls that reproduce ``scene``, and a message for each scene value outside the
    app's ranges (clamped: the app cannot show it).

    part_materials : the material of every target part with the scene's overrides applied
        (``app.logic.scene_map.resolved_materials``).
    """
    raw = {
        "pitch_deg": scene.pose.pitch_deg,
        "azimuth_deg": scene.pose.azimuth_deg,
        "distance_m": scene.pose.distance_m,
        "pixels": scene.detector.pixels,
        "pulse_energy_mj": scene.laser.pulse_energy_j * 1e3,
        "tnr": scene.timing.tnr,
        "seed": scene.seed,
        "subrays": scene.fidelity.subrays,
        "preset": preset_of(scene),
        "materials": dict(part_materials),
        "sun_mode": scene.sun.mode,
        "sun_azimuth_deg": scene.sun.azimuth_deg,
        "sun_elevation_deg": scene.sun.elevation_deg,
        "filter_width_nm": scene.receive.filter_width_m * 1e9,
        "receiver_kind": scene.receiver.kind,
        "gm_pde": scene.gm.pde,
        "gm_dark_count_rate_hz": scene.gm.dark_count_rate_hz,
        "gm_dead_time_ns": scene.gm.dead_time_s * 1e9,
        "gm_pulses": scene.gm.pulses,
        "gm_attenuation_db": scene.gm.attenuation_db,
    }
    return sanitize_controls(raw, Controls(materials=dict(part_materials)))


def echo(value: Any) -> str:
    """A short quote of a value from the page for a message (a huge string or list sent over the
    websocket must not come back as a huge message)."""
    if isinstance(value, str | int | float | bool | type(None)):
        text = repr(value[: MAX_ECHO_CHARS + 1] if isinstance(value, str) else value)
    else:
        text = f"a {type(value).__name__}"
        if isinstance(value, list | dict | tuple):
            text += f" of {len(value)} items"
    return text if len(text) <= MAX_ECHO_CHARS else text[: MAX_ECHO_CHARS - 1] + "…"


def preset_of(scene: simcore.Scene) -> str:
    """The app's fidelity choice for ``scene``: the preset whose knobs it has (its own preset
    first), the app's default for the core's default fidelity, else "custom"."""
    names = [scene.preset] if scene.preset in simcore.PRESETS else []
    for name in names + [n for n in simcore.PRESETS if n not in names]:
        knobs = simcore.PRESETS[name]
        if all(getattr(scene.fidelity, k.split(".", 1)[1]) == v for k, v in knobs.items()):
            return name
    if scene.fidelity == simcore.Scene().fidelity:
        return DEFAULT_PRESET
    return "custom"


def _number(value: Any, spec: ControlSpec, previous: float) -> tuple[float, str | None]:
    """A valid number for ``key``: clamped into range, or ``previous`` if ``value`` is no number."""
    try:
        if isinstance(value, bool) or value is None or value == "":
            raise ValueError
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        kept = spec.text(previous)
        return previous, f"{spec.label}: {echo(value)} is not a number; kept {kept}"
    if math.isnan(number):
        return previous, f"{spec.label}: not a number; kept {spec.text(previous)}"
    clamped = min(max(number, spec.lo), spec.hi)
    if spec.integer:
        clamped = int(round(clamped))
    message = None
    if number < spec.lo or number > spec.hi:
        message = (
            f"{spec.label} {number:g} is outside {spec.lo:g} to {spec.hi:g} {spec.unit}; "
            f"set to {spec.text(clamped)}"
        ).replace("  ", " ")
    return clamped, message


def _choice(label: str, value: Any, choices: tuple, previous: Any) -> tuple[Any, str | None]:
    if value in choices and not isinstance(value, bool):
        return value, None
    for choice in choices:  # "16" from a text field is 16
        if isinstance(value, str | int | float) and str(choice) == str(value).strip():
            return choice, None
    options = ", ".join(str(c) for c in choices)
    return previous, f"{label}: {echo(value)} is not one of {options}; kept {previous}"


def _materials(value: Any, previous: dict[str, str]) -> tuple[dict[str, str], list[str]]:
    if not isinstance(value, dict):
        return dict(previous), [f"Materials: expected part -> material, got {echo(value)}; kept"]
    if len(value) > MAX_MATERIAL_ENTRIES:
        return dict(previous), [f"Materials: {len(value)} entries is too many; kept"]
    out, messages = dict(previous), []
    for part, name in value.items():
        if previous and part not in previous:
            messages.append(f"Materials: the target has no part {echo(part)}; ignored")
        elif name not in simcore.MATERIAL_NAMES:
            messages.append(
                f"Materials: {echo(name)} is not in the material library; "
                f"{echo(part)} kept {previous.get(part, '?')}"
            )
        else:
            out[str(part)] = str(name)
    return out, messages


def sanitize_controls(raw: dict[str, Any], previous: Controls) -> tuple[Controls, list[str]]:
    """Valid controls from raw page/websocket values, and a message for each value changed.

    Numbers outside their range are clamped; values that are no number, not one of the choices
    or unknown materials are refused (the previous value is kept). Never raises.
    """
    values: dict[str, Any] = {}
    messages: list[str] = []
    for key, spec in SPECS.items():
        old = getattr(previous, key)
        values[key], msg = _number(raw.get(key, old), spec, old)
        messages += [msg] if msg else []
    choices = (
        ("subrays", "Sub-rays per pixel", SUBRAY_CHOICES),
        ("preset", "Fidelity preset", PRESET_CHOICES),
        ("color_by", "Colour points by", COLOR_BY),
        ("image_kind", "Array image", IMAGE_KINDS),
        ("sun_mode", "Sun", SUN_MODES),
        ("receiver_kind", "Receiver", RECEIVER_KINDS),
    )
    for key, label, options in choices:
        old = getattr(previous, key)
        values[key], msg = _choice(label, raw.get(key, old), options, old)
        messages += [msg] if msg else []
    materials = raw.get("materials", previous.materials)
    values["materials"], msgs = _materials(materials, previous.materials)
    messages += msgs
    return Controls(**values), messages
