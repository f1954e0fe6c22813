"""How a scene key is declared and read back: a dataclass field carrying its unit, valid range,
choices and one-line doc (``key``), the range as text, the per-key checks, and a section as plain
values (JSON and TOML)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import field
from typing import Any

from ..errors import SceneError


def key(
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


def range_text(meta) -> str:
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
        raise SceneError(f"{key}: NaN is not a valid value; valid range {range_text(meta)}")
    lo, hi = meta["lo"], meta["hi"]
    too_low = value <= lo if meta["lo_open"] else value < lo
    if meta.get("zero_or") and value == 0:
        return
    if (lo is not None and too_low) or (hi is not None and value > hi):
        raise SceneError(f"{key} = {value!r} is out of range; valid range {range_text(meta)}")
    if math.isinf(value) and not math.isinf(hi):
        raise SceneError(f"{key}: infinite value; valid range {range_text(meta)}")


def check_fields(obj, prefix: str, names=None) -> None:
    for f in dataclasses.fields(obj):
        meta = f.metadata
        if not meta or (names is not None and f.name not in names):
            continue
        key = f"{prefix}{f.name}"
        value = getattr(obj, f.name)
        values = value if isinstance(value, tuple) else (value,)
        if meta["choices"] is not None:
            choices = choices_of(meta)
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


def choices_of(meta) -> tuple:
    choices = meta["choices"]
    return tuple(choices()) if callable(choices) else choices


def to_plain(obj, inf_as_text: bool = True):
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            if f.name == "receiver_sections":  # a scene's receivers' own: each its own table
                scene: Any = obj  # a SceneKeys (this module does not import it)
                for name, section in scene.receiver_section_items():
                    out[name] = to_plain(section, inf_as_text)
                continue
            v = getattr(obj, f.name)
            out[f.name] = dict(v) if f.name == "materials" else to_plain(v, inf_as_text)
        return out
    if isinstance(obj, tuple):
        return [to_plain(v, inf_as_text) for v in obj]
    if inf_as_text and isinstance(obj, float) and math.isinf(obj):
        return "inf"  # strict JSON has no infinity
    return obj
