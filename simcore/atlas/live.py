"""An atlas drawn coarse to fine, for a live view: nested grids (each step half the last, so a
finer grid holds every point of the coarser and only the new ones run), the rows so far after
each level, stoppable between attitudes."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from ..pipeline import Pipeline
from ..scene import Scene, with_overrides
from ..stage import Cancelled
from .frame import attitude_row
from .grid import AtlasError, AttitudeGrid, attitude_grid

LIVE_LEVELS_DEG = (45.0, 22.5, 11.25)  # [deg] 26, then 114, then 482 attitudes


@dataclass(frozen=True)
class Level:
    """One level done: its grid, and the rows of every attitude of it, (pitch_deg,
    azimuth_deg) -> the atlas row (simcore.atlas.frame.COLUMNS)."""

    grid: AttitudeGrid
    rows: dict[tuple[float, float], dict[str, Any]]
    n_run: int  # attitudes run for this level (the rest came from the coarser ones)


def map_levels(
    scene: Scene,
    levels_deg: tuple[float, ...] = LIVE_LEVELS_DEG,
    pipeline: Pipeline | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> Iterator[Level]:
    """Yield each level of the map of ``scene`` over every attitude, coarse to fine.

    ``levels_deg`` must each halve the last (nested grids). ``pipeline``: the Pipeline the
    frames run through (a fresh one by default; give one that adopted a loaded target to skip
    loading it). ``should_stop`` is asked before every attitude: True raises
    :class:`simcore.stage.Cancelled`.

    Raises
    ------
    AtlasError
        Levels that are not nested, or a scene whose attitude is a quaternion.
    """
    if scene.pose.quaternion_wxyz:
        raise AtlasError("the scene fixes its attitude with pose.quaternion_wxyz")
    for coarse, fine in zip(levels_deg, levels_deg[1:], strict=False):
        if abs(coarse / fine - 2.0) > 1e-9:
            raise AtlasError(f"map levels {levels_deg}: each step must be half the last")
    pipe = pipeline or Pipeline()
    rows: dict[tuple[float, float], dict[str, Any]] = {}
    for step in levels_deg:
        grid = attitude_grid(step)
        n_run = 0
        for attitude in grid.attitudes():
            if attitude in rows:
                continue
            if should_stop is not None and should_stop():
                raise Cancelled("the attitude map was stopped")
            pitch, azimuth = attitude
            frame = with_overrides(scene, pitch_deg=pitch, azimuth_deg=azimuth)
            rows[attitude] = attitude_row(pipe.run(frame, should_stop=should_stop))
            n_run += 1
        yield Level(grid, {a: rows[a] for a in grid.attitudes()}, n_run)
