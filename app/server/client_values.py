"""The values a page may write into the shared state: each key's screen takes the client's value
and returns the value to store, or raises ValueError (the value is dropped; ``app.server.sync``
applies them, ``app.main.client_keys`` says which screen each key has)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from app.state import MAX_MATERIAL_ENTRIES, echo

MAX_SCALAR_CHARS = 256  # a string value of a control

Screen = Callable[[Any], Any]  # a client value -> the value to store; ValueError: drop it


def scalar(value: Any) -> Any:
    """A number, a short string, a boolean or None (the controls' validators do the rest)."""
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, str) and len(value) <= MAX_SCALAR_CHARS:
        return value
    raise ValueError(f"not a scalar: {echo(value)}")


def boolean(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    raise ValueError(f"not a boolean: {echo(value)}")


def cleared(value: Any) -> str:
    """A message the page may only clear (closing its alert)."""
    if value in ("", None):
        return ""
    raise ValueError(f"a message may only be cleared, not set to {echo(value)}")


def mapping_of_names(value: Any) -> dict[str, str]:
    """A part -> material mapping of short strings."""
    if not isinstance(value, dict) or len(value) > MAX_MATERIAL_ENTRIES:
        raise ValueError(f"not a short mapping: {echo(value)}")
    for k, v in value.items():
        if not (isinstance(k, str) and isinstance(v, str)) or max(len(k), len(v)) > 256:
            raise ValueError("a mapping entry that is no short string")
    return value


def file_upload(value: Any) -> Any:
    """What trame's file input sends: a dict (or a list of at most one), or nothing."""
    if value is None or isinstance(value, dict):
        return value
    if isinstance(value, list) and len(value) <= 1 and all(isinstance(v, dict) for v in value):
        return value
    raise ValueError(f"not a file upload: {echo(value)}")
