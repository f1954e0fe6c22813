"""Orbits of the target and the imaging satellite, their attitudes and the relative pose series.

- ``elements``: the Earth's constants, Keplerian elements, the paper's Table 3 orbits, Kepler's
  equation (and the frames this package uses);
- ``propagation``: elements <-> ECI states, two-body or with the secular J2 drift;
- ``attitude``: the target's LVLH attitude, the lidar's tracking attitude, the relative pose
  series of a fly-around and its distances;
- ``epoch`` and ``tle``: the UTC epochs and two-line element sets of a scene, parsed and checked
  (no numpy: the scene's validation reads them).

The public names below load on first use (PEP 562), so that the scene's validation can read the
epoch and TLE modules without loading numpy; ``from simcore.orbit import propagate`` works as
before (docs/physics.md#table-3).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # for type checkers and IDEs: the names as if imported eagerly
    from .attitude import (
        RelativePose,
        distance_stats,
        flyaround_times,
        lvlh_attitude,
        relative_pose_from_states,
        relative_pose_series,
        tracking_attitude,
    )
    from .elements import (
        J2,
        MU_EARTH_M3_S2,
        PAPER_IMAGING,
        PAPER_PERIOD_S,
        PAPER_TARGET,
        R_EARTH_M,
        Elements,
        OrbitError,
        solve_kepler,
    )
    from .propagation import (
        elements_to_state,
        j2_secular_rates_rad_s,
        propagate,
        state_to_elements,
    )

# public name -> the module of this package that defines it
_EXPORTS = {
    "J2": "elements",
    "MU_EARTH_M3_S2": "elements",
    "PAPER_IMAGING": "elements",
    "PAPER_PERIOD_S": "elements",
    "PAPER_TARGET": "elements",
    "R_EARTH_M": "elements",
    "Elements": "elements",
    "OrbitError": "elements",
    "solve_kepler": "elements",
    "elements_to_state": "propagation",
    "j2_secular_rates_rad_s": "propagation",
    "propagate": "propagation",
    "state_to_elements": "propagation",
    "RelativePose": "attitude",
    "distance_stats": "attitude",
    "flyaround_times": "attitude",
    "lvlh_attitude": "attitude",
    "relative_pose_from_states": "attitude",
    "relative_pose_series": "attitude",
    "tracking_attitude": "attitude",
}

__all__ = [
    "J2",
    "MU_EARTH_M3_S2",
    "PAPER_IMAGING",
    "PAPER_PERIOD_S",
    "PAPER_TARGET",
    "R_EARTH_M",
    "Elements",
    "OrbitError",
    "RelativePose",
    "distance_stats",
    "elements_to_state",
    "flyaround_times",
    "j2_secular_rates_rad_s",
    "lvlh_attitude",
    "propagate",
    "relative_pose_from_states",
    "relative_pose_series",
    "solve_kepler",
    "state_to_elements",
    "tracking_attitude",
]  # = the keys of _EXPORTS


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use."""
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value  # the next access is a plain attribute
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
