"""Writers and readers: point clouds (binary PLY), JSON summaries, waveform cubes (NPZ).

Every writer is atomic: it writes a temporary file in the destination's folder and renames it into
place, so an interrupted run never leaves a half-written file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement

from .pointcloud import ATTRIBUTES, PointCloud

_PLY_TYPES = {np.int32: "i4", np.float64: "f8", np.bool_: "u1"}


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path next to ``path``; rename it to ``path`` only if the block succeeds."""
    path = Path(path)
    if not path.parent.exists():
        raise FileNotFoundError(f"output folder does not exist: {path.parent}")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual mode
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_ply(path: str | Path, cloud: PointCloud, comments: tuple[str, ...] = ()) -> None:
    """Binary little-endian PLY: x, y, z [m] and every per-point attribute of ATTRIBUTES."""
    dtype = [("x", "f8"), ("y", "f8"), ("z", "f8")]
    dtype += [(name, _PLY_TYPES[t]) for name, t in ATTRIBUTES]
    data = np.empty(len(cloud), dtype=dtype)
    for i, axis in enumerate("xyz"):
        data[axis] = cloud.points[:, i]
    for name, _ in ATTRIBUTES:
        data[name] = cloud.attributes[name]
    ply = PlyData([PlyElement.describe(data, "vertex")], text=False, comments=list(comments))
    with atomic_path(path) as tmp:
        ply.write(str(tmp))


def read_ply(path: str | Path) -> PointCloud:
    """Read a PLY written by :func:`write_ply` back into a PointCloud."""
    vertex = PlyData.read(str(path))["vertex"].data
    points = np.stack([vertex[a].astype(np.float64) for a in "xyz"], axis=1)
    attrs = {name: vertex[name].astype(t) for name, t in ATTRIBUTES}
    return PointCloud(points, attrs)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None if np.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


def write_json(path: str | Path, data: dict) -> None:
    """Pretty JSON, NaN as null and infinities as strings (strict JSON)."""
    text = json.dumps(_jsonable(data), indent=2, allow_nan=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")


def waveform_cube(result, max_elements: int = 1 << 22) -> dict[str, np.ndarray]:
    """Every lit pixel's band-limited and raw echo on a common-length window.

    Returns a dict: row, col (n,), t0_s (n,) start time of each row, dt_s, power_w and
    filtered_w (n, L) [W], t_half_s (n,), range_m (n,) (NaN where not detected).
    """
    e = result.echo
    energy = result.scene.laser.pulse_energy_j
    has = e.weights > 0
    t_first = np.where(has, e.arrivals_s, np.inf).min(axis=1)
    t_last = np.where(has, e.arrivals_s, -np.inf).max(axis=1)
    length = (
        int(
            np.ceil(
                (np.max(t_last - t_first, initial=0.0) + e.shape.t_end_s - e.shape.t_start_s)
                / e.dt_s
            )
        )
        + 1
    )
    n, k = e.weights.shape
    t0 = t_first + e.shape.t_start_s
    raw = np.zeros((n, length))
    filt = np.zeros((n, length))
    step = max(1, max_elements // (length * max(k, 1)))
    offsets = e.dt_s * np.arange(length)
    for c in range(0, n, step):
        sl = slice(c, c + step)
        tau = (t0[sl, None] + offsets[None, :])[:, :, None] - e.arrivals_s[sl, None, :]
        raw[sl] = np.einsum("nlk,nk->nl", e.shape.raw_at(tau), e.weights[sl]) * energy
        filt[sl] = np.einsum("nlk,nk->nl", e.shape.filtered_at(tau), e.weights[sl]) * energy
    p = result.pixels
    return {
        "row": (e.pixel // p).astype(np.int32),
        "col": (e.pixel % p).astype(np.int32),
        "t0_s": t0,
        "dt_s": np.float64(e.dt_s),
        "power_w": raw.astype(np.float32),
        "filtered_w": filt.astype(np.float32),
        "t_half_s": e.features.t_half_s,
        "range_m": result.detection.range_m,
        "reference_t_half_s": np.float64(e.shape.t_half_s),
    }


def write_waveforms_npz(path: str | Path, result) -> None:
    """The waveform cube (lit pixels x time) as a compressed NPZ."""
    cube = waveform_cube(result)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **cube)


__all__ = [
    "atomic_path",
    "read_ply",
    "waveform_cube",
    "write_json",
    "write_ply",
    "write_waveforms_npz",
]
