"""UI controls (display units) to a simcore Scene (SI units) and back."""

from __future__ import annotations

import simcore
from app.state import Controls, controls_from_scene, receiver_controls
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
        **fidelity_overrides(controls),
        "target.materials": dict(controls.materials),
        "sun.mode": controls.sun_mode,
        "sun.azimuth_deg": float(controls.sun_azimuth_deg),
        "sun.elevation_deg": float(controls.sun_elevation_deg),
        "receive.filter_width_m": float(controls.filter_width_nm) * 1e-9,
        "receiver.kind": controls.receiver_kind,
        **receiver_overrides(controls),
    }


def receiver_overrides(controls: Controls) -> dict[str, object]:
    """Every registered receiver's controls as scene keys (their declarations': display units
    times the control's scale; whole numbers stay whole)."""
    out: dict[str, object] = {}
    for name, control in receiver_controls().items():
        value = getattr(controls, name)
        if control.integer:
            out[control.key] = int(value)
        else:
            out[control.key] = (
                float(value) * control.scale if control.scale != 1.0 else float(value)
            )
    return out


def fidelity_overrides(controls: Controls) -> dict[str, object]:
    """A core preset by name, or (``custom``) the scene's fidelity with the chosen sub-rays."""
    if controls.preset in simcore.PRESETS:
        return {"preset": controls.preset}
    return {"fidelity.subrays": int(controls.subrays)}


def preset_text(name: str) -> str:
    """What a fidelity preset sets, in words with units (for the page's tooltips and hints)."""
    knobs = simcore.PRESETS[name]
    subrays = knobs["fidelity.subrays"]
    text = f"{subrays} sub-ray{'s' if subrays > 1 else ''} per pixel"
    refine = knobs.get("fidelity.refine_subrays", 0)
    if refine:
        step_cm = knobs.get("fidelity.refine_step_m", 0.0) * 100
        text += f", {refine} on mixed pixels (edges, depth steps > {step_cm:g} cm"
        text += ", found with pixel-corner rays)" if knobs.get("fidelity.probe_corners") else ")"
    else:
        text += ", no refinement"
    if knobs.get("fidelity.cell_spread"):
        text += ", each ray spread over its cell's depth"
    if knobs.get("fidelity.merge_window"):
        text += ", close sub-ray echoes merged"
    step_s = knobs.get("fidelity.time_step_s", 0.0)
    text += f", time step {step_s * 1e12:g} ps" if step_s else ", time step auto"
    return text


def scene_from_controls(base: simcore.Scene, controls: Controls) -> simcore.Scene:
    """``base`` with the controls applied. Raises simcore.SceneError (a ValueError) naming the key
    if a value is invalid for the core."""
    return simcore.with_overrides(base, scene_overrides(controls))


def first_scene(base: simcore.Scene, model: simcore.TargetModel) -> simcore.Scene:
    """The scene of the app's first frame on ``base`` (``model``: its target): ``base`` with the
    controls a page starts with (the fidelity preset's, not the scene file's own fidelity)."""
    controls, _messages = controls_from_scene(base, resolved_materials(model, base))
    return scene_from_controls(base, controls)


def resolved_materials(model: simcore.TargetModel, scene: simcore.Scene) -> dict[str, str]:
    """The material of every part of ``model`` once the scene's ``target.materials`` overrides
    (including ``*`` for all parts) are applied. Raises simcore.TargetError for an unknown part
    or material."""
    resolved = with_materials(model, scene.target.materials)
    return dict(zip(resolved.part_names, resolved.part_materials, strict=True))
