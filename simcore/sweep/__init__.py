"""Sweeps: many frames over a grid or a list of scene keys, each frame a task on Dask distributed.

    sweep = load_sweep("study.toml")             # or build_sweep(base=..., grid=...)
    report = run_sweep(sweep, "out/study")       # the command: lmapd sweep SWEEP.toml --out DIR

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

The package's modules follow those steps: ``spec`` (the file and its frames), ``frames`` (one frame
on a worker), ``run`` (the runners, the row files) and ``table`` (Parquet). Dask and pyarrow are
imported inside the functions that use them.
"""

from .frames import FrameOutcome, frame_metrics, run_frame, warm_workers
from .run import SweepReport, run_sweep
from .spec import (
    CONNECT_TIMEOUT_S,
    METRICS,
    TABLE_NAME,
    Frame,
    Sweep,
    SweepError,
    build_sweep,
    frame_id,
    load_sweep,
    sweep_from_dict,
)
from .table import read_table

__all__ = [
    "CONNECT_TIMEOUT_S",
    "METRICS",
    "TABLE_NAME",
    "Frame",
    "FrameOutcome",
    "Sweep",
    "SweepError",
    "SweepReport",
    "build_sweep",
    "frame_id",
    "frame_metrics",
    "load_sweep",
    "read_table",
    "run_frame",
    "run_sweep",
    "sweep_from_dict",
    "warm_workers",
]
