"""The receiver and detection stages: the scene's receiver (``receiver.kind``, found in the
registry, :mod:`simcore.plugins.registry`), its two steps, the range gate they share, and the
stages' cache keys (``receiver.kind`` and the scene values the selected receiver declares it
reads)."""

from __future__ import annotations

from dataclasses import fields, replace
from typing import TYPE_CHECKING

import numpy as np

from ..plugins.declaration import resolve
from ..plugins.registry import get, section_of
from ..stage import Stage, readonly
from .records import Detection, Response

if TYPE_CHECKING:
    from ..background import Background
    from ..echo import EchoStage
    from ..scene import Scene


# ----------------------------------------------------------------------------------------------
# the receiver and detection stages: the scene's receiver, its two steps
# ----------------------------------------------------------------------------------------------
def _response_reads(scene: Scene) -> tuple:
    return (scene.receiver.kind, resolve(get(scene.receiver.kind).response_reads)(scene))


def _detection_reads(scene: Scene) -> tuple:
    reads = resolve(get(scene.receiver.kind).detection_reads)(scene)
    return (scene.receiver.kind, reads, ignored_keys(scene))


def stage_receiver(scene: Scene, echo: EchoStage, background: Background) -> Response:
    return _readonly_arrays(resolve(get(scene.receiver.kind).respond)(scene, echo, background))


def stage_detection(scene: Scene, echo: EchoStage, response: Response) -> Detection:
    detection = resolve(get(scene.receiver.kind).detect)(scene, echo, response)
    return _readonly_arrays(with_ignored_keys(scene, outside_the_gate(scene, detection)))


def ignored_keys(scene: Scene) -> tuple[str, ...]:
    """The keys set (to other than their defaults) in another receiver's section than the
    selected one's (``gm.pulses`` with ``receiver.kind = lm_apd``): the frame ignores them."""
    names = []
    for name, keys in scene.receiver_sections:
        owner = section_of(name)
        if owner is None or owner.kind == scene.receiver.kind:
            continue
        default = type(keys)()
        names += [
            f"{name}.{f.name}"
            for f in fields(keys)
            if getattr(keys, f.name) != getattr(default, f.name)
        ]
    return tuple(names)


def with_ignored_keys(scene: Scene, detection: Detection) -> Detection:
    """``detection`` with a summary warning naming the keys :func:`ignored_keys` finds."""
    names = ignored_keys(scene)
    if not names:
        return detection
    owners = sorted({section_of(n.split(".")[0]).kind for n in names})  # type: ignore[union-attr]
    figures = dict(detection.summary_figures)
    figures["warnings"] = [
        *figures.get("warnings", []),
        f"{', '.join(names)} set for receiver.kind = {' / '.join(owners)}: receiver.kind = "
        f"{scene.receiver.kind} ignores {'it' if len(names) == 1 else 'them'}",
    ]
    return replace(detection, summary_figures=figures)


def gate_m(scene: Scene) -> tuple[float, float]:
    """The range gate [R_st - R_gate / 2, R_st + R_gate / 2], clipped at 0 [m]."""
    half = 0.5 * scene.timing.range_gate_m
    return max(0.0, scene.gate_center_m - half), scene.gate_center_m + half


def outside_the_gate(scene: Scene, detection: Detection) -> Detection:
    """``detection`` with P_d = 0 for every lit pixel whose noise-free range lies outside the
    range gate (its echo cannot give a point, whatever its SNR), and a summary warning (one
    line under ``warnings``) saying how many and where the target is. Unchanged if none."""
    lo, hi = gate_m(scene)
    r = np.asarray(detection.range_true_m)
    out = (r < lo) | (r > hi)
    if not out.any():
        return detection
    figures = dict(detection.summary_figures)
    figures["warnings"] = [
        *figures.get("warnings", []),
        f"{int(out.sum())} of {len(r)} lit pixels see the target at {np.min(r[out]):.4g}-"
        f"{np.max(r[out]):.4g} m, outside the range gate [{lo:.4g}, {hi:.4g}] m: no point "
        "from them (P_d 0); move timing.gate_center_m or lengthen timing.range_gate_m",
    ]
    return replace(
        detection,
        p_detect=np.where(out, 0.0, detection.p_detect),
        summary_figures=figures,
    )


def _readonly_arrays(record):
    """``record`` with its array fields made read-only (stage outputs are cached and shared)."""
    readonly(*(getattr(record, f.name) for f in fields(record)))
    return record


RECEIVER = Stage(
    name="receiver",
    upstream=("echo", "background"),
    reads=_response_reads,
    compute=stage_receiver,
)
DETECTION = Stage(
    name="detection",
    upstream=("echo", "receiver"),
    reads=_detection_reads,
    compute=stage_detection,
)
