"""Receivers: what turns the echo stage's per-pixel echoes into detections, ranges and outliers.

Each receiver is a package that declares itself in one :class:`Receiver` object: its parameter
section, its two steps, the figures and point attributes it adds, and what the app shows of it.
The steps:

- the *receiver* stage, ``respond(scene, echo, background)``: reads the echo stage's hand-off,
  :class:`simcore.echo.EchoStage`, and the background stage's
  :class:`simcore.background.Background`, and returns a :class:`Response` (per lit pixel: peak
  power at the input, the SNR the app shows, and the receiver's scalar noise figures);
- the *detection* stage, ``detect(scene, echo, response)``: returns a :class:`Detection` (per
  lit pixel: detection probability, the detected mask, noise-free and measured range, range
  sigma; the threshold and the false-alarm points).

The built-in receivers are ``lm_apd`` (the default: the paper's linear-mode APD chain,
Eqs. 7-28, :mod:`simcore.receivers.lm_apd`) and ``gm_apd`` (a Geiger-mode single-photon array,
:mod:`simcore.receivers.gm_apd`); installed packages add theirs under the entry-point group
``lmapd_sim.receivers``, programs with :func:`register` (docs/receivers.md).

The registry and the declaration types live below the scene, in :mod:`simcore.plugins` (the
scene reads them for the valid kinds and the receivers' sections); this package re-exports them
(``register``, ``get``, ``kinds``, ``Receiver``, ...). The records and the two stages load on
first use (:mod:`simcore.receivers.records`, :mod:`simcore.receivers.stages`).
"""

from __future__ import annotations

import importlib
from typing import Any

from ..plugins.declaration import (
    Attribute,
    Control,
    Figure,
    Receiver,
    Section,
    Series,
    StatsRow,
    resolve,
)
from ..plugins.registry import (
    BUILT_IN,
    DEFAULT_KIND,
    ENTRY_POINTS,
    get,
    kinds,
    receivers,
    register,
    section_of,
    sections,
    unregister,
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

# the records and stages, by their old names here (loaded on first use)
_LAZY = {
    "Response": "records",
    "Detection": "records",
    "Outliers": "records",
    "RECEIVER": "stages",
    "DETECTION": "stages",
    "gate_m": "stages",
    "outside_the_gate": "stages",
    "stage_receiver": "stages",
    "stage_detection": "stages",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
