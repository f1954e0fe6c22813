"""Shareable scenes: the controls as a link's query string, and a link's query string back to
controls, a child of the app's logic.

The query uses the names of ``lmapd simulate --set`` in SI units (``pitch_deg``, ``azimuth_deg``,
``distance_m``, ``pixels``, ``pulse_energy_j``, ``tnr``, ``seed``, ``preset`` or
``fidelity.subrays``, ``target.materials.PART``, ``sun.mode``, ``sun.azimuth_deg``,
``sun.elevation_deg``, ``receive.filter_width_m``, ``receiver.kind`` and the ``gm.*`` keys), so
a link and a command line read alike:

    http://127.0.0.1:8080/?token=...&pitch_deg=30&pixels=128&tnr=4

A link lists the settings that differ from the app's initial controls, each value written with at
most 12 significant digits (``1e-06``, not the ``1.0000000000000002e-06`` of a float product), and
read back to the same control value; opening one starts from the app's initial controls, so it
restores the frame exactly (same seed, same points): a setting the link leaves out keeps its
default, and a
tampered or invalid one (an unknown name, a value that is no number or out of range, an unknown
part or material) falls back to its default (or is clamped) with a message that names it. The
query is untrusted input: at most ``MAX_LINK_SETTINGS`` settings, names and values cut short in
messages, nothing but the controls ever set.
"""

from __future__ import annotations

import urllib.parse
from typing import Any

from app.state import SPECS, Controls, echo, receiver_controls, sanitize_controls

MAX_LINK_SETTINGS = 64  # a longer query is refused whole
MATERIAL_PREFIX = "target.materials."
_SCENE_NAMES = {
    "pulse_energy_mj": ("pulse_energy_j", 1e-3),
    "sun_azimuth_deg": ("sun.azimuth_deg", 1.0),
    "sun_elevation_deg": ("sun.elevation_deg", 1.0),
    "filter_width_nm": ("receive.filter_width_m", 1e-9),
}


def link_names() -> dict[str, tuple[str, float]]:
    """The link's name of each numeric control, and the factor from its display unit to the SI
    one: the receivers' own controls by their scene keys (their declarations', read at each use:
    a receiver registered before the app starts is in)."""
    own = {name: (c.key, c.scale) for name, c in receiver_controls().items()}
    return {key: (key, 1.0) for key in SPECS} | _SCENE_NAMES | own


LINK_NAMES = link_names()  # (those known when this module loads)
# link name -> control
CHOICES = {"preset": "preset", "sun.mode": "sun_mode", "receiver.kind": "receiver_kind"}
IGNORED = ("token",)  # the page's access token rides in the same query


def link_settings(controls: Controls, initial: Controls) -> dict[str, str]:
    """The query settings that reproduce ``controls`` from ``initial`` (those that differ), in
    SI units, each value as text."""
    settings = {}
    for key, (name, factor) in link_names().items():
        value = getattr(controls, key)
        if value != getattr(initial, key):
            settings[name] = _text(value * factor if factor != 1.0 else value)
    if controls.sun_mode != initial.sun_mode:
        settings["sun.mode"] = controls.sun_mode
    if controls.receiver_kind != initial.receiver_kind:
        settings["receiver.kind"] = controls.receiver_kind
    if controls.preset == "custom":
        if (initial.preset, initial.subrays) != ("custom", controls.subrays):
            settings["fidelity.subrays"] = str(controls.subrays)
    elif controls.preset != initial.preset:
        settings["preset"] = controls.preset
    for part, material in sorted(controls.materials.items()):
        if initial.materials.get(part) != material:
            settings[MATERIAL_PREFIX + part] = material
    return settings


def link_query(controls: Controls, initial: Controls) -> str:
    """``link_settings`` as a URL query string (without the leading ``?``)."""
    return urllib.parse.urlencode(link_settings(controls, initial), quote_via=urllib.parse.quote)


def controls_from_link(settings: Any, initial: Controls) -> tuple[Controls, list[str]]:
    """The controls a link's settings give, starting from ``initial``, and a message for each
    setting that was ignored, refused or changed. Never raises."""
    if not isinstance(settings, dict):
        return initial, [f"Link: expected name=value settings, got {echo(settings)}; ignored"]
    if len(settings) > MAX_LINK_SETTINGS:
        return initial, [f"Link: {len(settings)} settings is too many; ignored"]
    control_of = {name: (key, factor) for key, (name, factor) in link_names().items()}
    raw: dict[str, Any] = {}
    materials = dict(initial.materials)
    messages = []
    for name, value in settings.items():
        if not isinstance(name, str) or name in IGNORED:
            continue
        if name in control_of:
            key, factor = control_of[name]
            raw[key] = value if factor == 1.0 else _display(value, factor)
        elif name in CHOICES:
            raw[CHOICES[name]] = value
        elif name == "fidelity.subrays":
            raw["subrays"] = value
            raw.setdefault("preset", "custom")
        elif name.startswith(MATERIAL_PREFIX):
            materials[name[len(MATERIAL_PREFIX) :]] = value
        else:
            messages.append(f"Link: unknown setting {echo(name)}; ignored")
    raw["materials"] = materials
    controls, refused = sanitize_controls(raw, initial)
    messages += [f"Link: {m}" for m in refused]
    return controls, messages


LINK_DIGITS = 12  # significant digits of a link's values: above a float product's noise


def _display(value: Any, factor: float) -> Any:
    """A link's SI value in the control's display unit (anything that is no number is passed on
    for the sanitiser to refuse): divided by the factor and rounded to LINK_DIGITS significant
    digits, so that a value written by :func:`_text` (display x factor, 12 digits) comes back
    bit for bit (checked on every 3-digit slider value of a decade and 2,000 random ones)."""
    try:
        x = float(value) / factor
        return float(f"{x:.{LINK_DIGITS}g}") if x == x and abs(x) != float("inf") else x
    except (TypeError, ValueError, OverflowError):
        return value


def _text(value: Any) -> str:
    """A value as a link writes it: a float with at most LINK_DIGITS significant digits."""
    return f"{value:.{LINK_DIGITS}g}" if isinstance(value, float) else str(value)
