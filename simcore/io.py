"""Writers and readers: point clouds (binary PLY, LAS 1.4), JSON summaries, waveform cubes (NPZ,
HDF5).

Every writer is atomic: it writes a temporary file in the destination's folder and renames it into
place, so an interrupted run never leaves a half-written file behind. ``write_cloud`` /
``read_cloud`` and ``write_waveforms`` / ``read_waveforms`` choose the format from the suffix.
laspy and h5py are imported only when a LAS or HDF5 file is written or read.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from plyfile import PlyData, PlyElement

from .pointcloud import ATTRIBUTES, PointCloud

_PLY_TYPES = {np.int32: "i4", np.float64: "f8", np.bool_: "u1"}


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path next to ``path``; rename it to ``path`` only if the block succeeds.

    The temporary file is hidden (``.NAME.lmapd-PID-XXXX.part``); ``remove_stale_parts`` removes
    those a killed process left (the ``lmapd`` commands call it on their output folders). A
    ``path`` that is itself such a temporary file (the commands stage their outputs in them) is
    written in place: its owner renames it, and no temporary of a temporary (a nested name that
    the commands' clean-up would not recognise as its own) is made.
    """
    path = Path(path)
    if not path.parent.exists():
        raise FileNotFoundError(f"output folder does not exist: {path.parent}")
    umask = os.umask(0)
    os.umask(umask)
    if is_part_path(path):
        yield path
        os.chmod(path, 0o666 & ~umask)
        return
    tmp = part_path(path)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual mode
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


_PART_TAG = ".lmapd-"  # in the name of every temporary file: .NAME.lmapd-PID-XXXX.part[.SUFFIX]


def part_path(path: str | Path) -> Path:
    """Create an empty hidden temporary file next to ``path`` and return it; its name ends in
    ``.part`` plus ``path``'s suffix (the writers choose the format by suffix)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}{_PART_TAG}{os.getpid()}-",
        suffix=f".part{path.suffix}",
        dir=path.parent,
    )
    os.close(fd)
    return Path(tmp)


def is_part_path(path: str | Path) -> bool:
    """Whether ``path`` is named as :func:`part_path` names its temporary files."""
    name = Path(path).name
    head, tag, tail = name.rpartition(_PART_TAG)
    pid_text, _, rest = tail.partition("-")
    return bool(tag) and head.startswith(".") and pid_text.isdigit() and ".part" in rest


def remove_stale_parts(folder: str | Path) -> list[Path]:
    """Remove the temporary files (``part_path``) in ``folder`` whose process is gone; the
    removed paths. Files of running processes, and anything else, stay."""
    removed = []
    for p in Path(folder).glob(f".*{_PART_TAG}*-*.part*"):
        pid_text = p.name.rpartition(_PART_TAG)[2].partition("-")[0]
        if not pid_text.isdigit() or _process_alive(int(pid_text)):
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process, or not a pid: leave its file alone
    return True


def ply_comment(text: str) -> str:
    """``text`` as one PLY header comment: printable ASCII; every other character (non-ASCII
    letters, line breaks, tabs) written as its Python escape (``\\xe9``, ``\\u4e2d``, ``\\n``),
    so that a scene or mesh name in any script, or with a newline, keeps the header one line per
    comment. ASCII text is unchanged."""
    if text.isascii() and text.isprintable():
        return text
    return "".join(
        c if c.isascii() and c.isprintable() else c.encode("unicode_escape").decode() for c in text
    )


def cloud_attributes(cloud: PointCloud) -> tuple[tuple[str, type], ...]:
    """The cloud's per-point attributes as (name, numpy type): the shared ATTRIBUTES, then any a
    receiver adds (the Geiger-mode array's ``counts``, ``signal_pe``), stored as float64 unless
    int32 or bool."""
    shared = {name for name, _ in ATTRIBUTES}
    extra = []
    for name, values in cloud.attributes.items():
        if name in shared:
            continue
        kind = np.asarray(values).dtype
        extra.append(
            (name, np.bool_ if kind == np.bool_ else np.int32 if kind == np.int32 else np.float64)
        )
    return (*ATTRIBUTES, *extra)


def write_ply(path: str | Path, cloud: PointCloud, comments: tuple[str, ...] = ()) -> None:
    """Binary little-endian PLY: x, y, z [m] and every per-point attribute of the cloud (the
    shared ATTRIBUTES, then a receiver's own)."""
    attributes = cloud_attributes(cloud)
    dtype = [("x", "f8"), ("y", "f8"), ("z", "f8")]
    dtype += [(name, _PLY_TYPES[t]) for name, t in attributes]
    data = np.empty(len(cloud), dtype=dtype)
    for i, axis in enumerate("xyz"):
        data[axis] = cloud.points[:, i]
    for name, _ in attributes:
        data[name] = cloud.attributes[name]
    header = [ply_comment(c) for c in comments]
    ply = PlyData([PlyElement.describe(data, "vertex")], text=False, comments=header)
    with atomic_path(path) as tmp:
        ply.write(str(tmp))


def read_ply(path: str | Path) -> PointCloud:
    """Read a PLY written by :func:`write_ply` back into a PointCloud."""
    vertex = PlyData.read(str(path))["vertex"].data
    points = np.stack([vertex[a].astype(np.float64) for a in "xyz"], axis=1)
    attrs = {name: vertex[name].astype(t) for name, t in ATTRIBUTES}
    shared = {"x", "y", "z", *attrs}
    attrs |= {n: np.asarray(vertex[n]) for n in vertex.dtype.names if n not in shared}
    return PointCloud(points=points, attributes=attrs)


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


def waveform_cube(result) -> dict[str, np.ndarray]:
    """Every lit pixel's band-limited and raw echo on a common-length window.

    Returns a dict: row, col (n,), t0_s (n,) start time of each row, dt_s, power_w and
    filtered_w (n, L) [W], t_half_s (n,), range_m (n,) (NaN where not detected).
    """
    from .echo.features import sample_echoes  # noqa: PLC0415  (the kernel, loaded on use)

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
    t0 = t_first + e.shape.t_start_s
    raw = sample_echoes(e.shape, e.shape.raw, e.arrivals_s, e.weights, t0, e.dt_s, length)
    filt = sample_echoes(e.shape, e.shape.filtered, e.arrivals_s, e.weights, t0, e.dt_s, length)
    p = result.pixels
    return {
        "row": (e.pixel // p).astype(np.int32),
        "col": (e.pixel % p).astype(np.int32),
        "t0_s": t0,
        "dt_s": np.float64(e.dt_s),
        "power_w": (raw * energy).astype(np.float32),
        "filtered_w": (filt * energy).astype(np.float32),
        "t_half_s": e.features.t_half_s,
        "range_m": result.detection.range_m,
        "reference_t_half_s": np.float64(e.shape.t_half_s),
    }


def write_waveforms_npz(path: str | Path, result) -> None:
    """The waveform cube (lit pixels x time) as a compressed NPZ."""
    cube: dict[str, Any] = waveform_cube(result)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **cube)


# ----------------------------------------------------------------------------------------------
# LAS 1.4 (laspy)
# ----------------------------------------------------------------------------------------------
CLOUD_SUFFIXES = (".ply", ".las")  # point cloud formats, chosen by the file's suffix
LAS_SCALE_M = 1e-4  # [m] coordinate step of the LAS integers: 0.1 mm (see write_las)
LAS_CLASS_TARGET = 1  # ASPRS class 1 "unclassified": a detected point of the target
LAS_CLASS_OUTLIER = 7  # ASPRS class 7 "low point (noise)": a false alarm (is_outlier)
_LAS_POINT_FORMAT = 6  # LAS 1.4 point format 6: x, y, z, intensity, returns, class, GPS time
_LAS_INT_MAX = 2**31 - 1  # [-] LAS stores x, y, z as int32 multiples of the scale
_LAS_VLR_USER = "lmapd-sim"  # user id of our VLR (at most 16 characters)
_LAS_VLR_COMMENTS = 1  # record id of the VLR that holds the comment lines (UTF-8, one a line)
_LAS_TYPES = {np.int32: "int32", np.float64: "float64", np.bool_: "uint8"}
_LAS_DESCRIPTIONS = {  # extra-bytes descriptions, at most 32 characters each
    "row": "pixel row (0 = top)",
    "col": "pixel column (0 = left)",
    "range_m": "measured range [m]",
    "intensity_w": "peak received power [W]",
    "snr": "signal-to-noise ratio (Eq. 18)",
    "material_id": "material index (-1: outlier)",
    "facet_id": "mesh facet index (-1: outlier)",
    "is_outlier": "1: false alarm, 0: target",
    "counts": "Geiger: counts in peak window",
    "signal_pe": "Geiger: echo pe per pulse",
    "part_id": "truth: target part (-1: none)",
    "true_range_m": "truth: noise-free range [m]",
    "range_error_m": "truth: measured - true range [m]",
    "incidence_deg": "truth: incidence angle [deg]",
    "outlier": "truth: false or > tau off (1)",
}


def _las_offsets_and_scale(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Offsets (3,) [m] (the bounding box centre, whole metres) and the coordinate scale [m].

    The scale is LAS_SCALE_M unless the cloud reaches farther than 214.7 km (int32 times 0.1 mm)
    from its centre; then it is the smallest power of ten that holds it.
    """
    if len(points) == 0:
        return np.zeros(3), LAS_SCALE_M
    offsets = np.round((points.min(axis=0) + points.max(axis=0)) / 2.0)
    reach_m = float(np.abs(points - offsets).max())
    scale = LAS_SCALE_M
    while reach_m / scale > _LAS_INT_MAX:
        scale *= 10.0
    return offsets, scale


def write_las(path: str | Path, cloud: PointCloud, comments: tuple[str, ...] = ()) -> None:
    """LAS 1.4, point format 6, with every per-point attribute as an extra-bytes dimension.

    Parameters
    ----------
    path : str or Path
        The ``.las`` file; its folder must exist. Written atomically.
    cloud : PointCloud
        points (n, 3) float64 [m] in the sensor frame and the ATTRIBUTES arrays (n,).
    comments : tuple of str
        Lines stored in a VLR (user id "lmapd-sim", record 1), e.g. the target's credit line;
        ``read_cloud_comments`` returns them.

    Notes
    -----
    - Coordinates: LAS stores int32 multiples of a scale. The scale is 0.1 mm (LAS_SCALE_M): its
      rounding error, at most 0.05 mm (0.03 mm rms), is far below the range noise (millimetres at
      best) and the 15 mm of a 100 ps timing step, and int32 steps of 0.1 mm reach +-214.7 km
      around the offset (the bounding box centre), so a frame at 100 km keeps millimetre
      coordinates. A cloud reaching farther gets the smallest power of ten that holds it. The
      exact range is also kept, in float64, in the ``range_m`` dimension.
    - Extra bytes: row, col, material_id, facet_id int32; range_m, intensity_w, snr float64;
      is_outlier uint8 (0 / 1).
    - Classification (ASPRS): target points 1 (LAS_CLASS_TARGET), false alarms 7 "low point
      (noise)" (LAS_CLASS_OUTLIER), the noise class most tools drop by default.
    - Intensity (uint16): the peak received power relative to the brightest point of the file,
      times 65535; the absolute power [W] is ``intensity_w``. Every point is return 1 of 1;
      GPS time 0.
    - Header: system identifier "lmapd-sim simulation", generating software "lmapd-sim VERSION";
      the WKT bit is set as LAS 1.4 requires for point format 6 (no CRS: sensor frame).
    """
    import laspy  # noqa: PLC0415  (only for LAS files)

    from ._version import __version__  # noqa: PLC0415

    attributes = cloud_attributes(cloud)
    header = laspy.LasHeader(point_format=_LAS_POINT_FORMAT, version="1.4")
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams(n, _LAS_TYPES[t], _LAS_DESCRIPTIONS.get(n, n[:32]))
            for n, t in attributes
        ]
    )
    offsets, scale = _las_offsets_and_scale(cloud.points)
    header.offsets = offsets
    header.scales = np.full(3, scale)
    header.system_identifier = "lmapd-sim simulation"
    header.generating_software = f"lmapd-sim {__version__}"[:32]
    header.global_encoding.wkt = True
    if comments:
        text = "\n".join(ply_comment(c) for c in comments).encode("utf-8")  # one line each
        header.vlrs.append(laspy.VLR(_LAS_VLR_USER, _LAS_VLR_COMMENTS, "comments", text))
    las = laspy.LasData(header)
    las.x, las.y, las.z = (cloud.points[:, i] for i in range(3))
    attrs = cloud.attributes
    for name, _ in attributes:
        values = attrs[name]
        setattr(las, name, values.astype(np.uint8) if values.dtype == np.bool_ else values)
    outlier = attrs["is_outlier"]
    las.classification = np.where(outlier, LAS_CLASS_OUTLIER, LAS_CLASS_TARGET).astype(np.uint8)
    power = attrs["intensity_w"]
    top = float(power.max(initial=0.0))
    relative = power / top if top > 0 else np.zeros(len(cloud))
    las.intensity = np.round(65535.0 * relative).astype(np.uint16)
    las.return_number = np.ones(len(cloud), np.uint8)
    las.number_of_returns = np.ones(len(cloud), np.uint8)
    with atomic_path(path) as tmp:
        las.write(str(tmp))


def read_las(path: str | Path) -> PointCloud:
    """Read a LAS written by :func:`write_las` back into a PointCloud.

    The coordinates come back rounded to the file's scale (0.1 mm, see write_las); every attribute
    comes back exactly.
    """
    import laspy  # noqa: PLC0415

    las = laspy.read(str(path))
    names = set(las.point_format.extra_dimension_names)
    missing = [n for n, _ in ATTRIBUTES if n not in names]
    if missing:
        raise ValueError(f"{path}: not an lmapd-sim LAS, no dimension {', '.join(missing)}")
    points = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    attrs = {n: np.asarray(las[n]).astype(t) for n, t in ATTRIBUTES}
    attrs |= {
        n: np.asarray(las[n]) for n in las.point_format.extra_dimension_names if n not in attrs
    }
    return PointCloud(points=points.astype(np.float64), attributes=attrs)


# ----------------------------------------------------------------------------------------------
# point clouds and waveform cubes by suffix
# ----------------------------------------------------------------------------------------------
def _suffix(path: str | Path, suffixes: tuple[str, ...], what: str) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in suffixes:
        raise ValueError(f"{path}: unsupported {what} format; use {' or '.join(suffixes)}")
    return suffix


def write_cloud(path: str | Path, cloud: PointCloud, comments: tuple[str, ...] = ()) -> None:
    """Write a point cloud in the format of the file's suffix (CLOUD_SUFFIXES: .ply, .las).

    ``comments`` go into the PLY header or the LAS comments VLR. Raises ValueError for another
    suffix. Written atomically.
    """
    suffix = _suffix(path, CLOUD_SUFFIXES, "point cloud")
    (write_ply if suffix == ".ply" else write_las)(path, cloud, comments)


def read_cloud(path: str | Path) -> PointCloud:
    """Read a point cloud written by :func:`write_cloud` (.ply or .las)."""
    suffix = _suffix(path, CLOUD_SUFFIXES, "point cloud")
    return read_ply(path) if suffix == ".ply" else read_las(path)


def read_cloud_comments(path: str | Path) -> tuple[str, ...]:
    """The comment lines of a point cloud file: the PLY header comments or the LAS VLR's lines."""
    if _suffix(path, CLOUD_SUFFIXES, "point cloud") == ".ply":
        return tuple(PlyData.read(str(path)).comments)
    import laspy  # noqa: PLC0415

    with laspy.open(str(path)) as reader:
        for vlr in reader.header.vlrs:
            if vlr.user_id == _LAS_VLR_USER and vlr.record_id == _LAS_VLR_COMMENTS:
                return tuple(vlr.record_data.decode("utf-8").split("\n"))
    return ()


WAVEFORM_SUFFIXES = (".npz", ".h5", ".hdf5")  # waveform cube formats, chosen by the suffix
_WAVEFORM_UNITS = {
    "row": "px",
    "col": "px",
    "t0_s": "s",
    "dt_s": "s",
    "power_w": "W",
    "filtered_w": "W",
    "t_half_s": "s",
    "range_m": "m",
    "reference_t_half_s": "s",
}


def write_waveforms_hdf5(path: str | Path, result) -> None:
    """The waveform cube (:func:`waveform_cube`) as HDF5: one dataset per entry, gzip-compressed.

    Every dataset carries a ``units`` attribute; scalars (dt_s, reference_t_half_s) are 0-d
    datasets. Written atomically.
    """
    import h5py  # noqa: PLC0415  (only for HDF5 files)

    from ._version import __version__  # noqa: PLC0415

    cube = waveform_cube(result)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["generating_software"] = f"lmapd-sim {__version__}"
            f.attrs["layout"] = "lit pixels x time; t = t0_s[i] + dt_s * j"
            for name, value in cube.items():
                arr = np.asarray(value)
                opts = {"compression": "gzip", "shuffle": True} if arr.ndim else {}
                ds = f.create_dataset(name, data=arr, **opts)
                ds.attrs["units"] = _WAVEFORM_UNITS.get(name, "")


def write_waveforms(path: str | Path, result) -> None:
    """The waveform cube of ``result`` as NPZ or HDF5, by suffix (WAVEFORM_SUFFIXES)."""
    suffix = _suffix(path, WAVEFORM_SUFFIXES, "waveform")
    (write_waveforms_npz if suffix == ".npz" else write_waveforms_hdf5)(path, result)


def read_waveforms(path: str | Path) -> dict[str, np.ndarray]:
    """Read a waveform cube written by :func:`write_waveforms`: the dict of :func:`waveform_cube`
    (scalars as numpy scalars)."""
    if _suffix(path, WAVEFORM_SUFFIXES, "waveform") == ".npz":
        with np.load(path) as data:
            return {k: data[k][()] if data[k].ndim == 0 else data[k] for k in data.files}
    import h5py  # noqa: PLC0415

    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in f.keys()}


__all__ = [
    "CLOUD_SUFFIXES",
    "LAS_CLASS_OUTLIER",
    "LAS_CLASS_TARGET",
    "LAS_SCALE_M",
    "WAVEFORM_SUFFIXES",
    "atomic_path",
    "read_cloud",
    "read_cloud_comments",
    "read_las",
    "read_ply",
    "read_waveforms",
    "waveform_cube",
    "write_cloud",
    "write_json",
    "write_las",
    "write_ply",
    "write_waveforms",
    "write_waveforms_hdf5",
    "write_waveforms_npz",
]
