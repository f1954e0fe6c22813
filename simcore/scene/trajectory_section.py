"""The scene's ``[trajectory]`` section: the relative motion of a fly-around (orbit, approach or
hold) and the target's tumble (``simcore.trajectory`` poses the frames; docs/trajectories.md)."""

from __future__ import annotations

from dataclasses import dataclass

from .fields import key

__all__ = ["MAX_TRAJECTORY_FRAMES", "Trajectory"]

# The most frames a trajectory may make (frame_rate_hz x duration_s + 1): a mistyped rate must not
# start a night of imaging (10k frames of 256 x 256 px ~ 20 GB of PLY); = the CLI's MAX_FRAMES.
MAX_TRAJECTORY_FRAMES = 10_000


@dataclass(frozen=True)
class Trajectory:
    kind: str = key(
        "orbit",
        "-",
        doc="the fly-around's relative motion: orbit (the Table 3 orbits or the two TLEs, frames "
        "every --interval-s), approach (along the line of sight from start_range_m to "
        "end_range_m over duration_s) or hold (at start_range_m); a tumble goes on top of each",
        choices=("orbit", "approach", "hold"),
    )
    start_range_m: float = key(
        2000.0,
        "m",
        0.0,
        1e6,
        "approach and hold: range to the target's centre at t = 0",
        lo_open=True,
    )
    end_range_m: float = key(
        20.0,
        "m",
        0.0,
        1e6,
        "approach: range at t = duration_s (linear in time); must stay outside the target",
        lo_open=True,
    )
    duration_s: float = key(
        60.0, "s", 0.0, 1e6, "approach and hold: length of the trajectory", lo_open=True
    )
    frame_rate_hz: float = key(
        1.0,
        "Hz",
        0.0,
        1000.0,
        "approach and hold: frames per second (frames at 0, 1/rate, ... <= duration_s; "
        f"at most {MAX_TRAJECTORY_FRAMES} frames)",
        lo_open=True,
    )
    tumble_rate_deg_s: float = key(
        0.0,
        "deg/s",
        -360.0,
        360.0,
        "the target's spin about tumble_axis (right hand), on top of the trajectory's attitude",
    )
    tumble_axis: tuple[float, ...] = key(
        (0.0, 0.0, 1.0),
        "1",
        -1e6,
        1e6,
        "the tumble's axis in the target body frame (x, y, z; normalised, not zero)",
    )
    initial_quaternion_wxyz: tuple[float, ...] = key(
        (1.0, 0.0, 0.0, 0.0),
        "1",
        -1e6,
        1e6,
        "the target's attitude at t = 0 relative to the trajectory's (approach, hold: the "
        "sensor frame; orbit: the target's LVLH frame); w, x, y, z, normalised",
    )
