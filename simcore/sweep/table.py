"""The sweep's table: one row per frame from the row files, written as Parquet (pyarrow, imported
only here, inside the functions)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .. import io
from .._version import __version__
from ..scene import Scene
from .spec import FRAMES_DIR, METRICS, TABLE_NAME, Frame, Sweep, _field, _is_number


def _row_path(out: Path, frame: Frame) -> Path:
    return out / FRAMES_DIR / f"{frame.frame_id}.json"


def _read_row(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # missing or unreadable: the frame runs again


def _assemble_table(out: Path, sweep: Sweep):
    """One row per frame, in frame order, from the row files; frames without a row are
    'pending'. A parameter a frame does not set holds its value in that frame's scene."""
    import pyarrow as pa  # noqa: PLC0415

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
