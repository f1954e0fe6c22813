"""Downloads from the page: the frame's point cloud (PLY or LAS), the selected pixels' waveforms
(CSV, units in the header) and the scene (TOML) that gives the same frame with
``lmapd simulate``.

Each is built in memory from the frame the page shows; the point-cloud writers of ``simcore.io``
write to a private temporary directory (mode 0700) that is removed at once, so nothing is left on
the server's disk and no name from the page is ever used as a path.
"""

from __future__ import annotations

import csv
import io
import tempfile
from pathlib import Path

import numpy as np

import simcore
from simcore import io as simcore_io

CLOUD_FORMATS = ("ply", "las")
WAVEFORM_COLUMNS = (
    "row",
    "col",
    "time_s",
    "power_w",
    "filtered_w",
    "threshold_w",
    "range_m",
    "detected",
)


class ExportError(ValueError):
    """A download that cannot be made; the message is shown on the page as it is."""


def cloud_file(result: simcore.Result, fmt: object) -> bytes:
    """The frame's point cloud in ``fmt`` ("ply" or "las"), with its provenance in the
    comments."""
    if fmt not in CLOUD_FORMATS:
        raise ExportError(f"point clouds download as {' or '.join(CLOUD_FORMATS)}")
    with tempfile.TemporaryDirectory(prefix="lmapd-export-") as folder:
        path = Path(folder) / f"cloud.{fmt}"
        simcore_io.write_cloud(path, result.cloud, comments=provenance(result))
        return path.read_bytes()


def waveforms_csv(result: simcore.Result, pixels: list) -> str:
    """The waveforms of the selected ``pixels`` ((row, col) pairs) as CSV text: one line per
    sample, every column's unit in its name; a pixel with no echo gives one line with
    empty samples."""
    if not pixels:
        raise ExportError("select a pixel on the detector array first")
    out = io.StringIO()
    out.write("".join(f"# {line}\n" for line in provenance(result)))
    table = csv.writer(out, lineterminator="\n")
    table.writerow(WAVEFORM_COLUMNS)
    for row, col in pixels:
        w = result.waveform(int(row), int(col))
        fixed = [_num(w.threshold_w), _num(w.range_m), int(bool(w.detected))]
        if len(w.t_s) == 0:
            table.writerow([w.row, w.col, "", "", "", *fixed])
        for t, p, y in zip(w.t_s, w.power_w, w.filtered_w, strict=True):
            table.writerow([w.row, w.col, _num(t), _num(p), _num(y), *fixed])
    return out.getvalue()


def scene_toml(result: simcore.Result) -> str:
    """The frame's scene as TOML text: ``lmapd simulate`` of it gives the same points."""
    header = "".join(f"# {line}\n" for line in provenance(result)[1:3])
    header += "# the same frame: lmapd simulate THIS_FILE.toml --out cloud.ply\n"
    return header + simcore.dump_scene(result.scene)


def provenance(result: simcore.Result) -> tuple[str, ...]:
    """Comment lines naming what made the file, the frame and target (with its credit: NASA's
    for a NASA model), as ``lmapd simulate`` writes them."""
    target = result.target
    return (
        "lmapd-sim app: point cloud in the sensor frame (x right, y down, z boresight), metres",
        f"scene {result.scene.name}, seed {result.scene.seed}",
        f"target {target.name}; {target.credit}" if target.credit else f"target {target.name}",
        f"material_id indexes: {' '.join(simcore.MATERIAL_NAMES)}",
    )


def _num(value: float) -> str:
    return "" if not np.isfinite(value) else repr(float(value))
