"""Draw the frames of a fly-around's ground truth (docs/img/frames.png, docs/trajectories.md):
the lidar's sensor frame, the target's body frame at a tumbling pose, and T_sensor_target.

    PYTHONPATH=$PWD python scripts/plot_frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent


def axes(ax, origin, rotation, length, label, colours=("C3", "C2", "C0")) -> None:
    """Draw the three axes (columns of ``rotation``) of a frame at ``origin``."""
    for k, (name, colour) in enumerate(zip("xyz", colours, strict=True)):
        tip = origin + length * rotation[:, k]
        ax.quiver(*origin, *(tip - origin), color=colour, arrow_length_ratio=0.15, lw=2)
        ax.text(*(origin + 1.12 * length * rotation[:, k]), f"{name}", color=colour, fontsize=10)
    ax.text(*(origin - 0.35 * length * np.ones(3)), label, fontsize=10)


def main(out: Path) -> None:
    fig = Figure(figsize=(7.0, 5.5), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    sensor = np.eye(3)
    target_at = np.array([0.0, 0.0, 10.0])  # the target's centre on the boresight
    turned = Rotation.from_rotvec(np.radians(35.0) * np.array([1.0, -2.0, 2.0]) / 3.0)
    axes(ax, np.zeros(3), sensor, 3.0, "sensor (lidar)\nx right, y down, z boresight")
    axes(ax, target_at, turned.as_matrix(), 2.5, "target (body)")
    ax.plot(*np.stack([np.zeros(3), target_at]).T, "k--", lw=1)
    ax.text(0.3, 0.0, 5.5, "t = (0, 0, range)\nT_sensor_target = [R(q) | t]", fontsize=9)
    ax.set_xlim(-4, 4)
    ax.set_ylim(-4, 4)
    ax.set_zlim(-1, 13)
    ax.view_init(elev=-150, azim=-60)  # y down as in the image
    ax.set_box_aspect((1, 1, 1.6))
    ax.set_axis_off()
    fig.suptitle(
        "Ground-truth frames: p_sensor = R(q) p_target + t (Hamilton, w first, active)",
        fontsize=10,
    )
    fig.savefig(out, dpi=100)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "img" / "frames.png")
