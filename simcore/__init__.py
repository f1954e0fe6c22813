"""lmapd-sim: space-based LM-APD flash-lidar imaging (Wang et al., Electronics 2023, 12, 2261).

Public API (re-exports only)::

    import simcore
    result = simcore.simulate(pitch_deg=20, pixels=128)
    result.points, result.attributes, result.waveform(64, 64), result.summary()
"""

from .materials import LIBRARY as MATERIALS
from .materials import MATERIAL_NAMES, Material, brdf
from .parallel import set_threads
from .pipeline import STAGES, Cancelled, Pipeline, Result, Waveform, simulate
from .scene import (
    PAPER_FORMS,
    PRESETS,
    QUICK,
    Scene,
    SceneError,
    dump_scene,
    key_reference,
    load_scene,
    with_overrides,
)
from .target import TargetError, TargetModel, load_target

__version__ = "0.1.0"

__all__ = [
    "Cancelled",
    "MATERIALS",
    "MATERIAL_NAMES",
    "PAPER_FORMS",
    "PRESETS",
    "QUICK",
    "STAGES",
    "Material",
    "Pipeline",
    "Result",
    "Scene",
    "SceneError",
    "TargetError",
    "TargetModel",
    "Waveform",
    "brdf",
    "dump_scene",
    "key_reference",
    "load_scene",
    "load_target",
    "set_threads",
    "simulate",
    "with_overrides",
]
