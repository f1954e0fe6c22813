"""The study file: the conditions a design must meet (envelope), what may change (variables),
what it must achieve (requirements) and what it costs (objectives). Everything is checked when
the file is read, before any trial runs (``design.study_file``); each problem is one StudyError
naming it. This module holds what a study is (``Study``, its variables and requirements); the
file's reading and checks are ``study_file``'s.

    name = "mro-approach"
    base = "paper"                 # the scene every evaluation starts from (name or TOML path)
    seed = 1                       # the search's seed: the same file and seed, the same trials
    trials = 200                   # default of --trials
    preset = "interactive"         # the screening fidelity; confirm_preset the confirmation's
    confirm = 3                    # front designs confirmed at confirm_preset

    [set]                          # fixed keys of every evaluation
    "detector.pixels" = 128

    [envelope]                     # the cartesian product of these lists (one value: fixed)
    "pose.distance_m" = [300, 1000]            # or {start = 300, stop = 1000, num = 3}
    "pose.pitch_deg" = [0, 30]
    seed = [0, 1]
    sun = [{mode = "none"}, {mode = "manual", azimuth_deg = 30, elevation_deg = 10}]
    [[envelope.points]]            # and/or explicit points (any scene keys, e.g. orbit.time_s)

    [variables]                    # bounds (log = true across decades, int = true) or choices
    "laser.pulse_energy_j" = {low = 1e-4, high = 1e-2, log = true}
    "receiver.kind" = {choices = ["lm_apd", "gm_apd"]}

    [requirements]                 # figure = "OP BOUND [at worst | at pNN | at median]"
    "quality.recall" = ">= 0.8"
    "quality.range_rmse_m" = "<= 0.02 at p90"
    "track.translation_error_m" = "<= 0.1 at median"   # a pose track over the trajectory

A study that requires a ``track.*`` figure is evaluated along the base scene's trajectory (its
``[trajectory]``: an approach or a hold, or ``[envelope.flyaround]`` times along the orbits): the
envelope's points ARE the trajectory's frames, once per condition of the other envelope entries
(each condition one ``Track``), so that every requirement, the imaging ones too, aggregates over
the frames, and a track figure is a frame's like any other (``design.evaluate`` registers the
frames of each track in time order, as ``simcore.tracking.track`` does). A lost frame's errors are
infinite: it fails a requirement "at worst" and counts against a median or a percentile.

    [objectives]
    minimize = ["laser.pulse_energy_j", "receive.aperture_area_m2"]   # or ["cost"] with:
    cost = {"laser.pulse_energy_j" = 1000.0, "receive.aperture_area_m2" = 10.0}
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import receivers
from .._assets import ASSETS_DIR
from ..scene import (
    QUICK,
    Scene,
    SceneError,
    with_overrides,
)

STUDIES_DIR = ASSETS_DIR / "studies"
STUDY_KEYS = (
    "name",
    "base",
    "seed",
    "trials",
    "preset",
    "confirm_preset",
    "confirm",
    "polish_steps",
    "set",
    "envelope",
    "variables",
    "requirements",
    "objectives",
)
ENVELOPE_LISTS = ("sun",)  # envelope entries that are tables of a section's keys
MAX_ENVELOPE = 256  # envelope points at most (each trial runs them all; a track: each frame)
MAX_TRIALS = 100_000
# derived cost figures an objective may name, besides any numeric scene key
DERIVED = {
    "receive.aperture_area_m2": lambda s: math.pi * s.receive.aperture_diameter_m**2 / 4.0,
    "detector.pixel_count": lambda s: float(s.detector.pixels**2),
    "laser.pulse_energy_total_j": lambda s: s.laser.pulse_energy_j * _frame_pulses(s),
}
# what a figure can be at all: a requirement outside it can never be met
FRACTIONS = re.compile(
    r"(^|\.)(precision|recall|f_score|outlier_fraction|p_detect\w*|\w*_fraction)$"
)
NON_NEGATIVE = re.compile(
    r"(^|\.)(n_\w+|\w*_rmse_m|\w*_p95_m|\w*sigma\w*|\w*_per_m2|\w*area_m2|snr\w*)$"
    r"|^track\.\w+_error_(deg|m)$"
)
TRACK_PREFIX = "track."  # the figures of a pose track (design.evaluate.TRACK_FIGURES)
REQUIREMENT = re.compile(
    r"^\s*(>=|<=)\s*([-+0-9.eE]+|inf)\s*(?:at\s+(worst|median|mean|p\d{1,2}))?\s*$"
)


class StudyError(SceneError):
    """The study file, or a value in it, is unusable; the message names it. A SceneError, so that
    the ``lmapd`` command prints it as one line (exit status 2)."""


@dataclass(frozen=True)
class Variable:
    """A design variable: a scene key with bounds (``log``: sampled on a log scale; ``integer``)
    or a list of ``choices``."""

    key: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    integer: bool = False
    choices: tuple[Any, ...] = ()

    @property
    def continuous(self) -> bool:
        return not self.choices and not self.integer


@dataclass(frozen=True)
class Requirement:
    """``figure OP bound`` over the envelope, aggregated ``over`` its points: "worst" (the least
    favourable point), "median", "mean" or "pNN" (NN % of the points meet it)."""

    figure: str
    op: str  # ">=" or "<="
    bound: float
    over: str = "worst"

    def aggregate(self, values) -> float:
        """The envelope's value of the figure (NaN where a point has no value: it fails)."""
        v = np.asarray(values, dtype=np.float64)
        if not len(v) or np.isnan(v).any():
            return math.nan
        if self.over == "mean":
            return float(np.mean(v))
        if self.over == "median":
            return _percentile(v, 50.0)
        share = 100.0 if self.over == "worst" else float(self.over[1:])
        # NN % of the points must meet it: the (100 - NN)th percentile for >=, the NNth for <=
        q = 100.0 - share if self.op == ">=" else share
        return _percentile(v, q)

    def margin(self, value: float) -> float:
        """How far ``value`` meets the bound (negative: by how much it fails), in the figure's
        unit; NaN fails by infinity."""
        if math.isnan(value):
            return -math.inf
        return value - self.bound if self.op == ">=" else self.bound - value

    def violation(self, value: float) -> float:
        """Optuna's constraint value: <= 0 when met, relative to the bound's scale."""
        m = self.margin(value)
        return -m / max(abs(self.bound), 1e-12) if math.isfinite(m) else 1e12

    def text(self) -> str:
        at = "" if self.over == "worst" else f" at {self.over}"
        return f"{self.figure} {self.op} {self.bound:g}{at}"


def _percentile(v: np.ndarray, q: float) -> float:
    """numpy's (linear) percentile, where infinities (a lost frame's error) stay infinite: between
    two infinite order statistics it is that infinity, not numpy's NaN of inf - inf."""
    if np.isfinite(v).all():
        return float(np.percentile(v, q))
    s = np.sort(v)
    h = (len(s) - 1) * q / 100.0
    lo, hi = s[math.floor(h)], s[math.ceil(h)]
    frac = h - math.floor(h)
    if frac == 0.0 or lo == hi:
        return float(lo)
    if math.isinf(hi):  # the line up to an infinity is infinite past its start
        return float(hi)
    if math.isinf(lo):
        return float(lo)
    return float(lo + frac * (hi - lo))


@dataclass(frozen=True, eq=False)
class Track:
    """One pose track of a study: the envelope points that are its frames, in time order, and
    their relative pose (``flyaround.pose_series`` of the condition's scene at the frame times),
    imaged with ``j2`` or not."""

    points: tuple[int, ...]
    pose: Any  # orbit.RelativePose
    j2: bool = False


@dataclass(frozen=True)
class Study:
    """A parsed, checked study file (see the module docstring)."""

    name: str
    base: Scene
    seed: int
    trials: int
    preset: str
    confirm_preset: str
    confirm: int
    polish_steps: int
    fixed: dict[str, Any]
    envelope: tuple[dict[str, Any], ...]
    variables: tuple[Variable, ...]
    requirements: tuple[Requirement, ...]
    minimize: tuple[str, ...]
    cost: dict[str, float] = field(default_factory=dict)
    source: str = "<python>"
    text: str = ""
    tracks: tuple[Track, ...] = field(default=(), compare=False)  # a study that tracks (above)

    @property
    def fingerprint(self) -> str:
        """16 hex digits of the study's text: a resumed study must be the same study."""
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()[:16]

    def scene(self, params: Mapping[str, Any], point: int, preset: str | None = None) -> Scene:
        """The scene of a design (``params``) at envelope point ``point``."""
        overrides = {"preset": preset or self.preset, **self.fixed, **self.envelope[point]}
        return with_overrides(self.base, {**overrides, **params})

    def objective_values(self, scene: Scene) -> list[float]:
        """The objectives of a design (its scene at any envelope point: costs do not depend on
        the pose), in ``minimize`` order."""
        return [self._cost(name, scene) for name in self.minimize]

    def _cost(self, name: str, scene: Scene) -> float:
        if name == "cost":
            return float(sum(w * self._cost(k, scene) for k, w in self.cost.items()))
        return float(cost_figure(name, scene))

    @property
    def uses_quality(self) -> bool:
        return any(r.figure.startswith("quality.") for r in self.requirements)

    @property
    def uses_track(self) -> bool:
        """Whether a requirement is on a pose track's figure (``track.*``)."""
        return any(r.figure.startswith(TRACK_PREFIX) for r in self.requirements)


def _frame_pulses(scene: Scene) -> int:
    """The pulses one frame of the scene's receiver sums (its declaration's ``frame_pulses_key``;
    1 for a single-flash receiver)."""
    key = receivers.get(scene.receiver.kind).frame_pulses_key
    if key is None:
        return 1
    section, name = key.split(".", 1)
    return int(getattr(getattr(scene, section), name))


def cost_figure(name: str, scene: Scene) -> float:
    """A numeric scene key's value, or a DERIVED figure, of ``scene``."""
    if name in DERIVED:
        return DERIVED[name](scene)
    dotted = QUICK.get(name, name)
    section, _, key = dotted.partition(".")
    value = getattr(getattr(scene, section), key) if key else getattr(scene, section)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise StudyError(f"objective {name!r} is not a number ({value!r})")
    return float(value)
