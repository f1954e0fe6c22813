"""The attitudes of an atlas: a latitude-longitude grid of (pitch, azimuth) over the sphere of
view directions, each with the solid angle it stands for.

Pitch is the latitude (-90 to 90 deg) and azimuth the longitude (0 to 360 deg) of the line of
sight about the target: with no roll, ``R = Rx(pitch) Ry(azimuth) R0`` (``simcore.geometry.
target_pose``), the direction from the target to the lidar in the front view's frame is
``(-sin(az) cos(pitch), sin(pitch), cos(az) cos(pitch))`` up to R0, so every direction is one
(pitch, azimuth), the poles (pitch = +-90 deg) one each. The grid is in the sliders' own
coordinates, so that a cell is a pose ``lmapd simulate --set pitch_deg=.. --set azimuth_deg=..``
reproduces exactly and the app moves its sliders to; its cells are not of equal area, so every
share and median over the sphere weighs each grid point by the solid angle of its cell (the
weights add up to 4 pi sr), and the map is drawn in an equal-area projection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STEP_RANGE_DEG = (1.0, 90.0)  # [deg] the grid steps --step-deg accepts
DEFAULT_STEP_DEG = 10.0  # [deg]


class AtlasError(ValueError):
    """An atlas that cannot be built or run as asked; the message names the option."""


@dataclass(frozen=True)
class AttitudeGrid:
    """The grid of attitudes, pole to pole.

    Attributes
    ----------
    step_deg : float
        The step asked for [deg].
    pitch_deg : (n_rows,) float64
        The rows' pitch, -90 to 90 inclusive [deg]: 180 / step_deg rounded, the poles included.
    n_azimuth : int
        Points in each row but the poles' (one each): 360 / step_deg rounded.
    """

    step_deg: float
    pitch_deg: np.ndarray
    n_azimuth: int

    @property
    def pitch_step_deg(self) -> float:
        """The rows' spacing [deg] (step_deg rounded so that it divides 180)."""
        return 180.0 / (len(self.pitch_deg) - 1)

    @property
    def azimuth_step_deg(self) -> float:
        """The columns' spacing [deg] (step_deg rounded so that it divides 360)."""
        return 360.0 / self.n_azimuth

    def attitudes(self) -> list[tuple[float, float]]:
        """Every (pitch_deg, azimuth_deg) of the grid, south pole first, each row by azimuth from
        0; a pole once, at azimuth 0."""
        out: list[tuple[float, float]] = []
        for pitch in self.pitch_deg:
            if abs(pitch) == 90.0:
                out.append((float(pitch), 0.0))
                continue
            out += [
                (float(pitch), _rounded(k * self.azimuth_step_deg)) for k in range(self.n_azimuth)
            ]
        return out

    def __len__(self) -> int:
        return 2 + (len(self.pitch_deg) - 2) * self.n_azimuth

    def solid_angle_sr(self, pitch_deg: float) -> float:
        """The solid angle of the cell of a grid point at ``pitch_deg`` [sr]: its band of
        latitude (half a row either side, a cap at a pole) shared by the row's points."""
        half = math.radians(self.pitch_step_deg) / 2.0
        p = math.radians(pitch_deg)
        if abs(pitch_deg) == 90.0:
            return 2.0 * math.pi * (1.0 - math.cos(half))
        band = math.sin(min(p + half, math.pi / 2)) - math.sin(max(p - half, -math.pi / 2))
        return 2.0 * math.pi * band / self.n_azimuth

    def to_dict(self) -> dict:
        return {
            "kind": "latitude-longitude (pitch, azimuth), poles once",
            "step_deg": self.step_deg,
            "pitch_step_deg": self.pitch_step_deg,
            "azimuth_step_deg": self.azimuth_step_deg,
            "n_rows": len(self.pitch_deg),
            "n_azimuth": self.n_azimuth,
            "n_attitudes": len(self),
        }


def attitude_grid(step_deg: float = DEFAULT_STEP_DEG) -> AttitudeGrid:
    """The grid at about ``step_deg`` [deg], 1 to 90: AtlasError outside that."""
    lo, hi = STEP_RANGE_DEG
    if isinstance(step_deg, bool) or not isinstance(step_deg, (int, float)):
        raise AtlasError(f"--step-deg {step_deg!r}: give a number of degrees from {lo:g} to {hi:g}")
    if not (math.isfinite(step_deg) and lo <= step_deg <= hi):
        raise AtlasError(f"--step-deg {step_deg:g}: the grid step must lie in [{lo:g}, {hi:g}] deg")
    n_rows = max(2, round(180.0 / step_deg)) + 1
    pitch = np.array([_rounded(-90.0 + 180.0 * k / (n_rows - 1)) for k in range(n_rows)])
    n_azimuth = max(1, round(360.0 / step_deg))
    return AttitudeGrid(float(step_deg), pitch, n_azimuth)


def _rounded(deg: float) -> float:
    """Degrees to 9 decimals (1/3 * 180 gives 60.0, not 59.99999999999999)."""
    return float(round(deg, 9)) + 0.0
