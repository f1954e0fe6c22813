"""Scene description: frozen dataclasses, validation, TOML load and dump.

The package, by concern:

- ``sections``: one frozen dataclass per TOML table, each key with its unit, range and doc
  (``fields.key``); ``keys``: the sections together (``SceneKeys``) and the key reference;
- ``validation``: every key against its range and the rules between keys; ``model``: the
  ``Scene``, validated on construction;
- ``overrides``: scenes from dicts, dotted keys, quick names and ``--set``; ``files``: the
  built-in scenes, loading and dumping TOML; ``presets``: the fidelity presets.

UTC epochs and two-line element sets are parsed next to the orbits (``simcore.orbit.epoch``,
``simcore.orbit.tle``). ``from simcore.scene import X`` gives every public name as before.
"""

from __future__ import annotations

from .._assets import ASSETS_DIR
from ..errors import SceneError
from ..orbit.epoch import EPHEMERIS_FIRST_UTC, EPHEMERIS_LAST_UTC, parse_utc
from ..orbit.tle import DIGITS, SGP4_ERRORS, check_tle, tle_lines
from .files import MESH_SUFFIXES, SCENES_DIR, builtin_scenes, dump_scene, load_scene, read_toml
from .keys import SceneKeys, key_reference
from .model import Scene
from .overrides import parse_assignment, scene_from_dict, with_overrides
from .presets import PRESETS
from .sections import (
    DEFAULT_RECEIVER,
    EARTH_RADIUS_M,
    MAX_FILTER_WIDTH_M,
    MAX_STOPS,
    MAX_TRAJECTORY_FRAMES,
    PAPER_FORMS,
    QUICK,
    RECEIVER_SECTIONS,
    SECTIONS,
    TABLE3_ALTITUDE_M,
    Amplifiers,
    Background,
    Detector,
    Fidelity,
    Laser,
    Orbit,
    Pose,
    Quality,
    ReceiveOptics,
    ReceiverSelection,
    Sections,
    Sun,
    Target,
    Timing,
    Trajectory,
    TransmitOptics,
)
from .validation import (
    MAX_GATE_SAMPLES,
    MAX_SAMPLES_PER_PULSE,
    MIN_TIME_STEP_S,
    SOLAR_TABLE_M,
    SPEED_OF_LIGHT_M_S,
    auto_time_step_s,
    validate,
)

__all__ = [
    "ASSETS_DIR",
    "DEFAULT_RECEIVER",
    "DIGITS",
    "EARTH_RADIUS_M",
    "EPHEMERIS_FIRST_UTC",
    "EPHEMERIS_LAST_UTC",
    "MAX_FILTER_WIDTH_M",
    "MAX_GATE_SAMPLES",
    "MAX_SAMPLES_PER_PULSE",
    "MAX_STOPS",
    "MAX_TRAJECTORY_FRAMES",
    "MESH_SUFFIXES",
    "MIN_TIME_STEP_S",
    "PAPER_FORMS",
    "PRESETS",
    "QUICK",
    "RECEIVER_SECTIONS",
    "SCENES_DIR",
    "SECTIONS",
    "SGP4_ERRORS",
    "SOLAR_TABLE_M",
    "SPEED_OF_LIGHT_M_S",
    "TABLE3_ALTITUDE_M",
    "Amplifiers",
    "Background",
    "Detector",
    "Fidelity",
    "Laser",
    "Orbit",
    "Pose",
    "Quality",
    "ReceiveOptics",
    "ReceiverSelection",
    "Sections",
    "Scene",
    "SceneError",
    "SceneKeys",
    "Sun",
    "Target",
    "Timing",
    "Trajectory",
    "TransmitOptics",
    "auto_time_step_s",
    "builtin_scenes",
    "check_tle",
    "dump_scene",
    "key_reference",
    "load_scene",
    "parse_assignment",
    "parse_utc",
    "read_toml",
    "scene_from_dict",
    "tle_lines",
    "validate",
    "with_overrides",
]
