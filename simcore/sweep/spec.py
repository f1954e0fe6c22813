"""The sweep: a sweep file or its parts -> checked frames, each a resolved scene with its id."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..scene import (
    QUICK,
    SECTIONS,
    Scene,
    SceneError,
    dump_scene,
    load_scene,
    read_toml,
    with_overrides,
)
from ..target import TargetError, load_target, with_materials

CONNECT_TIMEOUT_S = 5.0  # [s] wait for an existing scheduler (and one of its workers)
MAX_FRAMES = 1_000_000  # [-] guard against a mistyped grid
TABLE_NAME = "sweep.parquet"
MANIFEST_NAME = "sweep.json"
FRAMES_DIR = "frames"
CLOUDS_DIR = "clouds"
SWEEP_KEYS = ("name", "base", "clouds", "set", "grid", "list")
CLOUD_FORMATS = ("ply", "las")
_ID_HEX = 16  # [-] hex digits of the frame id (64 bits of SHA-256)
_SIG_DIGITS = 12  # [-] significant digits kept of linspace / step grid values (0.1 * 3 -> 0.3)

# The metric columns of the table: name, Arrow type, meaning (units in the names).
METRICS = (
    ("n_pixels", "int64", "pixels of the array"),
    ("n_hit_pixels", "int64", "pixels whose line of sight hits the target"),
    ("n_lit_pixels", "int64", "pixels that receive an echo"),
    ("n_points", "int64", "points of the cloud (target points and outliers)"),
    ("n_target_points", "int64", "detected target points"),
    ("n_outliers", "int64", "false alarms (outliers) drawn"),
    ("n_dropped", "int64", "lit pixels that see the target and give no point"),
    ("n_unlit", "int64", "pixels that see the target but receive no echo (outside the lit spot)"),
    ("n_false_expected", "float64", "false points expected in the cloud (the stops they keep)"),
    ("n_false_crossings_expected", "float64", "noise crossings expected over the gate (Eq. 28)"),
    ("p_detect_mean", "float64", "mean detection probability of the lit pixels"),
    ("snr_p10", "float64", "10th percentile of the lit pixels' SNR"),
    ("snr_median", "float64", "median SNR of the lit pixels"),
    ("snr_p90", "float64", "90th percentile of the lit pixels' SNR"),
    ("range_sigma_m_median", "float64", "median range sigma of the detected pixels [m]"),
    ("range_sigma_m_p90", "float64", "90th percentile range sigma of the detected pixels [m]"),
    # the imaging quality against the true mesh (simcore.quality), at the frame's quality.tau_m
    ("quality.precision", "float64", "share of target points within tau of the true mesh"),
    ("quality.recall", "float64", "share of the seen surface within tau of a point"),
    ("quality.f_score", "float64", "harmonic mean of precision and recall"),
    ("quality.recall_projected", "float64", "recall weighted by projected area (|cos incidence|)"),
    ("quality.recall_cap", "float64", "recall of an ideal lidar with these pixels (its ceiling)"),
    ("quality.range_bias_m", "float64", "median signed range error of the target points [m]"),
    ("quality.range_rmse_m", "float64", "RMS range error along each point's line of sight [m]"),
    (
        "quality.range_rmse_surface_m",
        "float64",
        "RMS range error against each point's surface-group truth [m]",
    ),
    ("quality.range_error_p95_m", "float64", "95th percentile of |range error| [m]"),
    ("quality.distance_to_mesh_median_m", "float64", "median point-to-mesh distance [m]"),
    ("quality.distance_to_mesh_p95_m", "float64", "95th percentile point-to-mesh distance [m]"),
    (
        "quality.target_outlier_fraction",
        "float64",
        "share of target points farther than tau from their truth",
    ),
    ("quality.false_alarm_fraction", "float64", "share of all points that are false alarms"),
    ("quality.point_density_per_m2", "float64", "target points per m^2 of seen surface"),
)


class SweepError(SceneError):
    """A sweep file, frame, output folder or scheduler is unusable; the message names it.

    A SceneError, so that the ``lmapd`` command prints it as one line (exit status 2).
    """


@dataclass(frozen=True)
class Frame:
    """One frame of a sweep.

    Attributes
    ----------
    index : int
        Position in the sweep (grid frames first, then the list's).
    frame_id : str
        16 hex digits: SHA-256 of the resolved scene (its name left out); names its files.
    params : dict
        The frame's parameters as written: the [set] keys, then its grid or list keys.
    scene : Scene
        The resolved scene.
    scene_toml : str
        The scene as TOML (``dump_scene``): ``scene_from_dict(tomllib.loads(...))`` rebuilds it.
    """

    index: int
    frame_id: str
    params: dict[str, Any]
    scene: Scene
    scene_toml: str


@dataclass(frozen=True, eq=False)
class Sweep:
    """A checked sweep: every frame's scene is built and valid.

    Attributes
    ----------
    name : str
        Shown in the progress bar and stored in the table's metadata.
    base : Scene
        The scene every frame starts from.
    fixed : dict
        The [set] overrides.
    frames : tuple of Frame
    clouds : str or None
        "ply" or "las" to write each frame's point cloud, None for none.
    source : str
        The sweep file, or "<python>".
    """

    name: str
    base: Scene
    fixed: dict[str, Any]
    frames: tuple[Frame, ...]
    clouds: str | None
    source: str

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def keys(self) -> tuple[str, ...]:
        """The parameter columns: every key of any frame, in first-seen order."""
        return tuple(dict.fromkeys(k for f in self.frames for k in f.params))


def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep file (TOML, format in the module docstring and docs/api.md).

    Raises
    ------
    SweepError
        File missing or not TOML, unknown sweep key, empty grid, invalid frame (the message names
        the scene key, the frame and its parameters), a target that cannot be loaded.
    """
    path = Path(path)
    if not path.is_file():
        raise SweepError(f"sweep file not found: {path}")
    data = read_toml(path, SweepError)
    data.setdefault("name", path.stem)
    return sweep_from_dict(data, base_dir=path.parent, source=str(path))


def sweep_from_dict(
    data: Mapping[str, Any], base_dir: str | Path | None = None, source: str = "<python>"
) -> Sweep:
    """A Sweep from the tables of a sweep file (as read by tomllib); see :func:`build_sweep`.

    ``base_dir`` is the folder a relative ``base`` path is read from (the sweep file's).
    """
    unknown = [k for k in data if k not in SWEEP_KEYS]
    if unknown:
        raise SweepError(
            f"{source}: unknown sweep key {unknown[0]!r}; a sweep file has {', '.join(SWEEP_KEYS)}"
        )
    for key in ("set", "grid"):
        if key in data and not isinstance(data[key], Mapping):
            raise SweepError(f"{source}: [{key}] must be a table of scene keys")
    frames = data.get("list")
    if frames is not None and (
        not isinstance(frames, list) or not all(isinstance(f, Mapping) for f in frames)
    ):
        raise SweepError(f"{source}: [[list]] must be an array of tables, one per frame")
    return build_sweep(
        base=data.get("base", "paper"),
        fixed=data.get("set"),
        grid=data.get("grid"),
        frames=frames,
        clouds=data.get("clouds", False),
        name=str(data.get("name", "sweep")),
        base_dir=base_dir,
        source=source,
    )


def build_sweep(
    base: str | Path | Scene = "paper",
    fixed: Mapping[str, Any] | None = None,
    grid: Mapping[str, Any] | None = None,
    frames: Sequence[Mapping[str, Any]] | None = None,
    clouds: str | bool | None = None,
    name: str = "sweep",
    base_dir: str | Path | None = None,
    source: str = "<python>",
) -> Sweep:
    """Build and check a sweep: every frame's scene, and each distinct target once.

    Parameters
    ----------
    base : str, Path or Scene
        A built-in scene name, a scene TOML path (relative to ``base_dir`` if found there) or a
        Scene.
    fixed : mapping, optional
        Overrides for every frame (the file's [set]): quick names (``pixels``) or dotted keys
        (``fidelity.subrays``); a section table (``{"fidelity": {"subrays": 1}}``) reads the same.
    grid : mapping, optional
        key -> list of values, or ``{start, stop, num}`` (inclusive linspace) or
        ``{start, stop, step}`` (start, start + step, ... <= stop); the cartesian product.
    frames : sequence of mappings, optional
        Explicit frames (the file's [[list]]), after the grid's.
    clouds : "ply", "las", False or None
        Write each frame's point cloud in this format (None or False: no clouds).
    name, source : str
        The sweep's name; where it came from (for messages).

    Returns
    -------
    Sweep

    Raises
    ------
    SweepError
        No frames, an empty grid key, a key both fixed and varied, two identical frames, or an
        invalid frame scene or target (the message names the key and the frame).
    """
    where = source
    base_scene = _base_scene(base, base_dir, where)
    fixed = _flatten(fixed or {}, f"{where} [set]")
    varied = []
    if grid is not None:
        grid = _flatten(grid, f"{where} [grid]")
        if not grid:
            raise SweepError(
                f"{where}: [grid] is empty; give at least one key with a list of values"
            )
        varied += _expand_grid(grid, where)
    for i, frame in enumerate(frames or ()):
        varied.append(_flatten(frame, f"{where} [[list]] frame {i + 1}"))
    if not varied:
        raise SweepError(f"{where}: no frames; give a [grid] of values or [[list]] frames")
    if len(varied) > MAX_FRAMES:
        raise SweepError(f"{where}: {len(varied)} frames, more than {MAX_FRAMES}; split the sweep")
    built: list[Frame] = []
    seen: dict[str, int] = {}
    fixed_fields = {_field(k) for k in fixed}
    for index, params in enumerate(varied):
        both = [k for k in params if _field(k) in fixed_fields]
        if both:
            raise SweepError(
                f"{where}: {both[0]!r} is both in [set] and in frame {index}; give it in one place"
            )
        merged = {**fixed, **params}
        scene = _frame_scene(base_scene, merged, f"{where}: frame {index} ({_describe(params)})")
        fid = frame_id(scene)
        if fid in seen:
            raise SweepError(
                f"{where}: frames {seen[fid]} and {index} are the same scene "
                f"({_describe(params)}); vary a key (e.g. seed) or drop one"
            )
        seen[fid] = index
        built.append(Frame(index, fid, merged, scene, dump_scene(scene)))
    _check_targets(built, where)
    return Sweep(name, base_scene, fixed, tuple(built), _cloud_format(clouds, where), source)


def frame_id(scene: Scene) -> str:
    """The frame id: 16 hex digits of the SHA-256 of the scene's TOML, its name left out."""
    text = dump_scene(dataclasses.replace(scene, name=""))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:_ID_HEX]


def _base_scene(base, base_dir, where: str) -> Scene:
    if isinstance(base, Scene):
        return base
    if not isinstance(base, (str, Path)):
        raise SweepError(f"{where}: base must be a scene name or file, got {base!r}")
    local = Path(base_dir or ".") / Path(base).expanduser()
    try:
        return load_scene(local if local.is_file() else base)
    except SceneError as exc:
        raise SweepError(f"{where}: base = {str(base)!r}: {exc}") from None


def _flatten(table: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Scene overrides with section tables ({"fidelity": {"subrays": 1}}) as dotted keys."""
    if not isinstance(table, Mapping):
        raise SweepError(f"{where}: expected a table of scene keys, got {table!r}")
    flat: dict[str, Any] = {}
    for key, value in table.items():
        if key in SECTIONS and isinstance(value, Mapping):
            for sub, v in value.items():
                flat[f"{key}.{sub}"] = v
        else:
            flat[str(key)] = value
    return flat


def _field(key: str) -> str:
    """The dotted field a key names (pitch_deg -> pose.pitch_deg)."""
    return QUICK.get(key, key)


def _expand_grid(grid: dict[str, Any], where: str) -> list[dict[str, Any]]:
    values = {key: _grid_values(key, spec, f"{where} [grid]") for key, spec in grid.items()}
    return [dict(zip(values, combo, strict=True)) for combo in itertools.product(*values.values())]


def _grid_values(key: str, spec, where: str) -> list:
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: {key} = []: an empty list gives no frames")
        return spec
    if not isinstance(spec, Mapping):
        raise SweepError(
            f"{where}: {key} = {spec!r}: give a list of values or {{start, stop, num}} / "
            "{start, stop, step}; a single value belongs in [set]"
        )
    extra = set(spec) - {"start", "stop", "num", "step"}
    numbers = {k: v for k, v in spec.items() if k in ("start", "stop", "num", "step")}
    if extra or not {"start", "stop"} <= set(spec) or (("num" in spec) == ("step" in spec)):
        raise SweepError(
            f"{where}: {key}: a range is {{start, stop, num}} or {{start, stop, step}}"
        )
    if not all(_is_number(v) for v in numbers.values()):
        raise SweepError(f"{where}: {key}: start, stop, num and step must be numbers")
    start, stop = float(spec["start"]), float(spec["stop"])
    if "num" in spec:
        num = spec["num"]
        if not (isinstance(num, int) and num >= 1):
            raise SweepError(f"{where}: {key}: num = {num!r} must be a whole number >= 1")
        raw = np.linspace(start, stop, num) if num > 1 else np.array([start])
    else:
        step = float(spec["step"])
        count = (stop - start) / step if step != 0 else -1.0
        if not (math.isfinite(count) and count >= 0):
            raise SweepError(f"{where}: {key}: step = {step!r} never goes from start to stop")
        raw = start + step * np.arange(math.floor(count * (1 + 1e-12) + 1e-9) + 1)
    return [float(f"{v:.{_SIG_DIGITS}g}") for v in raw]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _describe(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in params.items()) or "no keys"


def _frame_scene(base: Scene, overrides: dict[str, Any], where: str) -> Scene:
    try:
        return with_overrides(base, overrides)
    except SceneError as exc:
        raise SweepError(f"{where}: {exc}") from None


def _check_targets(frames: Sequence[Frame], where: str) -> None:
    """Load each distinct target once (and apply each distinct material override)."""
    models: dict[tuple, Any] = {}
    checked: set[tuple] = set()
    for frame in frames:
        t = frame.scene.target
        key = (t.mesh, t.scale_m_per_unit, t.material_map)
        if (key, t.materials) in checked:
            continue
        context = f"{where}: frame {frame.index} ({_describe(frame.params)})"
        try:
            if key not in models:
                models[key] = load_target(t)
            with_materials(models[key], t.materials)
        except (TargetError, SceneError, ValueError) as exc:
            raise SweepError(f"{context}: {exc}") from None
        checked.add((key, t.materials))


def _cloud_format(clouds, where: str) -> str | None:
    if clouds is None or clouds is False:
        return None
    if isinstance(clouds, str) and clouds.lower().lstrip(".") in CLOUD_FORMATS:
        return clouds.lower().lstrip(".")
    raise SweepError(f"{where}: clouds = {clouds!r}; use {' or '.join(CLOUD_FORMATS)} or false")
