"""lmapd-sim: space-based LM-APD flash-lidar imaging (Wang et al., Electronics 2023, 12, 2261).

Public API (re-exports only)::

    import simcore
    result = simcore.simulate(pitch_deg=20, pixels=128)
    result.points, result.attributes, result.waveform(64, 64), result.summary()

The names below load on first use (PEP 562), so that ``import simcore`` alone, and the ``lmapd``
command's ``--help`` and ``keys``, do not pay for the imaging chain's imports. The library loads
numpy, scipy, trimesh and embreex; matplotlib, Dask, pyarrow, h5py and laspy load only inside the
functions that need them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__ as __version__

if TYPE_CHECKING:  # for type checkers and IDEs: the names as if imported eagerly
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

# public name -> (module, name in that module)
_EXPORTS = {
    "MATERIALS": ("materials", "LIBRARY"),
    "MATERIAL_NAMES": ("materials", "MATERIAL_NAMES"),
    "Material": ("materials", "Material"),
    "brdf": ("materials", "brdf"),
    "set_threads": ("parallel", "set_threads"),
    "STAGES": ("pipeline", "STAGES"),
    "Cancelled": ("pipeline", "Cancelled"),
    "Pipeline": ("pipeline", "Pipeline"),
    "Result": ("pipeline", "Result"),
    "Waveform": ("pipeline", "Waveform"),
    "simulate": ("pipeline", "simulate"),
    "PAPER_FORMS": ("scene", "PAPER_FORMS"),
    "PRESETS": ("scene", "PRESETS"),
    "QUICK": ("scene", "QUICK"),
    "Scene": ("scene", "Scene"),
    "SceneError": ("scene", "SceneError"),
    "dump_scene": ("scene", "dump_scene"),
    "key_reference": ("scene", "key_reference"),
    "load_scene": ("scene", "load_scene"),
    "with_overrides": ("scene", "with_overrides"),
    "TargetError": ("target", "TargetError"),
    "TargetModel": ("target", "TargetModel"),
    "load_target": ("target", "load_target"),
}

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
]  # = the keys of _EXPORTS (a test checks)


def __getattr__(name: str) -> Any:
    """A public name (imported from its module on first use) or a submodule (``simcore.io``)."""
    if name in _EXPORTS:
        module, attr = _EXPORTS[name]
        value = getattr(importlib.import_module(f"{__name__}.{module}"), attr)
        globals()[name] = value  # the next access is a plain attribute
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise  # the submodule exists but one of its own imports failed
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
