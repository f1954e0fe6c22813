"""The fly-around's map: the two orbits of Table 3 around the Earth, and the lidar's path around
the target seen from the target (its LVLH frame), with where both are at the frame's time.

The orbits panel is drawn in the target orbit's plane at the epoch (x towards the target at t = 0,
y along its motion) [km]: at that scale the lidar's orbit lies on the target's (they are a few
hundred metres apart), so the lower panel shows the fly-around itself: the lidar relative to the
target, along-track (x of the target's body frame: its direction of motion) against radial
(-z: up, away from the Earth) [m], over the whole orbit.
"""

from __future__ import annotations

import numpy as np

from app.payloads.charts import axis
from simcore import orbit

N_TRACK = 241  # points along one orbit (the first and the last at the same place)
EARTH_COLOR = "#42a5f5"
TARGET_COLOR = "#37474f"
LIDAR_COLOR = "#ef6c00"


def plane_basis(r0_m: np.ndarray, v0_m_s: np.ndarray) -> np.ndarray:
    """(2, 3) the orbit plane's axes in ECI: towards ``r0_m``, then along the motion."""
    x = r0_m / np.linalg.norm(r0_m)
    normal = np.cross(r0_m, v0_m_s)
    y = np.cross(normal / np.linalg.norm(normal), x)
    return np.vstack([x, y])


def relative_lvlh_m(r_tgt: np.ndarray, v_tgt: np.ndarray, r_img: np.ndarray) -> np.ndarray:
    """(n, 3) the lidar's position relative to the target in the target's LVLH (body) frame [m]
    (x along the motion, y minus the orbit normal, z towards the Earth's centre)."""
    body = orbit.lvlh_attitude(r_tgt, v_tgt)  # columns: body axes in ECI
    return np.einsum("nji,nj->ni", body, r_img - r_tgt)


class OrbitMap:
    """The map's figure of one pair of orbits (the tracks computed once per J2 choice)."""

    def __init__(
        self,
        period_s: float = orbit.PAPER_PERIOD_S,
        target: orbit.Elements = orbit.PAPER_TARGET,
        imaging: orbit.Elements = orbit.PAPER_IMAGING,
    ):
        self.period_s = float(period_s)
        self.orbits = (target, imaging)
        self._tracks: dict[bool, dict[str, np.ndarray]] = {}

    def states(self, t_s, j2: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(n, 3) the target's position and velocity and the lidar's position (ECI) at ``t_s``."""
        r_tgt, v_tgt = orbit.propagate(self.orbits[0], t_s, j2=j2)
        r_img, _ = orbit.propagate(self.orbits[1], t_s, j2=j2)
        return np.atleast_2d(r_tgt), np.atleast_2d(v_tgt), np.atleast_2d(r_img)

    def tracks(self, j2: bool) -> dict[str, np.ndarray]:
        """One orbit of both: ``plane`` (2, 3) the panel's axes, ``target_km`` and ``lidar_km``
        (n, 2) in the orbit panel, ``relative_m`` (n, 3) the lidar in the target's LVLH."""
        if j2 not in self._tracks:
            t = np.linspace(0.0, self.period_s, N_TRACK)
            r_tgt, v_tgt, r_img = self.states(t, j2)
            plane = plane_basis(r_tgt[0], v_tgt[0])
            self._tracks[j2] = {
                "plane": plane,
                "target_km": r_tgt @ plane.T / 1e3,
                "lidar_km": r_img @ plane.T / 1e3,
                "relative_m": relative_lvlh_m(r_tgt, v_tgt, r_img),
            }
        return self._tracks[j2]

    def figure(self, t_s: float, j2: bool) -> dict:
        """The plotly figure at frame time ``t_s`` [s]: the Earth, both orbits and where the
        target is (top); the lidar's path around the target and where it is (bottom)."""
        track = self.tracks(j2)
        r_tgt, v_tgt, r_img = self.states(np.array([float(t_s)]), j2)
        now_km = r_tgt[0] @ track["plane"].T / 1e3
        now_m = relative_lvlh_m(r_tgt, v_tgt, r_img)[0]
        angle = np.linspace(0.0, 2.0 * np.pi, 73)
        earth_km = orbit.R_EARTH_M / 1e3 * np.column_stack([np.cos(angle), np.sin(angle)])
        rel = track["relative_m"]

        def line(xy, name, color, x="x", y="y", **extra):
            return {
                "type": "scatter",
                "mode": "lines",
                "x": np.round(xy[:, 0], 3).tolist(),
                "y": np.round(xy[:, 1], 3).tolist(),
                "name": name,
                "line": {"color": color, "width": 1.5},
                "xaxis": x,
                "yaxis": y,
                "hoverinfo": "skip",
                **extra,
            }

        def marker(x_val, y_val, name, color, x="x", y="y"):
            return {
                "type": "scatter",
                "mode": "markers",
                "x": [round(float(x_val), 3)],
                "y": [round(float(y_val), 3)],
                "name": name,
                "marker": {"color": color, "size": 9},
                "xaxis": x,
                "yaxis": y,
            }

        data = [
            line(earth_km, "Earth", EARTH_COLOR, fill="toself", fillcolor="rgba(66,165,245,0.25)"),
            line(track["target_km"], "target's orbit", TARGET_COLOR),
            line(track["lidar_km"], "lidar's orbit", LIDAR_COLOR, opacity=0.8),
            marker(now_km[0], now_km[1], "target now", TARGET_COLOR),
            line(
                np.column_stack([rel[:, 0], -rel[:, 2]]),
                "lidar around the target",
                LIDAR_COLOR,
                x="x2",
                y="y2",
            ),
            marker(0.0, 0.0, "target", TARGET_COLOR, x="x2", y="y2"),
            marker(now_m[0], -now_m[2], "lidar now", LIDAR_COLOR, x="x2", y="y2"),
        ]
        layout = {
            "margin": {"l": 48, "r": 8, "t": 8, "b": 36},
            "paper_bgcolor": "rgba(0,0,0,0)",
            "plot_bgcolor": "#ffffff",
            "font": {"family": "Roboto, sans-serif", "size": 10},
            "showlegend": False,
            "xaxis": axis("orbit plane x (km)", domain=[0.0, 1.0], anchor="y"),
            "yaxis": axis("y (km)", domain=[0.56, 1.0], anchor="x", scaleanchor="x"),
            "xaxis2": axis("along-track (m)", domain=[0.0, 1.0], anchor="y2"),
            "yaxis2": axis(
                "up, from the Earth (m)", domain=[0.0, 0.4], anchor="x2", scaleanchor="x2"
            ),
        }
        return {"data": data, "layout": layout}
