"""Reading a study file (``design.study``'s docstring shows one): the built-in studies, the file's
tables read and checked one by one (the base scene, presets, envelope, fly-around points,
variables, requirements, objectives), and the envelope's points tried on the base scene, before
any trial runs; each problem is one StudyError naming it."""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..scene import PRESETS, QUICK, SECTIONS, Scene, SceneError, load_scene, with_overrides
from ..tomlfile import read_toml_file
from .study import (
    DERIVED,
    ENVELOPE_LISTS,
    FRACTIONS,
    MAX_ENVELOPE,
    MAX_TRIALS,
    NON_NEGATIVE,
    REQUIREMENT,
    STUDIES_DIR,
    STUDY_KEYS,
    TRACK_PREFIX,
    Requirement,
    Study,
    StudyError,
    Track,
    Variable,
    cost_figure,
)

# the keys each frame of a trajectory sets (the pose, the orbit's time): no envelope condition
# nor variable of a study that tracks may set them, nor may a variable move the trajectory
FRAME_KEYS = (
    "pose.quaternion_wxyz",
    "pose.distance_m",
    "pose.pitch_deg",
    "pose.azimuth_deg",
    "pose.roll_deg",
    "orbit.time_s",
    "orbit.j2",
)


def _sets_frames(key: str) -> bool:
    dotted = QUICK.get(key, key)
    return dotted in FRAME_KEYS or dotted.startswith("trajectory.")


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
    requirements = tuple(
        _requirement(k, v, where) for k, v in _table(data, "requirements", where).items()
    )
    tracked = next((r.figure for r in requirements if r.figure.startswith(TRACK_PREFIX)), None)
    envelope, tracks = _envelope(
        _table(data, "envelope", where), where, with_overrides(base, fixed), tracked
    )
    variables = tuple(
        _variable(k, v, base, where) for k, v in _table(data, "variables", where).items()
    )
    if not variables:
        raise StudyError(f"{where}: [variables] is empty; give at least one key to choose")
    clash = sorted({v.key for v in variables} & {QUICK.get(k, k) for k in fixed})
    if clash:
        raise StudyError(f"{where}: {clash[0]!r} is both fixed in [set] and a variable")
    moving = [v.key for v in variables if _sets_frames(v.key)]
    if tracked and moving:
        raise StudyError(
            f"{where} [variables] {moving[0]}: a study that tracks takes its frames from the "
            "trajectory, the same for every design; fix it in [set] or vary it in [envelope]"
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
        tracks=tracks,
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


def _envelope(
    table: Mapping[str, Any], where: str, scene: Scene, tracked: str | None = None
) -> tuple[tuple[dict[str, Any], ...], tuple[Track, ...]]:
    """Every envelope point as scene overrides: the product of the lists (the fly-around's
    frames one of them), then the points; and no tracks. A study that tracks (``tracked``: its
    first ``track.*`` figure) takes them as conditions instead, each run along the trajectory
    (:func:`_track_points`)."""
    axes: list[list[dict[str, Any]]] = []
    flyaround = None
    for key, value in table.items():
        if key == "points":
            continue
        if key == "flyaround":
            if tracked:
                flyaround = _flyaround_spec(value, where)
            else:
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
    if tracked:
        return _track_points(points or [{}], flyaround, scene, where, tracked)
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
    return tuple(points), ()


def _track_points(
    conditions: list[dict[str, Any]],
    flyaround: tuple[list[float], bool] | None,
    scene: Scene,
    where: str,
    figure: str,
) -> tuple[tuple[dict[str, Any], ...], tuple[Track, ...]]:
    """The envelope of a study that tracks: each condition (a point of the product, or an
    explicit one) once per frame of its trajectory, the frames in time order, one Track each.
    The frames are the ``[envelope.flyaround]`` times if given, else those of the condition's
    ``[trajectory]`` (an approach or a hold: ``trajectory.frame_times``); an orbit with no
    times is no trajectory to track. Every frame counts against MAX_ENVELOPE, refused before
    any pose is computed."""
    from .. import orbit, trajectory  # noqa: PLC0415  (only for a study that tracks)
    from ..flyaround import pose_series  # noqa: PLC0415

    times: list[tuple[Scene, list[float], bool]] = []
    for c in conditions:
        clash = [k for k in c if _sets_frames(k) and not QUICK.get(k, k).startswith("trajectory.")]
        if clash:
            raise StudyError(
                f"{where} [envelope] {clash[0]}: in a study that tracks, the trajectory sets "
                "each frame's pose and time; give them by [trajectory] or [envelope.flyaround]"
            )
        try:
            condition_scene = with_overrides(scene, c)
        except SceneError as exc:
            raise StudyError(f"{where} [envelope] {c}: {exc}") from None
        if flyaround is not None:
            times.append((condition_scene, *flyaround))
        elif condition_scene.trajectory.kind != "orbit":
            frames = trajectory.frame_times(condition_scene)
            times.append((condition_scene, [float(t) for t in frames], False))
        else:
            raise StudyError(
                f"{where} [requirements] {figure}: a pose track needs a trajectory: give the "
                'base scene (or [set]) trajectory.kind = "approach" or "hold", or '
                "[envelope.flyaround] times along the orbits"
            )
    total = sum(len(t) for _, t, _ in times)
    if total > MAX_ENVELOPE:
        counts = sorted({len(t) for _, t, _ in times})
        span = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        raise StudyError(
            f"{where}: the envelope has {total} points ({span} trajectory frames x "
            f"{len(times)} conditions), more than {MAX_ENVELOPE}; each trial runs them all: "
            "take fewer frames (trajectory.duration_s, frame_rate_hz) or fewer conditions"
        )
    points: list[dict[str, Any]] = []
    tracks = []
    for c, (condition_scene, t_s, j2) in zip(conditions, times, strict=True):
        try:
            pose = pose_series(condition_scene, t_s, j2=j2)
        except (orbit.OrbitError, SceneError, ValueError) as exc:
            raise StudyError(f"{where} [envelope] {c}: the trajectory: {exc}") from None
        first = len(points)
        points += [{**c, **frame} for frame in _frame_overrides(pose, j2)]
        tracks.append(Track(points=tuple(range(first, len(points))), pose=pose, j2=j2))
    return tuple(points), tuple(tracks)


def _flyaround_spec(spec, where: str) -> tuple[list[float], bool]:
    """The times [s] and the J2 switch of ``[envelope.flyaround]``."""
    if not isinstance(spec, Mapping) or "times_s" not in spec or set(spec) - {"times_s", "j2"}:
        raise StudyError(
            f"{where} [envelope.flyaround]: give times_s = [...] (or {{start, stop, num}}) [s] "
            "and optionally j2 = true"
        )
    times = [float(t) for t in _values(spec["times_s"], "flyaround.times_s", where)]
    return times, bool(spec.get("j2", False))


def _frame_overrides(pose, j2: bool) -> list[dict[str, Any]]:
    """Each frame of ``pose`` (a RelativePose) as the scene keys ``lmapd flyaround`` sets."""
    return [
        {
            "pose.quaternion_wxyz": [float(v) for v in pose.quaternion_wxyz[i]],
            "pose.distance_m": float(pose.distance_m[i]),
            "orbit.time_s": float(pose.t_s[i]),
            "orbit.j2": j2,
        }
        for i in range(len(pose.t_s))
    ]


def _flyaround_points(spec, scene: Scene, where: str) -> list[dict[str, Any]]:
    """``[envelope.flyaround]`` (``times_s``: a list or {start, stop, num} [s] since the orbits'
    epoch; ``j2``): one point per time, the relative pose and range of the imaging satellite's
    lidar to the target along the orbits (the paper's Table 3 elements, or the scene's TLEs:
    ``orbit.target_tle``, ``orbit.imaging_tle``), as ``lmapd flyaround`` images them."""
    from .. import orbit  # noqa: PLC0415  (only for a fly-around envelope)
    from ..flyaround import pose_series  # noqa: PLC0415

    times, j2 = _flyaround_spec(spec, where)
    try:
        pose = pose_series(scene, times, j2=j2)
    except (orbit.OrbitError, SceneError, ValueError) as exc:
        raise StudyError(f"{where} [envelope.flyaround]: {exc}") from None
    return _frame_overrides(pose, j2)


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
