"""The receivers' registry: the one list of the valid ``receiver.kind`` values and each kind's
declaration.

Each receiver is a package that declares itself in one :class:`Receiver` object
(:mod:`simcore.plugins.declaration`): its parameter section, its two steps (the *receiver* and
the *detection* stage, :mod:`simcore.receivers`), the figures and point attributes it adds, and
what the app shows of it.

The kinds, in order: the built-in receivers, ``lm_apd`` (the default: the paper's linear-mode
APD chain, Eqs. 7-28, :mod:`simcore.receivers.lm_apd`) and ``gm_apd`` (a Geiger-mode
single-photon array, :mod:`simcore.receivers.gm_apd`); then those installed packages declare
under the entry-point group ``lmapd_sim.receivers`` (name = ``"package.module:RECEIVER"``);
then those a program registers with :func:`register`. Adding a receiver is one package and one
of these two registrations: nothing else changes (docs/receivers.md).

This module loads only the standard library and sits below the scene, which reads it for the
valid kinds and the receivers' sections; a receiver's package is named here, never imported,
and loads on first use (:func:`get`). :mod:`simcore.receivers` re-exports these names.
"""

from __future__ import annotations

import warnings
from types import MappingProxyType
from typing import Any

from .declaration import (
    Attribute,
    Control,
    Figure,
    Receiver,
    Section,
    Series,
    StatsRow,
    resolve,
)

__all__ = [
    "BUILT_IN",
    "DEFAULT_KIND",
    "ENTRY_POINTS",
    "Attribute",
    "Control",
    "Figure",
    "Receiver",
    "Section",
    "Series",
    "StatsRow",
    "get",
    "kinds",
    "receivers",
    "register",
    "resolve",
    "section_of",
    "sections",
    "unregister",
]

DEFAULT_KIND = "lm_apd"
# kind -> its declaration, "package.module:NAME" (loaded on first use)
BUILT_IN = {
    "lm_apd": "simcore.receivers.lm_apd:RECEIVER",
    "gm_apd": "simcore.receivers.gm_apd:RECEIVER",
}
ENTRY_POINTS = "lmapd_sim.receivers"  # the entry-point group of installed receivers

_REGISTERED: dict[str, Receiver] = {}  # by register()
_LOADED: dict[str, Receiver] = {}  # built-in and installed ones, once loaded
_installed: dict[str, str] | None = None  # kind -> "package.module:NAME" of the entry points
_known: dict[str, Any] = {}  # the declarations and sections, until a register() or unregister()
_broken: dict[str, str] = {}  # installed receivers that did not load: kind -> why


def _entry_points() -> dict[str, str]:
    """The receivers installed packages declare (read once per process)."""
    global _installed
    if _installed is None:
        from importlib import metadata  # noqa: PLC0415  (25-35 ms: only when a kind is asked for)

        found = metadata.entry_points(group=ENTRY_POINTS)
        _installed = {ep.name: ep.value for ep in found if ep.name not in BUILT_IN}
    return _installed


def register(receiver: Receiver) -> Receiver:
    """Make ``receiver`` selectable as ``receiver.kind = receiver.kind``; returns it."""
    if not isinstance(receiver, Receiver):
        raise TypeError(f"register() takes a simcore.receivers.Receiver, not {receiver!r}")
    known = _REGISTERED.get(receiver.kind) or _LOADED.get(receiver.kind)
    taken = receiver.kind in BUILT_IN or receiver.kind in _entry_points()
    if (known is not None or taken) and known is not receiver:
        raise ValueError(f"receiver kind {receiver.kind!r} is already registered")
    section = receiver.section
    if section is not None:
        for other in receivers():
            if other.kind != receiver.kind and other.section and other.section.name == section.name:
                raise ValueError(
                    f"receiver {receiver.kind!r}: the section [{section.name}] is {other.kind!r}'s"
                )
    _REGISTERED[receiver.kind] = receiver
    _known.clear()
    return receiver


def unregister(kind: str) -> None:
    """Forget a receiver :func:`register` made known (built-in and installed ones stay)."""
    _REGISTERED.pop(kind, None)
    _known.clear()


def kinds() -> tuple[str, ...]:
    """The valid values of ``receiver.kind``: the built-in receivers, the installed ones (by
    name), then the registered ones (in the order registered)."""
    installed = sorted(k for k in _entry_points() if k not in _broken)
    return (*BUILT_IN, *installed, *(k for k in _REGISTERED if k not in BUILT_IN))


def get(kind: str) -> Receiver:
    """The declaration of the receiver ``kind`` (loading a built-in or installed one on first
    use); ValueError naming the valid kinds for any other."""
    if kind in _REGISTERED:
        return _REGISTERED[kind]
    if kind not in _LOADED:
        where = BUILT_IN.get(kind) or _entry_points().get(kind)
        if where is None:
            raise ValueError(f"receiver.kind = {kind!r}: choose from {', '.join(kinds())}")
        declared = resolve(where)
        if not isinstance(declared, Receiver) or declared.kind != kind:
            raise TypeError(f"{where} is not the declaration of the receiver {kind!r}")
        _LOADED[kind] = declared
    return _LOADED[kind]


def receivers() -> tuple[Receiver, ...]:
    """Every receiver's declaration, in the order of :func:`kinds`. An installed receiver that
    does not load is left out with a warning (a broken package stops no other receiver)."""
    if "receivers" not in _known:
        loaded = []
        for kind in kinds():
            try:
                loaded.append(get(kind))
            except Exception as exc:
                if kind in BUILT_IN or kind in _REGISTERED:
                    raise
                _broken[kind] = f"{type(exc).__name__}: {exc}"
                where = _entry_points()[kind]
                warnings.warn(
                    f"the installed receiver {kind!r} ({where}) does not load and is left out: "
                    f"{_broken[kind]}",
                    stacklevel=2,
                )
        _known["receivers"] = tuple(loaded)
    return _known["receivers"]


def sections() -> MappingProxyType[str, type]:
    """The receivers' own scene sections, name -> the dataclass of its keys (read-only: the
    scene reads it at every use of a receiver's section)."""
    if "sections" not in _known:
        found = {r.section.name: r.section.keys for r in receivers() if r.section is not None}
        _known["sections"] = MappingProxyType(found)
    return _known["sections"]


def section_of(name: str) -> Receiver | None:
    """The receiver whose section is ``name`` (None: no receiver's)."""
    return next((r for r in receivers() if r.section and r.section.name == name), None)
