"""Shareable scenes: the controls as a link's query string, and a link's query string back to
controls, a child of the app's logic.

The query uses the names of ``lmapd simulate --set`` in SI units (``pitch_deg``, ``azimuth_deg``,
``distance_m``, ``pixels``, ``pulse_energy_j``, ``tnr``, ``seed``, ``preset`` or
``fidelity.subrays``, ``target.materials.PART``), so a link and a command line read alike:

    http://127.0.0.1:8080/?token=...&pitch_deg=30&pixels=128&tnr=4

A link lists every setting, so it restores the frame exactly (same seed, same points). Opening one
starts from the app's initial controls: a setting the link leaves out keeps its default, and a
tampered or invalid one (an unknown name, a value that is no number or out of range, an unknown
part or material) falls back to its default (or is clamped) with a message that names it. The
query is untrusted input: at most ``MAX_LINK_SETTINGS`` settings, names and values cut short in
messages, nothing but the controls ever set.
"""

from __future__ import annotations

import urllib.parse
from typing import Any

from app.state import SPECS, Controls, echo, sanitize_controls

MAX_LINK_SETTINGS = 64  # a longer query is refused whole
MATERIAL_PREFIX = "target.materials."
# the link's names of the numeric controls (their display names, but the energy in joules)
LINK_NAMES = {key: key for key in SPECS} | {"pulse_energy_mj": "pulse_energy_j"}
CONTROL_OF = {name: key for key, name in LINK_NAMES.items()}
IGNORED = ("token",)  # the page's access token rides in the same query


def link_settings(controls: Controls, initial: Controls) -> dict[str, str]:
    """The query settings that reproduce ``controls`` (materials only where they differ from
    ``initial``'s), in SI units, each value as text."""
    settings = {}
    for key, name in LINK_NAMES.items():
        value = getattr(controls, key)
        if key == "pulse_energy_mj":
            value = value * 1e-3
        settings[name] = _text(value)
    if controls.preset == "custom":
        settings["fidelity.subrays"] = str(controls.subrays)
    else:
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
    raw: dict[str, Any] = {}
    materials = dict(initial.materials)
    messages = []
    for name, value in settings.items():
        if not isinstance(name, str) or name in IGNORED:
            continue
        if name in CONTROL_OF:
            raw[CONTROL_OF[name]] = _energy_mj(value) if name == "pulse_energy_j" else value
        elif name == "preset":
            raw["preset"] = value
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


def _energy_mj(value: Any) -> Any:
    """A link's pulse energy [J] in the control's mJ (anything that is no number is passed on
    for the sanitiser to refuse). Divided, not multiplied by 1e3: the scene's energy, mJ x 1e-3,
    then comes back bit for bit (checked on 200,000 slider values; x 1e3 missed 12 %)."""
    try:
        return float(value) / 1e-3
    except (TypeError, ValueError, OverflowError):
        return value


def _text(value: Any) -> str:
    return repr(value) if isinstance(value, float) else str(value)
