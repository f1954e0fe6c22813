"""The study file: the conditions a design must meet (envelope), what may change (variables),
what it must achieve (requirements) and what it costs (objectives). Everything is checked when
the file is read, before any trial runs; each problem is one StudyError naming it.

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

    [objectives]
    minimize = ["laser.pulse_energy_j", "receive.aperture_area_m2"]   # or ["cost"] with:
    cost = {"laser.pulse_energy_j" = 1000.0, "receive.aperture_area_m2" = 10.0}
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._assets import ASSETS_DIR
from ..scene import (
    PRESETS,
    QUICK,
    SECTIONS,
    Scene,
    SceneError,
    load_scene,
    with_overrides,
)
from ..tomlfile import read_toml_file

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
MAX_ENVELOPE = 256  # envelope points at most (each trial runs them all)
MAX_TRIALS = 100_000
# derived cost figures an objective may name, besides any numeric scene key
DERIVED = {
    "receive.aperture_area_m2": lambda s: math.pi * s.receive.aperture_diameter_m**2 / 4.0,
    "detector.pixel_count": lambda s: float(s.detector.pixels**2),
    "laser.pulse_energy_total_j": lambda s: (
        s.laser.pulse_energy_j * (s.gm.pulses if s.receiver.kind == "gm_apd" else 1)
    ),
}
# what a figure can be at all: a requirement outside it can never be met
FRACTIONS = re.compile(
    r"(^|\.)(precision|recall|f_score|outlier_fraction|p_detect\w*|\w*_fraction)$"
)
NON_NEGATIVE = re.compile(
    r"(^|\.)(n_\w+|\w*_rmse_m|\w*_p95_m|\w*sigma\w*|\w*_per_m2|\w*area_m2|snr\w*)$"
)
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
            return float(np.median(v))
        share = 100.0 if self.over == "worst" else float(self.over[1:])
        # NN % of the points must meet it: the (100 - NN)th percentile for >=, the NNth for <=
        q = 100.0 - share if self.op == ">=" else share
        return float(np.percentile(v, q))

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


def builtin_studies() -> list[str]:
    """The names of the built-in studies (``assets/studies/NAME.toml``, shipped in the package)."""
    return sorted(p.stem for p in STUDIES_DIR.glob("*.toml"))


def load_study(path: str | Path) -> Study:
    """Read and check a study file, or a built-in study by name (``mro_approach``); relative
    paths in it are relative to the file."""
    path = Path(path)
    if not path.exists() and path.suffix == "" and str(path) in builtin_studies():
        path = STUDIES_DIR / f"{path}.toml"
    if not path.exists():
        raise StudyError(
            f"study file not found: {path} (built-in studies: {', '.join(builtin_studies())})"
        )
    data = read_toml_file(path, "study file", StudyError)
    return study_from_dict(data, source=str(path), base_dir=path.parent, text=path.read_text())


def study_from_dict(
    data: Mapping[str, Any],
    source: str = "<python>",
    base_dir: str | Path | None = None,
    text: str | None = None,
) -> Study:
    """Build and check a study from the tables of a study file (see the module docstring)."""
    where = source
    unknown = [k for k in data if k not in STUDY_KEYS]
    if unknown:
        raise StudyError(
            f"{where}: unknown study key {unknown[0]!r}; a study file has {', '.join(STUDY_KEYS)}"
        )
    base = _base(data.get("base", "paper"), base_dir, where)
    preset = _preset(data.get("preset", "interactive"), "preset", where)
    confirm_preset = _preset(data.get("confirm_preset", "reference"), "confirm_preset", where)
    fixed = dict(_table(data, "set", where))
    try:
        with_overrides(base, fixed)
    except SceneError as exc:
        raise StudyError(f"{where} [set]: {exc}") from None
    envelope = _envelope(_table(data, "envelope", where), where, with_overrides(base, fixed))
    variables = tuple(
        _variable(k, v, base, where) for k, v in _table(data, "variables", where).items()
    )
    if not variables:
        raise StudyError(f"{where}: [variables] is empty; give at least one key to choose")
    clash = sorted({v.key for v in variables} & {QUICK.get(k, k) for k in fixed})
    if clash:
        raise StudyError(f"{where}: {clash[0]!r} is both fixed in [set] and a variable")
    requirements = tuple(
        _requirement(k, v, where) for k, v in _table(data, "requirements", where).items()
    )
    minimize, cost = _objectives(_table(data, "objectives", where), base, where)
    study = Study(
        name=str(data.get("name", "study")),
        base=base,
        seed=_integer(data.get("seed", 0), "seed", 0, 2**63 - 1, where),
        trials=_integer(data.get("trials", 100), "trials", 1, MAX_TRIALS, where),
        preset=preset,
        confirm_preset=confirm_preset,
        confirm=_integer(data.get("confirm", 3), "confirm", 0, 100, where),
        polish_steps=_integer(data.get("polish_steps", 8), "polish_steps", 0, 40, where),
        fixed=fixed,
        envelope=envelope,
        variables=variables,
        requirements=requirements,
        minimize=minimize,
        cost=cost,
        source=source,
        text=text if text is not None else _as_toml(data),
    )
    _check_points(study, where)
    return study


def _as_toml(data: Mapping[str, Any]) -> str:
    """The study's tables as TOML (what ``study.toml`` in its folder holds), or their repr where
    they hold something TOML cannot (a Scene as the base)."""
    import tomli_w  # noqa: PLC0415

    try:
        return tomli_w.dumps(dict(data))
    except TypeError:
        return repr(sorted(data.items(), key=lambda kv: kv[0]))


def _table(data, key: str, where: str) -> Mapping[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise StudyError(f"{where}: [{key}] must be a table")
    return value


def _base(base, base_dir, where: str) -> Scene:
    if isinstance(base, Scene):
        return base
    if not isinstance(base, str) or not base:
        raise StudyError(f"{where}: base = {base!r}; give a built-in scene name or a TOML path")
    candidate = Path(base_dir or ".") / base
    try:
        return load_scene(candidate if candidate.suffix == ".toml" else base)
    except SceneError as exc:
        raise StudyError(f"{where}: base = {base!r}: {exc}") from None


def _preset(value, key: str, where: str) -> str:
    if value not in PRESETS:
        raise StudyError(f"{where}: {key} = {value!r}; choose from {', '.join(PRESETS)}")
    return value


def _integer(value, key: str, lo: int, hi: int, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise StudyError(f"{where}: {key} = {value!r}; give an integer in [{lo}, {hi:,}]")
    return value


def _values(value, key: str, where: str) -> list:
    """A list of envelope values: a list, one value, or {start, stop, num} (inclusive)."""
    if isinstance(value, Mapping):
        if set(value) != {"start", "stop", "num"}:
            raise StudyError(
                f"{where} [envelope] {key}: a range is {{start = ..., stop = ..., num = ...}}"
            )
        num = value["num"]
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise StudyError(f"{where} [envelope] {key}: num = {num!r}; give a positive integer")
        return [float(x) for x in np.linspace(value["start"], value["stop"], num)]
    values = value if isinstance(value, list) else [value]
    if not values:
        raise StudyError(f"{where} [envelope] {key} is an empty list; give at least one value")
    return values


def _envelope(table: Mapping[str, Any], where: str, scene: Scene) -> tuple[dict[str, Any], ...]:
    """Every envelope point as scene overrides: the product of the lists (the fly-around's
    frames one of them), then the points."""
    axes: list[list[dict[str, Any]]] = []
    for key, value in table.items():
        if key == "points":
            continue
        if key == "flyaround":
            axes.append(_flyaround_points(value, scene, where))
            continue
        if key in ENVELOPE_LISTS:
            entries = _values(value, key, where)
            if not all(isinstance(e, Mapping) for e in entries):
                raise StudyError(f"{where} [envelope] {key}: give a list of tables of {key}.* keys")
            axes.append([{f"{key}.{k}": v for k, v in e.items()} for e in entries])
        else:
            axes.append([{key: v} for v in _values(value, key, where)])
    points = (
        [
            dict(itertools.chain.from_iterable(d.items() for d in combo))
            for combo in itertools.product(*axes)
        ]
        if axes
        else []
    )
    explicit = table.get("points", [])
    if not isinstance(explicit, list) or not all(isinstance(p, Mapping) for p in explicit):
        raise StudyError(f"{where}: [[envelope.points]] must be an array of tables")
    points += [dict(p) for p in explicit]
    if not points:
        raise StudyError(
            f"{where}: the [envelope] is empty; give at least one condition (e.g. "
            '"pose.distance_m" = [500]) or [[envelope.points]]'
        )
    if len(points) > MAX_ENVELOPE:
        raise StudyError(
            f"{where}: the envelope has {len(points)} points, more than {MAX_ENVELOPE}; "
            "each trial runs them all: take fewer values"
        )
    return tuple(points)


def _flyaround_points(spec, scene: Scene, where: str) -> list[dict[str, Any]]:
    """``[envelope.flyaround]`` (``times_s``: a list or {start, stop, num} [s] since the orbits'
    epoch; ``j2``): one point per time, the relative pose and range of the imaging satellite's
    lidar to the target along the orbits (the paper's Table 3 elements, or the scene's TLEs:
    ``orbit.target_tle``, ``orbit.imaging_tle``), as ``lmapd flyaround`` images them."""
    from .. import orbit  # noqa: PLC0415  (only for a fly-around envelope)
    from ..flyaround import pose_series  # noqa: PLC0415

    if not isinstance(spec, Mapping) or "times_s" not in spec or set(spec) - {"times_s", "j2"}:
        raise StudyError(
            f"{where} [envelope.flyaround]: give times_s = [...] (or {{start, stop, num}}) [s] "
            "and optionally j2 = true"
        )
    times = [float(t) for t in _values(spec["times_s"], "flyaround.times_s", where)]
    j2 = bool(spec.get("j2", False))
    try:
        pose = pose_series(scene, times, j2=j2)
    except (orbit.OrbitError, SceneError, ValueError) as exc:
        raise StudyError(f"{where} [envelope.flyaround]: {exc}") from None
    return [
        {
            "pose.quaternion_wxyz": [float(v) for v in pose.quaternion_wxyz[i]],
            "pose.distance_m": float(pose.distance_m[i]),
            "orbit.time_s": float(pose.t_s[i]),
            "orbit.j2": j2,
        }
        for i in range(len(pose.t_s))
    ]


def field_metadata(key: str) -> dict[str, Any]:
    """The metadata (unit, lo, hi, lo_open, choices) of a dotted scene key or quick name."""
    dotted = QUICK.get(key, key)
    section, _, name = dotted.partition(".")
    cls = SECTIONS.get(section) if name else Scene
    name = name or section
    fields = {f.name: f for f in dataclasses.fields(cls)} if cls else {}
    if name not in fields or (cls is Scene and name in SECTIONS):
        raise StudyError(f"[variables] {key!r} is not a scene key (`lmapd keys` lists them)")
    return dict(fields[name].metadata)


def _variable(key: str, spec, base: Scene, where: str) -> Variable:
    key = QUICK.get(key, key)
    meta = field_metadata(key)
    if not isinstance(spec, Mapping):
        raise StudyError(
            f"{where} [variables] {key}: give {{low = ..., high = ...}} or {{choices = [...]}}"
        )
    extra = set(spec) - {"low", "high", "log", "int", "choices"}
    if extra:
        raise StudyError(f"{where} [variables] {key}: unknown option {sorted(extra)[0]!r}")
    if "choices" in spec:
        choices = spec["choices"]
        if not isinstance(choices, list) or not choices:
            raise StudyError(f"{where} [variables] {key}: choices must be a non-empty list")
        for c in choices:
            _try(base, key, c, where)
        return Variable(key=key, choices=tuple(choices))
    if "low" not in spec or "high" not in spec:
        raise StudyError(f"{where} [variables] {key}: give both low and high (or choices)")
    low, high = spec["low"], spec["high"]
    for v in (low, high):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise StudyError(f"{where} [variables] {key}: bounds must be finite numbers")
    if not low < high:
        raise StudyError(f"{where} [variables] {key}: low = {low!r} must be below high = {high!r}")
    log = bool(spec.get("log", False))
    if log and low <= 0:
        raise StudyError(f"{where} [variables] {key}: a log scale needs low > 0")
    lo, hi = meta.get("lo"), meta.get("hi")
    outside = (lo is not None and (low < lo or (meta.get("lo_open") and low <= lo))) or (
        hi is not None and high > hi
    )
    if outside:
        left = "(" if meta.get("lo_open") else "["
        raise StudyError(
            f"{where} [variables] {key}: bounds [{low:g}, {high:g}] leave the key's range "
            f"{left}{lo:g}, {hi:g}] {meta.get('unit', '')}".rstrip()
        )
    integer = bool(spec.get("int", isinstance(base_value(base, key), int)))
    for v in (low, high):
        _try(base, key, int(v) if integer else float(v), where)
    return Variable(key=key, low=float(low), high=float(high), log=log, integer=integer)


def base_value(scene: Scene, key: str):
    section, _, name = key.partition(".")
    return getattr(getattr(scene, section), name) if name else getattr(scene, section)


def _try(base: Scene, key: str, value, where: str) -> None:
    try:
        with_overrides(base, {key: value})
    except SceneError as exc:
        raise StudyError(f"{where} [variables] {exc}") from None


def _requirement(figure: str, spec, where: str) -> Requirement:
    match = REQUIREMENT.match(spec) if isinstance(spec, str) else None
    if match is None:
        raise StudyError(
            f'{where} [requirements] {figure} = {spec!r}; write ">= 0.8", "<= 0.02 at p90" '
            "(at worst, median, mean or pNN)"
        )
    op, bound_text, over = match.groups()
    bound = float(bound_text)
    req = Requirement(figure=figure, op=op, bound=bound, over=over or "worst")
    if FRACTIONS.search(figure):
        lo, hi = 0.0, 1.0
    elif NON_NEGATIVE.search(figure):
        lo, hi = 0.0, math.inf
    else:
        lo, hi = -math.inf, math.inf
    if (op == ">=" and bound > hi) or (op == "<=" and bound < lo):
        raise StudyError(
            f"{where} [requirements] {req.text()}: {figure} lies in [{lo:g}, {hi:g}], "
            "so no design can meet it"
        )
    return req


def _objectives(table, base: Scene, where: str) -> tuple[tuple[str, ...], dict[str, float]]:
    extra = set(table) - {"minimize", "cost"}
    if extra:
        raise StudyError(f"{where} [objectives]: unknown key {sorted(extra)[0]!r}")
    minimize = table.get("minimize", [])
    if isinstance(minimize, str):
        minimize = [minimize]
    if not isinstance(minimize, list) or not minimize:
        raise StudyError(f"{where} [objectives]: give minimize = [...] (one or several names)")
    cost = table.get("cost", {})
    if not isinstance(cost, Mapping):
        raise StudyError(f"{where} [objectives] cost must be a table of name = weight")
    if "cost" in minimize and not cost:
        raise StudyError(f"{where} [objectives]: minimize names cost but no cost table is given")
    for name in [*(m for m in minimize if m != "cost"), *cost]:
        try:
            cost_figure(name, base)
        except (StudyError, AttributeError):
            raise StudyError(
                f"{where} [objectives]: {name!r} is neither a numeric scene key nor one of "
                f"{', '.join(DERIVED)}"
            ) from None
    weights = {k: float(w) for k, w in cost.items()}
    return tuple(minimize), weights


def _check_points(study: Study, where: str) -> None:
    """Every envelope point is a valid scene with the variables at their defaults."""
    for i in range(len(study.envelope)):
        try:
            study.scene({}, i)
        except SceneError as exc:
            raise StudyError(f"{where} [envelope] point {i} ({study.envelope[i]}): {exc}") from None
