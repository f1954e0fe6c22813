"""Sweeps: many frames over a grid or a list of scene keys, each frame a task on Dask distributed.

    lmapd sweep SWEEP.toml --out DIR [--scheduler ADDRESS] [--workers N] [--clouds ply|las|none]

A sweep file (TOML) names a base scene and the frames::

    name = "example"        # optional; default: the file's name without .toml
    base = "paper"          # a built-in scene or a scene TOML path relative to the sweep file
    clouds = "ply"          # optional: also write each frame's point cloud ("ply", "las", false)

    [set]                   # overrides applied to every frame: quick names or dotted keys
    pixels = 64
    fidelity.subrays = 1    # a dotted key (TOML reads it as a table; same meaning)

    [grid]                  # the cartesian product, in the order written (the last varies fastest)
    pitch_deg = [0, 30, 60]
    distance_m = { start = 300.0, stop = 600.0, num = 2 }   # inclusive linspace; or step = ...

    [[list]]                # explicit frames, after the grid's (each one table of overrides)
    pitch_deg = 90
    tnr = 4.0

Every frame's scene is built and checked (``with_overrides``, then the target and its materials
are loaded once per distinct target) before any work: an unknown key, a value out of range, an
empty grid or an unreachable scheduler raise :class:`SweepError` naming the key, frame or address,
and nothing is written.

Output folder::

    DIR/sweep.json             the frames: index, frame id, parameters (rewritten on each run)
    DIR/frames/<id>.json       one row per finished frame; its presence marks the frame done
    DIR/clouds/<id>.ply|.las   the frame's point cloud, if asked (written before its row)
    DIR/sweep.parquet          the table, one row per frame, assembled from the rows at the end

The frame id is a hash of the frame's fully resolved scene, so a rerun skips finished frames
(resume after a crash or Ctrl-C) and never reuses a row whose base scene or [set] changed. A
frame that fails is recorded (``status = "error"`` and its ``error`` message) and the sweep goes
on; the next run retries it. All files are written atomically by the client process; workers
only compute, so a remote cluster needs no shared file system, only lmapd-sim installed (and any
custom mesh file at the same path).

Each Dask worker keeps one Pipeline per thread, so the mesh and its BVH load once per worker,
not once per frame. Frames are pure functions of their scenes (seeded), so the table does not
depend on the number of workers; only ``frame_s`` (wall time) varies.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import json
import logging
import math
import os
import sys
import threading
import time
import uuid
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from . import io
from .materials import MATERIAL_NAMES
from .parallel import set_threads
from .pipeline import Pipeline, Result
from .pointcloud import PointCloud
from .scene import (
    QUICK,
    SECTIONS,
    Scene,
    SceneError,
    dump_scene,
    load_scene,
    read_toml,
    with_overrides,
)
from .target import TargetError, load_target, with_materials

__all__ = [
    "CONNECT_TIMEOUT_S",
    "METRICS",
    "TABLE_NAME",
    "Frame",
    "Sweep",
    "SweepError",
    "SweepReport",
    "add_parser",
    "build_sweep",
    "frame_metrics",
    "load_sweep",
    "read_table",
    "run_cli",
    "run_sweep",
    "sweep_from_dict",
    "warm_workers",
]

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
    ("n_dropped", "int64", "hit pixels without a target point"),
    ("n_false_expected", "float64", "expected false alarms over the array"),
    ("p_detect_mean", "float64", "mean detection probability of the lit pixels"),
    ("snr_p10", "float64", "10th percentile of the lit pixels' SNR"),
    ("snr_median", "float64", "median SNR of the lit pixels"),
    ("snr_p90", "float64", "90th percentile of the lit pixels' SNR"),
    ("range_sigma_m_median", "float64", "median range sigma of the detected pixels [m]"),
    ("range_sigma_m_p90", "float64", "90th percentile range sigma of the detected pixels [m]"),
)


class SweepError(SceneError):
    """A sweep file, frame, output folder or scheduler is unusable; the message names it.

    A SceneError, so that the ``lmapd`` command prints it as one line (exit status 2).
    """


# ----------------------------------------------------------------------------------------------
# the sweep: frames and their scenes
# ----------------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------------
# one frame (runs on a worker)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FrameOutcome:
    """What a worker sends back: metrics or an error, the wall time, the cloud if asked."""

    metrics: dict[str, Any] | None
    error: str | None
    frame_s: float
    cloud: PointCloud | None = None
    target_line: str = ""


def frame_metrics(result: Result) -> dict[str, Any]:
    """The table's metric columns (METRICS) of one frame; None where a statistic has no sample.

    SNR quantiles are over the lit pixels (``result.receiver.snr``), range sigma quantiles over
    the detected target pixels (``result.detection.range_sigma_m``) [m].
    """
    s = result.summary()
    snr = _finite(result.receiver.snr)
    sigma = _finite(result.detection.range_sigma_m[result.detection.detected])
    return {
        **{k: int(s[k]) for k, t, _ in METRICS if t == "int64"},
        "n_false_expected": float(s["n_false_expected"]),
        "p_detect_mean": s["p_detect_mean"],
        "snr_p10": _quantile(snr, 0.10),
        "snr_median": _quantile(snr, 0.50),
        "snr_p90": _quantile(snr, 0.90),
        "range_sigma_m_median": _quantile(sigma, 0.50),
        "range_sigma_m_p90": _quantile(sigma, 0.90),
    }


def _finite(values) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    return v[np.isfinite(v)]


def _quantile(values: np.ndarray, q: float) -> float | None:
    return float(np.quantile(values, q)) if len(values) else None


def run_frame(scene: Scene, pipeline: Pipeline, want_cloud: bool = False) -> FrameOutcome:
    """Simulate one frame; never raises (an error becomes the outcome's ``error`` text)."""
    start = time.perf_counter()
    try:
        result = pipeline.run(scene)
        metrics = frame_metrics(result)
        cloud = result.cloud if want_cloud else None
        line = f"target {result.target.name}; {result.target.credit}"
        return FrameOutcome(metrics, None, time.perf_counter() - start, cloud, line)
    except Exception as exc:  # noqa: BLE001  (a failed frame is recorded; the sweep goes on)
        pipeline.clear()  # a half-updated cache is not trusted
        return FrameOutcome(None, _error_text(exc), time.perf_counter() - start)


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


_LOCAL = threading.local()  # per worker thread: its Pipeline (the mesh and BVH load once)


def _worker_pipeline() -> Pipeline:
    pipe = getattr(_LOCAL, "pipeline", None)
    if pipe is None:
        _one_core_per_frame()
        pipe = _LOCAL.pipeline = Pipeline()
    return pipe


def _one_core_per_frame() -> None:
    """On a Dask worker the frames run side by side, one per core: turn off the core's own
    two-thread split of the ray cast and the echo features, which would oversubscribe the cores
    (measured on 2 cores: 2 workers x 2 threads take 1.6 x as long per frame as 2 x 1).
    Results do not depend on it."""
    set_threads(1)


def _frame_task(scene: Scene, want_cloud: bool) -> FrameOutcome:
    """The Dask task: one frame through this worker thread's Pipeline."""
    return run_frame(scene, _worker_pipeline(), want_cloud)


def warm_workers(client, scene: Scene) -> float:
    """Run ``scene`` once on every worker of ``client`` (loads the mesh and BVH there).

    For benchmarks that time the sweep alone. Returns the wall time [s].
    """
    start = time.perf_counter()
    futures = [
        client.submit(_frame_task, scene, False, workers=[w], pure=False, allow_other_workers=False)
        for w in client.scheduler_info()["workers"]
    ]
    client.gather(futures)
    return time.perf_counter() - start


# ----------------------------------------------------------------------------------------------
# running a sweep
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SweepReport:
    """The outcome of :func:`run_sweep`.

    Attributes
    ----------
    out_dir, table_path : Path
    n_frames, n_skipped, n_run, n_failed : int
        Frames in the sweep; already done and skipped; run now; failed (now or before).
    n_workers : int
        Workers that ran the frames (0: in this process, without Dask).
    wall_s : float
        Wall time of run_sweep [s].
    table : pyarrow.Table
        One row per frame, in frame order (``read_table`` reads it back).
    """

    out_dir: Path
    table_path: Path
    n_frames: int
    n_skipped: int
    n_run: int
    n_failed: int
    n_workers: int
    wall_s: float
    table: Any

    def rows(self) -> list[dict[str, Any]]:
        """The table as a list of dicts, one per frame."""
        return self.table.to_pylist()

    def describe(self) -> str:
        """One line for the command line."""
        where = f"{self.n_workers} workers" if self.n_workers else "in process"
        failed = f", {self.n_failed} failed (rerun to retry)" if self.n_failed else ""
        return (
            f"{self.n_frames} frames ({self.n_run} run, {self.n_skipped} already done{failed}) "
            f"in {self.wall_s:.1f} s on {where} -> {self.table_path}"
        )


def run_sweep(
    sweep: Sweep,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    clouds: str | bool | None = None,
    progress: bool = True,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> SweepReport:
    """Run every frame not done yet in ``out_dir``, then (re)write the table.

    Parameters
    ----------
    sweep : Sweep
        From :func:`load_sweep` or :func:`build_sweep`.
    out_dir : str or Path
        The output folder (created if missing); see the module docstring for its layout.
    workers : int, optional
        Worker processes of a Dask LocalCluster started for this run (one thread each); default
        the number of cores. 0 runs the frames in this process, one after the other, without Dask.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://HOST:8786``) to use instead.
    client : distributed.Client, optional
        An existing Dask client to use instead (a notebook's cluster).
    clouds : "ply", "las", False or None
        Write each frame's point cloud; None: as the sweep says.
    progress : bool
        A progress bar on stderr.
    connect_timeout_s : float
        How long to wait for ``scheduler`` and one of its workers [s].

    Returns
    -------
    SweepReport

    Raises
    ------
    SweepError
        Conflicting arguments, an output path that is a file, an unreachable scheduler or one
        without workers: before any frame runs and before anything is written.
    """
    start = time.perf_counter()
    options = {"workers": workers, "scheduler": scheduler, "client": client}
    given = [name for name, value in options.items() if value is not None]
    if len(given) > 1:
        raise SweepError(f"give one of workers, scheduler or client, not {' and '.join(given)}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 0
    ):
        raise SweepError(f"workers must be a whole number >= 0, got {workers!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise SweepError(f"output folder {str(out)!r} is a file")
    fmt = sweep.clouds if clouds is None else _cloud_format(clouds, "clouds")
    pending = [f for f in sweep.frames if not _is_done(out, f, fmt)]
    n_failed_now = 0
    n_workers = 0
    with _Executor(pending, workers, scheduler, client, connect_timeout_s) as submit:
        for sub in (FRAMES_DIR, *((CLOUDS_DIR,) if fmt else ())):
            (out / sub).mkdir(parents=True, exist_ok=True)
        io.write_json(out / MANIFEST_NAME, _manifest(sweep))
        n_workers = submit.n_workers
        bar = tqdm(
            total=len(sweep),
            initial=len(sweep) - len(pending),
            desc=f"sweep {sweep.name}",
            unit="frame",
            file=sys.stderr,
            disable=not progress,
            dynamic_ncols=True,
        )
        with bar:
            for frame, outcome in submit(pending, fmt is not None):
                _record(out, sweep, frame, outcome, fmt)
                n_failed_now += outcome.error is not None
                if outcome.error is not None:
                    bar.set_postfix_str(f"{n_failed_now} failed")
                bar.update()
    table = _assemble_table(out, sweep)
    path = out / TABLE_NAME
    _write_parquet(path, table)
    n_failed = sum(1 for s in table.column("status").to_pylist() if s != "ok")
    return SweepReport(
        out_dir=out,
        table_path=path,
        n_frames=len(sweep),
        n_skipped=len(sweep) - len(pending),
        n_run=len(pending),
        n_failed=n_failed,
        n_workers=n_workers,
        wall_s=time.perf_counter() - start,
        table=table,
    )


def _row_path(out: Path, frame: Frame) -> Path:
    return out / FRAMES_DIR / f"{frame.frame_id}.json"


def _cloud_name(frame: Frame, fmt: str) -> str:
    return f"{CLOUDS_DIR}/{frame.frame_id}.{fmt}"


def _read_row(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # missing or unreadable: the frame runs again


def _is_done(out: Path, frame: Frame, fmt: str | None) -> bool:
    """A frame is done when its row says ok and, if clouds are asked, its cloud file exists."""
    row = _read_row(_row_path(out, frame))
    if row is None or row.get("status") != "ok":
        return False
    return fmt is None or (out / _cloud_name(frame, fmt)).is_file()


def _record(out: Path, sweep: Sweep, frame: Frame, outcome: FrameOutcome, fmt: str | None) -> None:
    """Write the frame's cloud (if any), then its row: the row marks the frame done."""
    cloud_name = None
    if outcome.cloud is not None and fmt is not None:
        cloud_name = _cloud_name(frame, fmt)
        comments = (
            "lmapd-sim point cloud, sensor frame (x right, y down, z boresight), metres",
            f"sweep {sweep.name} frame {frame.index} ({frame.frame_id}): {_describe(frame.params)}",
            f"scene {frame.scene.name}",
            outcome.target_line,
            f"material_id indexes: {' '.join(MATERIAL_NAMES)}",
        )
        io.write_cloud(out / cloud_name, outcome.cloud, comments)
    row = {
        "frame_id": frame.frame_id,
        "params": frame.params,
        "status": "ok" if outcome.error is None else "error",
        "error": outcome.error,
        "metrics": outcome.metrics,
        "frame_s": outcome.frame_s,
        "cloud": cloud_name,
    }
    io.write_json(_row_path(out, frame), row)


def _manifest(sweep: Sweep) -> dict[str, Any]:
    return {
        "name": sweep.name,
        "source": sweep.source,
        "base": sweep.base.name,
        "set": sweep.fixed,
        "clouds": sweep.clouds,
        "n_frames": len(sweep),
        "frames": [
            {"index": f.index, "frame_id": f.frame_id, "params": f.params} for f in sweep.frames
        ],
    }


class _Submit:
    """Runs frames and yields (frame, outcome) as they finish."""

    n_workers = 0

    def __call__(self, frames: Sequence[Frame], want_cloud: bool) -> Iterator:
        raise NotImplementedError


class _Serial(_Submit):
    def __init__(self):
        self.pipeline = Pipeline()

    def __call__(self, frames, want_cloud):
        for frame in frames:
            yield frame, run_frame(frame.scene, self.pipeline, want_cloud)


class _Dask(_Submit):
    def __init__(self, client, n_workers: int):
        self.client = client
        self.n_workers = n_workers

    def __call__(self, frames, want_cloud):
        from distributed import as_completed  # noqa: PLC0415

        by_key = {}
        futures = []
        run = uuid.uuid4().hex[:8]  # task keys unique per run: a notebook may rerun a sweep
        for frame in frames:
            fut = self.client.submit(
                _frame_task, frame.scene, want_cloud, key=f"lmapd-frame-{frame.frame_id}-{run}"
            )
            by_key[fut.key] = frame
            futures.append(fut)
        try:
            # this client's loop: as_completed would take the default client's, and with two
            # clients in one process it would then wait forever
            done = as_completed(
                futures, loop=self.client.loop, with_results=True, raise_errors=False
            )
            for fut, value in done:
                frame = by_key.pop(fut.key)
                if not isinstance(value, FrameOutcome):  # the task itself failed (worker lost)
                    exc = value[1] if isinstance(value, tuple) and len(value) == 3 else value
                    value = FrameOutcome(None, _error_text(exc), math.nan)
                fut.release()
                yield frame, value
        finally:
            self.client.cancel(list(futures))


class _Executor:
    """Context manager: the frame runner, with any cluster it starts closed on exit."""

    def __init__(self, pending, workers, scheduler, client, timeout_s):
        self.pending = pending
        self.workers = workers
        self.scheduler = scheduler
        self.client = client
        self.timeout_s = timeout_s
        self.owned: list = []

    def __enter__(self) -> _Submit:
        try:
            return self._start()
        except BaseException:
            self.__exit__()  # __exit__ does not run when __enter__ raises
            raise

    def _start(self) -> _Submit:
        if self.client is not None:
            return _Dask(self.client, len(self.client.scheduler_info()["workers"]))
        if self.scheduler:
            client = _connect(self.scheduler, self.timeout_s)
            self.owned.append(client)
            return _Dask(client, len(client.scheduler_info()["workers"]))
        n = (os.cpu_count() or 1) if self.workers is None else self.workers
        if n == 0 or not self.pending:
            return _Serial()
        n = min(n, len(self.pending))
        from distributed import Client, LocalCluster  # noqa: PLC0415  (slow import)

        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
        self.owned.append(cluster)
        client = Client(cluster)
        self.owned.append(client)
        return _Dask(client, n)

    def __exit__(self, *exc) -> None:
        for obj in reversed(self.owned):
            obj.close()


def _connect(address: str, timeout_s: float):
    """A Client of the scheduler at ``address`` with at least one worker, or SweepError."""
    from distributed import Client  # noqa: PLC0415

    try:
        client = Client(address, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise SweepError(
            f"cannot reach the Dask scheduler at {address!r} within {timeout_s:g} s ({exc}); "
            "give its address as tcp://HOST:PORT (default port 8786) and check it is running"
        ) from None
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        client.close()
        raise SweepError(
            f"the Dask scheduler at {address!r} has no workers after {timeout_s:g} s ({exc}); "
            "start some with `dask worker ADDRESS`"
        ) from None
    return client


# ----------------------------------------------------------------------------------------------
# the table (Parquet, via pyarrow)
# ----------------------------------------------------------------------------------------------
def _assemble_table(out: Path, sweep: Sweep):
    """One row per frame, in frame order, from the row files; frames without a row are
    'pending'. A parameter a frame does not set holds its value in that frame's scene."""
    import pyarrow as pa  # noqa: PLC0415

    from . import __version__  # noqa: PLC0415

    frames = sweep.frames
    rows = [_read_row(_row_path(out, f)) or {} for f in frames]
    columns: dict[str, Any] = {
        "index": pa.array([f.index for f in sweep.frames], pa.int64()),
        "frame_id": pa.array([f.frame_id for f in sweep.frames], pa.string()),
    }
    for key in sweep.keys:
        values = [f.params[key] if key in f.params else _scene_value(f.scene, key) for f in frames]
        columns[key] = _param_column(values)
    columns["status"] = pa.array([r.get("status", "pending") for r in rows], pa.string())
    columns["error"] = pa.array([r.get("error") for r in rows], pa.string())
    for name, kind, _ in METRICS:
        values = [(r.get("metrics") or {}).get(name) for r in rows]
        columns[name] = pa.array(values, getattr(pa, kind)())
    columns["frame_s"] = pa.array([r.get("frame_s") for r in rows], pa.float64())
    columns["cloud"] = pa.array([r.get("cloud") for r in rows], pa.string())
    columns["scene_toml"] = pa.array([f.scene_toml for f in frames], pa.string())
    meta = {"lmapd-sim": __version__, "sweep": sweep.name, "source": sweep.source}
    return pa.table(columns).replace_schema_metadata(meta)


def _scene_value(scene: Scene, key: str):
    """The value of scene key ``key`` (quick or dotted) in ``scene``, TOML-like (lists, dicts)."""
    value: Any = scene
    for part in _field(key).split("."):
        value = getattr(value, part)
    if key.endswith("materials"):
        return dict(value)
    return list(value) if isinstance(value, tuple) else value


def _param_column(values: list):
    """A parameter column: bool, int64, float64 or string if all values agree, else JSON text."""
    import pyarrow as pa  # noqa: PLC0415

    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present):
        return pa.array(values, pa.bool_())
    if all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.array(values, pa.int64())
    if all(_is_number(v) or isinstance(v, float) for v in present):
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    if all(isinstance(v, str) for v in present):
        return pa.array(values, pa.string())
    text = [None if v is None else json.dumps(v, sort_keys=True) for v in values]
    return pa.array(text, pa.string())


def _write_parquet(path: Path, table) -> None:
    import pyarrow.parquet as pq  # noqa: PLC0415

    with io.atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def read_table(path: str | Path):
    """Read a sweep's table: ``path`` is the output folder or the Parquet file. A pyarrow.Table
    (``.to_pylist()`` for rows, ``.to_pandas()`` if pandas is installed)."""
    import pyarrow.parquet as pq  # noqa: PLC0415

    path = Path(path)
    return pq.read_table(path / TABLE_NAME if path.is_dir() else path)


# ----------------------------------------------------------------------------------------------
# the command line
# ----------------------------------------------------------------------------------------------
def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``sweep`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    p = subparsers.add_parser(
        "sweep",
        help="run a grid or list of frames on Dask and write a Parquet table of their metrics",
        description="Run every frame of SWEEP.toml not yet done in DIR (each a Dask task), "
        "write DIR/frames/<id>.json per frame and DIR/sweep.parquet. Rerun to resume or to "
        "retry failed frames.",
    )
    p.add_argument("sweep", help="sweep file (TOML: base, [set], [grid], [[list]])")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler, tcp://HOST:8786 (default: a local cluster)",
    )
    p.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes of the local cluster (default: the number of cores); "
        "0 runs the frames in this process without Dask",
    )
    p.add_argument(
        "--clouds",
        choices=(*CLOUD_FORMATS, "none"),
        help="also write each frame's point cloud in DIR/clouds (default: as the sweep file says)",
    )
    p.set_defaults(func=run_cli)
    return p


def run_cli(args: argparse.Namespace) -> int:
    """``lmapd sweep``: 0 if every frame is done, 1 if some failed (they are retried next run)."""
    from .cli import CliError, say  # noqa: PLC0415  (cli imports this module)

    if args.scheduler and args.workers is not None:
        raise CliError("--workers sizes the local cluster; with --scheduler give no --workers")
    if args.workers is not None and args.workers < 0:
        raise CliError(f"--workers {args.workers}: give a number >= 0")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {args.out!r} is a file, not a folder")
    sweep = load_sweep(args.sweep)
    clouds = None if args.clouds is None else (False if args.clouds == "none" else args.clouds)
    report = run_sweep(
        sweep, out, workers=args.workers, scheduler=args.scheduler, clouds=clouds, progress=True
    )
    say(f"sweep {sweep.name}: {report.describe()}")
    return 0 if report.n_failed == 0 else 1
