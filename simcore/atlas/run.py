"""Running an atlas: every attitude of the grid not done yet in its folder, in this process or
on Dask, each row written as it finishes; then the table, the summary, the map and the best and
worst attitudes' scene files.

The folder::

    DIR/atlas.json      the grid, the scene, the metric, the requirements; once complete the
                        best, worst and median attitudes and the share that meets the requirements
    DIR/atlas.parquet   one row per attitude (simcore.atlas.frame.COLUMNS)
    DIR/atlas.png       the map (an equal-area projection of the metric)
    DIR/best.toml, DIR/worst.toml   scenes that ``lmapd simulate`` reproduces exactly
    DIR/frames/ID.json  each attitude's row as it finished (what --resume reads)
"""

from __future__ import annotations

import math
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from .. import io
from .._version import __version__
from ..scene import Scene, SceneError, dump_scene, with_overrides
from ..sweep.run import _Executor, _is_done
from ..sweep.spec import CONNECT_TIMEOUT_S, FRAMES_DIR, Frame, Sweep, build_sweep
from ..sweep.table import _read_row, _row_path
from .frame import COLUMNS, DEFAULT_METRIC, METRICS, _attitude_task, metric_values, run_attitude
from .grid import DEFAULT_STEP_DEG, AtlasError, AttitudeGrid, attitude_grid

MANIFEST_NAME = "atlas.json"
TABLE_NAME = "atlas.parquet"
FIGURE_NAME = "atlas.png"
_REQUIREMENT = re.compile(r"^\s*([A-Za-z_.0-9]+)\s*(>=|<=)\s*([-+0-9.eE]+)\s*$")


@dataclass(frozen=True)
class Requirement:
    """``metric OP bound`` that one attitude meets or not (a figure with no value fails it)."""

    metric: str
    op: str  # ">=" or "<="
    bound: float

    def met(self, values: np.ndarray) -> np.ndarray:
        """(n,) bool for the (n,) values (NaN: no value, not met)."""
        with np.errstate(invalid="ignore"):
            return values >= self.bound if self.op == ">=" else values <= self.bound

    def text(self) -> str:
        return f"{self.metric} {self.op} {self.bound:g}"


def parse_requirement(text: str) -> Requirement:
    """``"recall >= 0.6"`` -> Requirement; AtlasError naming the text if it is not one."""
    match = _REQUIREMENT.match(text) if isinstance(text, str) else None
    if match is None:
        raise AtlasError(
            f'--require {text!r}: write a metric, >= or <=, and a number: "recall >= 0.6"'
        )
    name, op, bound_text = match.groups()
    name = name.removeprefix("quality.")
    if name not in METRICS:
        raise AtlasError(
            f"--require {text!r}: unknown metric {name!r}; choose from {', '.join(METRICS)}"
        )
    try:
        bound = float(bound_text)
    except ValueError:
        raise AtlasError(f"--require {text!r}: {bound_text!r} is not a number") from None
    if not math.isfinite(bound):
        raise AtlasError(f"--require {text!r}: the bound must be a finite number")
    return Requirement(name, op, bound)


@dataclass(frozen=True, eq=False)
class Atlas:
    """A checked atlas: the base scene, the grid, the metric mapped, the requirements, and one
    frame (a resolved scene) per attitude."""

    scene: Scene
    grid: AttitudeGrid
    metric: str
    requirements: tuple[Requirement, ...]
    sweep: Sweep = field(repr=False)

    @property
    def frames(self) -> tuple[Frame, ...]:
        return self.sweep.frames

    def __len__(self) -> int:
        return len(self.sweep)

    def manifest(self) -> dict[str, Any]:
        """What identifies the atlas (a --resume must find the same) and how to read it."""
        return {
            "lmapd-sim": __version__,
            "grid": self.grid.to_dict(),
            "metric": self.metric,
            "metric_column": METRICS[self.metric][0],
            "requirements": [r.text() for r in self.requirements],
            "scene_toml": dump_scene(self.scene),
            "columns": {name: meaning for name, _, meaning in COLUMNS},
        }


def build_atlas(
    scene: Scene,
    step_deg: float = DEFAULT_STEP_DEG,
    metric: str = DEFAULT_METRIC,
    requirements: tuple[str | Requirement, ...] = (),
) -> Atlas:
    """Check the options and build every attitude's scene (the base scene's pitch and azimuth
    replaced by the grid's; everything else, roll and the seed included, kept).

    Raises
    ------
    AtlasError
        A step outside 1-90 deg, an unknown metric or requirement, a scene whose attitude is fixed
        by a quaternion; before anything is run or written.
    """
    if not isinstance(scene, Scene):
        raise AtlasError("build_atlas() expects a Scene")
    if metric not in METRICS:
        raise AtlasError(f"--metric {metric!r}: unknown; choose from {', '.join(METRICS)}")
    if scene.pose.quaternion_wxyz:
        raise AtlasError(
            "the scene fixes its attitude with pose.quaternion_wxyz; an atlas varies pitch and "
            "azimuth: remove the quaternion (pose.quaternion_wxyz = [])"
        )
    grid = attitude_grid(step_deg)
    reqs = tuple(r if isinstance(r, Requirement) else parse_requirement(r) for r in requirements)
    frames = [{"pitch_deg": p, "azimuth_deg": a} for p, a in grid.attitudes()]
    try:
        sweep = build_sweep(base=scene, frames=frames, name=f"atlas {scene.name}")
    except SceneError as exc:
        raise AtlasError(str(exc)) from None
    return Atlas(scene, grid, metric, reqs, sweep)


@dataclass(frozen=True, eq=False)
class AtlasReport:
    """The outcome of :func:`run_atlas`.

    out_dir : Path
    n_attitudes, n_skipped, n_run, n_failed : int
        Attitudes of the grid; already done and skipped; run now; failed.
    n_workers : int
        Workers that ran them (0: in this process).
    wall_s : float
        Wall time [s].
    table : pyarrow.Table
        One row per attitude, in grid order.
    summary : dict
        What atlas.json holds (best, worst, median, shares).
    complete : bool
        Every attitude done (False after an interruption: the table holds what is done).
    """

    out_dir: Path
    n_attitudes: int
    n_skipped: int
    n_run: int
    n_failed: int
    n_workers: int
    wall_s: float
    table: Any
    summary: dict[str, Any]
    complete: bool

    def describe(self) -> str:
        where = f"{self.n_workers} workers" if self.n_workers else "in process"
        failed = f", {self.n_failed} failed (--resume retries them)" if self.n_failed else ""
        return (
            f"{self.n_attitudes} attitudes ({self.n_run} run, {self.n_skipped} already "
            f"done{failed}) in {self.wall_s:.1f} s on {where} -> {self.out_dir / TABLE_NAME}"
        )


def run_atlas(
    atlas: Atlas,
    out_dir: str | Path,
    *,
    resume: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    progress: bool = True,
    figure: bool = True,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> AtlasReport:
    """Run every attitude not done yet in ``out_dir``, then write the table, the summary, the
    map and the best and worst scenes.

    ``resume`` goes on with an atlas already in ``out_dir`` (the same grid, scene, metric and
    requirements); without it a folder that holds an atlas is refused. ``workers``,
    ``scheduler``, ``client``: as :func:`simcore.sweep.run_sweep` (a LocalCluster of one
    single-threaded worker per core by default, 0 for this process). An interruption
    (KeyboardInterrupt) writes the table of what is done and atlas.json, then goes on up.

    Raises
    ------
    AtlasError
        The folder is a file or cannot be written, holds another atlas, or holds one and
        ``resume`` is not given (or nothing to resume); before any attitude runs.
    """
    start = time.perf_counter()
    out = Path(out_dir)
    _prepare(out, atlas, resume)
    frames = atlas.frames
    pending = [f for f in frames if not _is_done(out, f, None)]  # the sweep's rule, no clouds
    n_workers = 0
    interrupted = False
    with _Executor(
        pending,
        workers,
        scheduler,
        client,
        connect_timeout_s,
        run=run_attitude,
        task=_attitude_task,
    ) as submit:
        n_workers = submit.n_workers
        bar = tqdm(
            total=len(frames),
            initial=len(frames) - len(pending),
            desc="atlas",
            unit="attitude",
            file=sys.stderr,
            disable=not progress,
            dynamic_ncols=True,
        )
        n_failed_now = 0
        try:
            with bar:
                for frame, outcome in submit(pending, False):
                    _record(out, frame, outcome)
                    n_failed_now += outcome.error is not None
                    if outcome.error is not None:
                        bar.set_postfix_str(f"{n_failed_now} failed")
                    bar.update()
        except KeyboardInterrupt:
            interrupted = True
    table = assemble_table(out, atlas)
    _write_parquet(out / TABLE_NAME, table)
    status = table.column("status").to_pylist()
    complete = not interrupted and all(s != "pending" for s in status)
    summary = summarize(table, atlas) if complete else {}
    io.write_json(out / MANIFEST_NAME, {**atlas.manifest(), "complete": complete, **summary})
    report = AtlasReport(
        out_dir=out,
        n_attitudes=len(frames),
        n_skipped=len(frames) - len(pending),
        n_run=sum(1 for s in status if s != "pending") - (len(frames) - len(pending)),
        n_failed=sum(1 for s in status if s == "error"),
        n_workers=n_workers,
        wall_s=time.perf_counter() - start,
        table=table,
        summary=summary,
        complete=complete,
    )
    if interrupted:
        raise KeyboardInterrupt(f"{report.n_skipped + report.n_run} of {len(frames)} done")
    _write_extremes(out, atlas, summary)
    if figure:
        from .figure import write_map  # noqa: PLC0415  (matplotlib)

        write_map(out / FIGURE_NAME, table, atlas.scene, atlas.grid, atlas.metric, summary)
    return report


def _prepare(out: Path, atlas: Atlas, resume: bool) -> None:
    """The folder made (or checked) and the manifest written: an unusable folder, another
    atlas there or a missing --resume fails here, before anything runs."""
    if out.exists() and not out.is_dir():
        raise AtlasError(f"--out {str(out)!r} is a file, not a folder")
    manifest = out / MANIFEST_NAME
    if manifest.is_file():
        old = _read_row(manifest) or {}
        mine = atlas.manifest()
        differs = [
            k for k in ("grid", "metric", "requirements", "scene_toml") if old.get(k) != mine[k]
        ]
        if not resume:
            raise AtlasError(
                f"{out} already holds an atlas: --resume to finish or redraw it, or give another "
                "--out folder"
            )
        if differs:
            raise AtlasError(
                f"{out} holds another atlas (its {differs[0].replace('_toml', '')} differs): give "
                "the same scene and options to --resume it, or another --out folder"
            )
    elif resume and out.is_dir() and any(out.iterdir()):
        raise AtlasError(f"--resume: {out} holds no atlas ({MANIFEST_NAME} is missing)")
    try:
        (out / FRAMES_DIR).mkdir(parents=True, exist_ok=True)
        io.remove_stale_parts(out)
        io.remove_stale_parts(out / FRAMES_DIR)
        io.write_json(manifest, {**atlas.manifest(), "complete": False})
    except OSError as exc:
        raise AtlasError(
            f"--out {str(out)!r}: cannot write there ({exc.strerror or exc})"
        ) from None


def _record(out: Path, frame: Frame, outcome) -> None:
    row = {
        "frame_id": frame.frame_id,
        "params": frame.params,
        "status": "ok" if outcome.error is None else "error",
        "error": outcome.error,
        "metrics": outcome.metrics,
        "frame_s": outcome.frame_s,
    }
    io.write_json(_row_path(out, frame), row)


def assemble_table(out: Path, atlas: Atlas):
    """One row per attitude, in grid order, from the row files ('pending' where none)."""
    import pyarrow as pa  # noqa: PLC0415

    rows = [_read_row(_row_path(out, f)) or {} for f in atlas.frames]
    columns: dict[str, Any] = {
        "index": pa.array([f.index for f in atlas.frames], pa.int64()),
        "pitch_deg": pa.array([f.params["pitch_deg"] for f in atlas.frames], pa.float64()),
        "azimuth_deg": pa.array([f.params["azimuth_deg"] for f in atlas.frames], pa.float64()),
        "solid_angle_sr": pa.array(
            [atlas.grid.solid_angle_sr(f.params["pitch_deg"]) for f in atlas.frames], pa.float64()
        ),
        "status": pa.array([r.get("status", "pending") for r in rows], pa.string()),
        "error": pa.array([r.get("error") for r in rows], pa.string()),
    }
    for name, kind, _ in COLUMNS:
        values = [(r.get("metrics") or {}).get(name) for r in rows]
        columns[name] = pa.array(values, getattr(pa, kind)())
    columns["frame_s"] = pa.array([r.get("frame_s") for r in rows], pa.float64())
    columns["frame_id"] = pa.array([f.frame_id for f in atlas.frames], pa.string())
    meta = {"lmapd-sim": __version__, "atlas": atlas.scene.name, "metric": atlas.metric}
    return pa.table(columns).replace_schema_metadata(meta)


def _write_parquet(path: Path, table) -> None:
    import pyarrow.parquet as pq  # noqa: PLC0415

    with io.atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def read_atlas(path: str | Path):
    """An atlas's table: ``path`` is its folder or the Parquet file (a pyarrow.Table)."""
    import pyarrow.parquet as pq  # noqa: PLC0415

    path = Path(path)
    return pq.read_table(path / TABLE_NAME if path.is_dir() else path)


def _score(values: np.ndarray, better: str) -> np.ndarray:
    """Larger is better: the values, their negatives or their negative magnitudes."""
    return values if better == "high" else (-values if better == "low" else -np.abs(values))


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The median of ``values`` with ``weights`` (the solid angles), NaN if none; the value at
    which the cumulative weight first reaches half."""
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    if not len(cum) or cum[-1] <= 0:
        return math.nan
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def summarize(table, atlas: Atlas) -> dict[str, Any]:
    """Best, worst and median attitudes of the metric, and the shares (of the sphere of view
    directions, weighted by solid angle, and of the grid's points) that see the target and that
    meet the requirements."""
    column, label, better = METRICS[atlas.metric]
    values = metric_values(table, atlas.metric)
    weights = np.asarray(table.column("solid_angle_sr").to_pylist(), dtype=np.float64)
    pitch = table.column("pitch_deg").to_pylist()
    azimuth = table.column("azimuth_deg").to_pylist()
    hit = np.asarray([n or 0 for n in table.column("n_hit_pixels").to_pylist()]) > 0
    has = np.isfinite(values)

    def attitude(i: int) -> dict[str, Any]:
        return {
            "index": int(i),
            "pitch_deg": pitch[i],
            "azimuth_deg": azimuth[i],
            "value": float(values[i]),
        }

    out: dict[str, Any] = {
        "metric_label": label,
        "better": better,
        "n_with_value": int(has.sum()),
        "n_not_seen": int((~hit).sum()),
        "share_seen_of_sphere": float(weights[hit].sum() / weights.sum()),
        "best": None,
        "worst": None,
        "median": None,
        "median_of_grid_points": None,
    }
    if has.any():
        score = np.where(has, _score(values, better), -np.inf)
        out["best"] = attitude(int(np.argmax(score)))
        out["worst"] = attitude(int(np.argmin(np.where(has, score, np.inf))))
        out["median"] = weighted_median(values[has], weights[has])
        out["median_of_grid_points"] = float(np.median(values[has]))
    if atlas.requirements:
        met = np.ones(len(values), dtype=bool)
        each = {}
        for req in atlas.requirements:
            ok = req.met(metric_values(table, req.metric))
            each[req.text()] = float(weights[ok].sum() / weights.sum())
            met &= ok
        out["meets_requirements"] = {
            "share_of_sphere": float(weights[met].sum() / weights.sum()),
            "share_of_grid_points": float(met.mean()),
            "each_share_of_sphere": each,
        }
    return out


def extreme_scene(atlas: Atlas, which: str, summary: dict[str, Any]) -> Scene | None:
    """The scene of the best or worst attitude (None if no attitude has a value)."""
    chosen = summary.get(which)
    if chosen is None:
        return None
    return with_overrides(
        atlas.scene, pitch_deg=chosen["pitch_deg"], azimuth_deg=chosen["azimuth_deg"]
    )


def _write_extremes(out: Path, atlas: Atlas, summary: dict[str, Any]) -> None:
    for which in ("best", "worst"):
        path = out / f"{which}.toml"
        scene = extreme_scene(atlas, which, summary)
        if scene is None:
            path.unlink(missing_ok=True)
            continue
        with io.atomic_path(path) as tmp:
            tmp.write_text(dump_scene(scene), encoding="utf-8")
