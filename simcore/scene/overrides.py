"""Scenes from nested dicts (as read from TOML), dotted-key overrides (``laser.pulse_width_s``),
quick names (``pitch_deg``) and the command line's ``--set NAME=VALUE``; every mismatch is a
SceneError naming the key (and the keys it may have meant)."""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from typing import Any

from ..errors import SceneError
from .keys import with_receiver_section
from .model import Scene
from .presets import PRESETS
from .sections import QUICK, RECEIVER_SECTIONS, SECTIONS


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
            fields = {
                f.name: f
                for f in dataclasses.fields(Scene)
                if f.name not in SECTIONS and f.name != "receiver_sections"
            }
            if dotted not in fields:
                raise _unknown(key)
            f = fields[dotted]
            if dotted == "name":
                top[dotted] = str(value)
            else:
                top[dotted] = _coerce(dotted, f, value)
    own = RECEIVER_SECTIONS()
    for section, changes in sections.items():
        keys = dataclasses.replace(getattr(scene, section), **changes)
        if section in own:  # a receiver's section
            held = top.get("receiver_sections", scene.receiver_sections)
            top["receiver_sections"] = with_receiver_section(held, section, keys)
        else:
            top[section] = keys
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
