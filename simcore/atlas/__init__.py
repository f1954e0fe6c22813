"""Attitude at a glance: imaging quality over every view direction of the target.

``build_atlas(scene, step_deg=10)`` makes one frame per attitude of a pole-to-pole grid of pitch
and azimuth (:mod:`.grid`), ``run_atlas(atlas, DIR)`` runs them (in this process or on Dask, one
target and BVH per worker; resumable) and writes the table, the summary, the map and the best and
worst attitudes' scene files (:mod:`.run`); :mod:`.frame` is one attitude's row, :mod:`.figure`
the map. The method and its cost: docs/atlas.md.
"""

from __future__ import annotations

from .frame import COLUMNS, DEFAULT_METRIC, METRICS, attitude_row, metric_values
from .grid import DEFAULT_STEP_DEG, STEP_RANGE_DEG, AtlasError, AttitudeGrid, attitude_grid
from .live import LIVE_LEVELS_DEG, Level, map_levels
from .run import (
    FIGURE_NAME,
    MANIFEST_NAME,
    TABLE_NAME,
    Atlas,
    AtlasReport,
    Requirement,
    build_atlas,
    parse_requirement,
    read_atlas,
    run_atlas,
    summarize,
    weighted_median,
)

__all__ = [
    "COLUMNS",
    "DEFAULT_METRIC",
    "DEFAULT_STEP_DEG",
    "LIVE_LEVELS_DEG",
    "FIGURE_NAME",
    "MANIFEST_NAME",
    "METRICS",
    "STEP_RANGE_DEG",
    "TABLE_NAME",
    "Atlas",
    "AtlasError",
    "AtlasReport",
    "AttitudeGrid",
    "Level",
    "Requirement",
    "attitude_grid",
    "attitude_row",
    "build_atlas",
    "map_levels",
    "metric_values",
    "parse_requirement",
    "read_atlas",
    "run_atlas",
    "summarize",
    "weighted_median",
]
