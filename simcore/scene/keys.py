"""The scene's keys as one dataclass (``SceneKeys``: the sections together, with the quantities
several stages derive from them) and the key reference (``lmapd keys``, the README's table)."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import Any

from .fields import choices_of, key, range_text, to_plain
from .presets import PRESETS
from .sections import (
    PAPER_FORMS,
    RECEIVER_SECTIONS,
    SECTIONS,
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
    Sun,
    Target,
    Timing,
    Trajectory,
    TransmitOptics,
)


@dataclass(frozen=True)
class SceneKeys:
    """The scene's top-level keys, its sections and the quantities derived from them, not yet
    checked: ``Scene`` (``scene.model``) is this class validated on construction. The checks
    (``scene.validation``) read this class, so that they need not import the Scene they check."""

    name: str = "paper"
    preset: str = key(
        "",
        "-",
        doc="fidelity preset applied before the other keys: interactive, balanced, "
        "reference (empty: none)",
        choices=("", *PRESETS),
    )
    seed: int = key(0, "1", 0, 2**63 - 1, "seed of every random draw")
    conventions: str = key(
        "ours",
        "-",
        doc="ours (docs/physics.md#corrections, default) or paper (all the paper's literal forms)",
        choices=("ours", "paper"),
    )
    paper_forms: tuple[str, ...] = key(
        (),
        "-",
        doc=f"individual paper forms on top of 'ours': {', '.join(PAPER_FORMS)}",
        choices=PAPER_FORMS,
    )
    laser: Laser = field(default_factory=Laser)
    transmit: TransmitOptics = field(default_factory=TransmitOptics)
    receive: ReceiveOptics = field(default_factory=ReceiveOptics)
    detector: Detector = field(default_factory=Detector)
    amplifiers: Amplifiers = field(default_factory=Amplifiers)
    timing: Timing = field(default_factory=Timing)
    target: Target = field(default_factory=Target)
    pose: Pose = field(default_factory=Pose)
    fidelity: Fidelity = field(default_factory=Fidelity)
    receiver: ReceiverSelection = field(default_factory=ReceiverSelection)
    sun: Sun = field(default_factory=Sun)
    orbit: Orbit = field(default_factory=Orbit)
    background: Background = field(default_factory=Background)
    trajectory: Trajectory = field(default_factory=Trajectory)
    # the receivers' own sections (``[gm]``: ``simcore.plugins.registry``), those set to other
    # than their defaults as (name, keys) pairs in name order; read as attributes (``scene.gm``)
    receiver_sections: tuple[tuple[str, Any], ...] = ()
    quality: Quality = field(default_factory=Quality)

    def __getattr__(self, name: str) -> Any:
        """A receiver's section (``scene.gm``): its keys as set, else its defaults."""
        if name.startswith("__") or name == "receiver_sections":
            raise AttributeError(name)  # copying and unpickling probe before the fields exist
        cls = RECEIVER_SECTIONS().get(name)
        if cls is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        for held, keys in self.receiver_sections:
            if held == name:
                return keys
        return _defaults(cls)

    def receiver_section_items(self) -> list[tuple[str, Any]]:
        """Every receiver's section, (name, keys), in the order of the key reference."""
        return [(name, getattr(self, name)) for name in RECEIVER_SECTIONS()]

    def uses(self, form: str) -> bool:
        """True if the paper's literal form ``form`` (one of PAPER_FORMS) is in force."""
        return self.conventions == "paper" or form in self.paper_forms

    # -- derived quantities used by several stages ------------------------------------------------
    @property
    def illumination_angle_rad(self) -> float:
        """Full angle of the illuminated disc: divergence / expansion ratio (Eq. 5)."""
        return self.laser.divergence_rad / self.transmit.beam_expansion_ratio

    @property
    def ifov_rad(self) -> float:
        """Angular size of one pixel (Eq. 23)."""
        return self.receive.fov_rad / self.detector.pixels

    @property
    def focal_length_m(self) -> float:
        """Receiver focal length f_r = D_array / theta_fov (Eq. 22)."""
        return self.detector.pixels * self.detector.pixel_pitch_m / self.receive.fov_rad

    @property
    def gate_center_m(self) -> float:
        return self.timing.gate_center_m or self.pose.distance_m

    def to_dict(self) -> dict[str, Any]:
        """Every resolved parameter as a plain, JSON- and TOML-ready dict (the receiver section
        only for a receiver other than the default lm_apd: LM-APD scenes read as before the key
        existed)."""
        return to_plain(self)


@functools.lru_cache(maxsize=64)
def _defaults(cls: type) -> Any:
    """A receiver section's defaults (frozen: one instance serves every scene)."""
    return cls()


def with_receiver_section(receiver_sections: tuple, name: str, keys: Any) -> tuple:
    """``receiver_sections`` (a scene's) with the section ``name`` set to ``keys`` (left out
    where they are its defaults, so that equal scenes compare equal)."""
    rest = {n: v for n, v in receiver_sections if n != name}
    if keys != type(keys)():
        rest[name] = keys
    return tuple(sorted(rest.items()))


def key_reference() -> list[dict[str, str]]:
    """One row per scene key: key, unit, default, valid range, doc (for `lmapd keys`, README)."""
    rows = []
    for name in ("preset", "seed", "conventions", "paper_forms"):
        f = next(f for f in dataclasses.fields(SceneKeys) if f.name == name)
        rows.append(_row(name, f))
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            rows.append(_row(f"{section}.{f.name}", f))
    return rows


def _row(key, f):
    m = f.metadata
    if m["choices"] is not None:
        valid = " / ".join(choices_of(m))
    elif m["lo"] is not None:
        valid = range_text(m)
    else:
        valid = ""
    default = f.default
    return {
        "key": key,
        "unit": m["unit"],
        "default": repr(default) if isinstance(default, str) else str(default),
        "valid": valid,
        "doc": m["doc"],
    }
