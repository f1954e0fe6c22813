"""One ``lmapd reproduce`` run: its output folder, settings, shared pipeline and progress bar."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from ... import io, orbit
from ...pipeline import Pipeline, Result
from ...reproduce import (
    FLYAROUND_FRAMES_S,
    PAPER_PERIOD_S,
    RESOLUTION_DISTANCES_M,
    RESOLUTION_PIXELS,
    ReproduceSettings,
    mc_tnr_grid,
)
from ...scene import PAPER_FORMS, Scene, load_scene, with_overrides


class ReproduceRun:
    """One reproduction: output folder, settings, the shared pipeline and the progress bar."""

    def __init__(self, out: Path, settings: ReproduceSettings, total_steps: int, progress: bool):
        self.out = out
        self.settings = settings
        self.pipeline = Pipeline()
        self.bar = tqdm(
            total=total_steps, desc="reproduce", unit="step", file=sys.stderr, disable=not progress
        )

    def step(self, label: str) -> None:
        self.bar.set_postfix_str(label, refresh=False)
        self.bar.update()

    def scene(self, overrides: dict[str, Any] | None = None) -> Scene:
        """The paper scene with the run's seed and ``overrides``."""
        overrides = {"seed": self.settings.seed, **(overrides or {})}
        return with_overrides(load_scene("paper"), overrides)

    def run(self, scene: Scene) -> Result:
        return self.pipeline.run(scene)

    def rng(self, *stream: int) -> np.random.Generator:
        return np.random.default_rng([self.settings.seed, *stream])

    def save(self, fig, name: str) -> str:
        with io.atomic_path(self.out / name) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
        return name


def total_steps(s: ReproduceSettings) -> int:
    n_tnr = len(mc_tnr_grid(s))
    n_frames = len(orbit.flyaround_times(s.flyaround_interval_s, PAPER_PERIOD_S))
    return (
        1  # brdf
        + n_tnr
        + len(s.mc_fa_tnrs)
        + 1  # detection
        + 2  # waveforms
        + 2 * len(s.attitude_steps_deg)
        + 2  # attitude
        + len(RESOLUTION_DISTANCES_M) * len(RESOLUTION_PIXELS)
        + 1  # resolution
        + n_frames
        + len(FLYAROUND_FRAMES_S)
        + 2  # flyaround
        + len(PAPER_FORMS)
        + 3  # conventions
        + 4  # daylight: three cases and the figure
    )
