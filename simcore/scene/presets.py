"""The fidelity presets (``preset = "interactive"``): the keys each sets."""

from __future__ import annotations

from typing import Any

# Fidelity presets: the knobs each sets (explicit keys given with it take precedence).
# The echo timing is refined on exact values, so the time step mostly matters for resolving close
# double peaks; the sub-rays per pixel decide how well each pixel's depth profile is sampled.
PRESETS: dict[str, dict[str, Any]] = {
    # one sub-ray per pixel; pixels that one ray cannot represent (silhouettes, depth steps)
    # are re-cast with the reference's 64
    "interactive": {
        "fidelity.subrays": 1,
        "fidelity.refine_subrays": 64,
        "fidelity.refine_step_m": 0.02,
        "fidelity.probe_corners": True,
        "fidelity.cell_spread": True,
        "fidelity.merge_window": 0.25,
        "fidelity.time_step_s": 0.0,
    },
    "balanced": {
        "fidelity.subrays": 1,
        "fidelity.refine_subrays": 64,
        "fidelity.refine_step_m": 0.01,
        "fidelity.probe_corners": True,
        "fidelity.cell_spread": True,
        "fidelity.merge_window": 0.25,
        "fidelity.time_step_s": 0.0,
    },
    # every pixel sampled by 8 x 8 sub-rays, a finer time grid
    "reference": {
        "fidelity.subrays": 64,
        "fidelity.refine_subrays": 0,
        "fidelity.refine_step_m": 0.02,
        "fidelity.probe_corners": False,
        "fidelity.cell_spread": False,
        "fidelity.merge_window": 0.0,
        "fidelity.time_step_s": 1e-10,
    },
}
