"""UI controls (display units) to a simcore Scene (SI units) and back."""

from __future__ import annotations

import simcore
from app.state import Controls
from simcore.target import with_materials


def scene_overrides(controls: Controls) -> dict[str, object]:
    """The ``simcore.with_overrides`` mapping of the controls: quick names in SI units."""
    return {
        "pitch_deg": float(controls.pitch_deg),
        "azimuth_deg": float(controls.azimuth_deg),
        "distance_m": float(controls.distance_m),
        "pixels": int(controls.pixels),
        "pulse_energy_j": float(controls.pulse_energy_mj) * 1e-3,
        "tnr": float(controls.tnr),
        "seed": int(controls.seed),
        "fidelity.subrays": int(controls.subrays),
        "target.materials": dict(controls.materials),
    }


def scene_from_controls(base: simcore.Scene, controls: Controls) -> simcore.Scene:
    """``base`` with the controls applied. Raises simcore.SceneError (a ValueError) naming the key
    if a value is invalid for the core."""
    return simcore.with_overrides(base, scene_overrides(controls))


def resolved_materials(model: simcore.TargetModel, scene: simcore.Scene) -> dict[str, str]:
    """The material of every part of ``model`` once the scene's ``target.materials`` overrides
    (including ``*`` for all parts) are applied. Raises simcore.TargetError for an unknown part
    or material."""
    resolved = with_materials(model, scene.target.materials)
    return dict(zip(resolved.part_names, resolved.part_materials, strict=True))
