"""The app's UI state: one typed dataclass in display units, the control ranges, and the
sanitiser that turns whatever arrives from the page (or the websocket) into valid controls.

Display units differ from the scene's SI units in a few places: the pulse energy is shown in mJ
(``pulse_energy_mj``), the filter width in nm (``filter_width_nm``); every other name matches
the scene's quick parameters (``pitch_deg``, ``azimuth_deg``, ``distance_m``, ``pixels``, ``tnr``,
``seed``) or its keys with the section's dot as an underscore (``sun_azimuth_deg``). The
receivers' own controls come from their declarations (``simcore.receivers``: each control's
state name, scene key, unit and the factor between them, e.g. the Geiger-mode dead time in ns,
``gm_dead_time_ns``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import simcore
from simcore import receivers

COLOR_BY = ("range", "snr", "outlier", "range_error", "part")
IMAGE_KINDS = ("range", "peak_power", "background", "multi_peak")
SUN_MODES = ("none", "manual", "orbit")  # sun.mode: the paper's dark sky, given, from the orbit
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
_SHARED_SPECS: dict[str, ControlSpec] = {
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
}


def receiver_controls() -> dict[str, receivers.Control]:
    """Every registered receiver's own controls (its declaration's), by state name."""
    declared = receivers.receivers()  # the same tuple until a receiver is (un)registered
    if declared is not _controls_of[0]:
        _controls_of[:] = [declared, {c.name: c for r in declared for c in r.controls}]
    return _controls_of[1]


_controls_of: list = [None, {}]  # (the registry's receivers, their controls by state name)


def display_per_si(control: receivers.Control) -> float:
    """The factor from a receiver control's scene unit to its display unit (1e9: s to ns)."""
    return float(f"{1.0 / control.scale:.15g}")


def receiver_control_default(control: receivers.Control) -> float:
    """A receiver control's default: its key's, in display units."""
    section, name = control.key.split(".", 1)
    value = getattr(receivers.sections()[section](), name)
    return value if control.scale == 1.0 else value * display_per_si(control)


class Specs(Mapping[str, ControlSpec]):
    """The numeric controls, state name -> ControlSpec: the shared ones, then each registered
    receiver's (read from the registry at each use)."""

    def _all(self) -> dict[str, ControlSpec]:
        own = {
            c.name: ControlSpec(c.label, c.unit, c.lo, c.hi, c.step, c.integer, c.log_slider)
            for c in receiver_controls().values()
        }
        return {**_SHARED_SPECS, **own}

    def __getitem__(self, key: str) -> ControlSpec:
        return self._all()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


SPECS = Specs()


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
    receiver_kind: str = receivers.DEFAULT_KIND
    # the receivers' own controls (their declarations'), (state name, value) pairs set to other
    # than their defaults, in name order; read as attributes (``controls.gm_pulses``)
    receiver_values: tuple[tuple[str, float], ...] = ()

    def __getattr__(self, name: str) -> Any:
        """A receiver's control (``gm_pulses``): its value as set, else its default."""
        if name.startswith("__") or name == "receiver_values":
            raise AttributeError(name)
        control = receiver_controls().get(name)
        if control is None:
            raise AttributeError(f"'Controls' object has no attribute {name!r}")
        return dict(self.receiver_values).get(name, receiver_control_default(control))

    def replace(self, **changes: Any) -> Controls:
        """A copy with ``changes``, fields or receivers' controls (``gm_pulses=20``) alike."""
        own = {k: changes.pop(k) for k in list(changes) if k in receiver_controls()}
        if own:
            changes["receiver_values"] = _receiver_values({**dict(self.receiver_values), **own})
        return dataclasses.replace(self, **changes)

    def as_state(self) -> dict[str, Any]:
        """The trame state entries of these controls."""
        out = dataclasses.asdict(self)
        out["materials"] = dict(self.materials)
        del out["receiver_values"]
        out.update({name: getattr(self, name) for name in receiver_controls()})
        return out


def state_keys() -> tuple[str, ...]:
    """The state entries of the controls: the fields, then every registered receiver's controls
    (the app reads them when it starts: a receiver registers before)."""
    shared = tuple(f.name for f in dataclasses.fields(Controls) if f.name != "receiver_values")
    return (*shared, *receiver_controls())


STATE_KEYS = state_keys()


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
    }
    for name, control in receiver_controls().items():
        section, key = control.key.split(".", 1)
        value = getattr(getattr(scene, section), key)
        raw[name] = value if control.scale == 1.0 else value * display_per_si(control)
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
        ("receiver_kind", "Receiver", receivers.kinds()),
    )
    for key, label, options in choices:
        old = getattr(previous, key)
        values[key], msg = _choice(label, raw.get(key, old), options, old)
        messages += [msg] if msg else []
    materials = raw.get("materials", previous.materials)
    values["materials"], msgs = _materials(materials, previous.materials)
    messages += msgs
    own = receiver_controls()
    values["receiver_values"] = _receiver_values(
        {k: values.pop(k) for k in list(values) if k in own}
    )
    return Controls(**values), messages


def _receiver_values(chosen: dict[str, float]) -> tuple[tuple[str, float], ...]:
    """``Controls.receiver_values`` of the receivers' controls ``chosen``: those not at their
    defaults, in name order (so that equal controls compare equal)."""
    own = receiver_controls()
    return tuple(sorted((k, v) for k, v in chosen.items() if v != receiver_control_default(own[k])))
