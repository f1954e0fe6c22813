"""The 3D scene's payloads: the display frame and cameras, the target mesh and its facet colours,
the lidar's frustum and footprint, the material legend, the Sun and the Earth and the sides of
the target they light.

Both 3D views share one display frame fixed to the target: the target frame rotated so that the
zero pose (pitch = azimuth = 0) looks along the display's -Z with image-up along +Y. The target
stays put when the pose changes; the lidar's frustum and the points move around it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import simcore
from app.payloads import encode
from app.payloads.style import HIDDEN_COLOR, MATERIAL_COLORS, OTHER_MATERIAL_COLOR
from simcore.geometry import front_view_rotation
from simcore.orbit.elements import R_EARTH_M

# Flip of the sensor axes (x right, y down, z boresight) to the display's (x right, y up, -z view).
FLIP = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class DisplayFrame:
    """rotation : (3, 3) target frame -> display frame; radius_m : target bounding radius."""

    rotation: np.ndarray
    radius_m: float

    def from_target(self, points_t: np.ndarray) -> np.ndarray:
        """(n, 3) target-frame points [m] in the display frame."""
        return np.asarray(points_t, dtype=np.float64) @ self.rotation.T

    def from_sensor(self, points_s: np.ndarray, rotation: np.ndarray, translation_m) -> np.ndarray:
        """(n, 3) sensor-frame points [m] in the display frame, for the pose
        p_sensor = rotation @ p_target + translation_m."""
        p = np.asarray(points_s, dtype=np.float64) - np.asarray(translation_m)[None, :]
        return self.from_target(p @ rotation)


def display_frame(model: simcore.TargetModel) -> DisplayFrame:
    """The shared display frame of a target (see the module docstring)."""
    return DisplayFrame(FLIP @ front_view_rotation(model.mesh.extents), model.radius_m)


def home_camera(
    radius_m: float, azimuth_deg: float = 35.0, elevation_deg: float = 22.0
) -> dict[str, list[float]]:
    """A vtk.js camera that frames the target obliquely from the lidar's side (+Z)."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    direction = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    distance = 1.15 * radius_m / math.sin(math.radians(15.0))  # vtk.js view angle 30 deg
    return {
        "position": (direction * distance).tolist(),
        "focalPoint": [0.0, 0.0, 0.0],
        "viewUp": [0.0, 1.0, 0.0],
        "viewAngle": 30.0,
        "centerOfRotation": [0.0, 0.0, 0.0],
    }


def view_radius_m(scene: simcore.Scene, radius_m: float) -> float:
    """The radius [m] the 3D scene frames: the target's bounding radius, or, where the field of
    view's footprint at the target reaches further (its half diagonal: beyond 390 m for the MRO
    in the paper's 1.72 deg), the target radius times the power of sqrt(2) that holds the
    footprint (so the camera moves only when the scale changes by that much). The frustum is
    drawn over a depth in proportion, so it keeps its shape at any distance (at 3 km the fixed
    camera showed it as a line: its 90 m footprint far outside the view, only the boresight
    inside)."""
    half_diagonal_m = math.sqrt(2.0) * scene.pose.distance_m * math.tan(scene.receive.fov_rad / 2.0)
    if half_diagonal_m <= radius_m:
        return float(radius_m)
    steps = math.ceil(2.0 * math.log2(half_diagonal_m / radius_m) - 1e-9)
    return float(radius_m * 2.0 ** (steps / 2.0))


def scene_camera(scene: simcore.Scene, radius_m: float) -> dict[str, list[float]]:
    """The 3D scene view's home camera for ``scene``: it frames :func:`view_radius_m`."""
    return home_camera(view_radius_m(scene, radius_m))


# ----------------------------------------------------------------------------------------------
# the 3D scene: target mesh, facet colours, frustum, legend
# ----------------------------------------------------------------------------------------------
def target_geometry(model: simcore.TargetModel, frame: DisplayFrame) -> dict:
    """vtk.js points and triangle cells of the target mesh in the display frame (sent once)."""
    points = frame.from_target(model.mesh.vertices).astype(np.float32)
    return {
        "points": encode.typed_array(points),
        "polys": encode.typed_array(encode.triangle_cells(model.mesh.faces)),
    }


def material_color(name: str) -> str:
    return MATERIAL_COLORS.get(name, OTHER_MATERIAL_COLOR)


def facet_colors(model: simcore.TargetModel, faces: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 material colour of each of the given facets."""
    palette = np.array([encode.rgb_of(material_color(n)) for n in simcore.MATERIAL_NAMES], np.uint8)
    return palette[model.face_material_library[np.asarray(faces, dtype=np.int64)]]


def seen_facets_mesh(
    model: simcore.TargetModel, vertices_d: np.ndarray, visible_faces: np.ndarray
) -> dict:
    """vtk.js mesh state of the facets seen this frame, in their material colours.

    The whole target is drawn once, grey; these facets (with their own vertices, taken from the
    display-frame vertices ``vertices_d`` (n_vertices, 3)) are drawn over it, so a new frame
    sends only the few thousand facets seen, never the whole mesh.
    """
    faces = np.asarray(visible_faces, dtype=np.int64)
    if len(faces) == 0:
        faces = np.zeros(1, np.int64)  # one facet keeps the arrays non-empty; the view hides it
    used, corners = np.unique(model.mesh.faces[faces], return_inverse=True)
    return {
        "mesh": {
            "points": encode.typed_array(vertices_d[used].astype(np.float32)),
            "polys": encode.typed_array(encode.triangle_cells(corners.reshape(-1, 3))),
        },
        "field": encode.rgb_field(facet_colors(model, faces), location="CellData"),
    }


def part_cells(model: simcore.TargetModel, part: str) -> dict | list:
    """vtk.js triangle cells of one part's facets, indices into the whole mesh's points (which
    the page already holds): the highlight of a part sends no points. ``[]`` for no such part."""
    if part not in model.part_names:
        return []
    faces = model.mesh.faces[model.face_part == model.part_names.index(part)]
    cells = np.column_stack([np.full(len(faces), 3), faces]).ravel()
    # the mesh's largest point index decides the type, so every part of a target has one dtype
    wide = len(model.mesh.vertices) >= 2**16
    return encode.typed_array(cells.astype(np.uint32 if wide else np.uint16))


def material_legend(model: simcore.TargetModel, visible_faces: np.ndarray) -> list[dict]:
    """One entry per material the target uses: colour, label, facets seen / facets in all."""
    lib = model.face_material_library
    seen = np.bincount(lib[np.asarray(visible_faces, np.int64)], minlength=len(simcore.MATERIALS))
    total = np.bincount(lib, minlength=len(simcore.MATERIALS))
    rows = []
    for i, name in enumerate(simcore.MATERIAL_NAMES):
        if total[i]:
            label = simcore.MATERIALS[name].label or name
            rows.append(
                {
                    "name": name,
                    "label": label,
                    "color": material_color(name),
                    "seen": int(seen[i]),
                    "total": int(total[i]),
                }
            )
    n_hidden = int(len(lib) - len(visible_faces))
    rows.append(
        {
            "name": "hidden",
            "label": "not seen this frame",
            "color": HIDDEN_COLOR,
            "seen": n_hidden,
            "total": int(len(lib)),
        }
    )
    return rows


def frustum_sensor(
    fov_rad: float, distance_m: float, radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The field-of-view frustum around the target, in the sensor frame.

    Returns points (k, 3) [m] and segments (s, 2) int: the four edges from the lidar (or, if it
    is more than 2.5 target radii away, from a plane there) to a plane behind the target, the
    footprint rectangle at the target distance, and the boresight.
    """
    half = math.tan(fov_rad / 2.0)
    near = max(0.0, distance_m - 2.5 * radius_m)
    far = distance_m + 1.2 * radius_m
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)

    def rect(z: float) -> np.ndarray:
        return np.column_stack([square * half * z, np.full(4, z)])

    points = np.vstack([rect(near), rect(far), rect(distance_m), [[0, 0, near], [0, 0, far]]])
    ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    edges = np.column_stack([np.arange(4), np.arange(4) + 4])
    return points, np.vstack([edges, ring + 8, [[12, 13]]])


def footprint_text(scene: simcore.Scene) -> str:
    """The field of view's footprint at the target distance, e.g. '15.0 m × 15.0 m at 500 m'."""
    distance = scene.pose.distance_m
    side = 2.0 * distance * math.tan(scene.receive.fov_rad / 2.0)
    return f"{side:.3g} m × {side:.3g} m at {distance:g} m"


def frustum_mesh(result: simcore.Result, frame: DisplayFrame) -> dict:
    """vtk.js mesh state of the frustum lines in the display frame, over the depth of
    :func:`view_radius_m`."""
    scene = result.scene
    points_s, segments = frustum_sensor(
        scene.receive.fov_rad, scene.pose.distance_m, view_radius_m(scene, frame.radius_m)
    )
    pose = result.hits.pose
    points_d = frame.from_sensor(points_s, pose.rotation, pose.translation_m)
    return {
        "mesh": {
            "points": encode.typed_array(points_d.astype(np.float32)),
            "lines": encode.typed_array(encode.polyline_cells(segments)),
        }
    }


# ----------------------------------------------------------------------------------------------
# the Sun and the Earth seen from the target
# ----------------------------------------------------------------------------------------------
SUN_COLOR = "#ffca28"  # the Sun's arrow and legend swatch
EARTH_COLOR = "#42a5f5"  # the Earth's
ARROW_FROM, ARROW_TO = 1.15, 2.0  # an arrow's ends [target bounding radii from its centre]


def arrow_lines(
    center: np.ndarray, direction: np.ndarray, radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """An arrow outside the target pointing along ``direction`` (3,), from ``ARROW_FROM`` to
    ``ARROW_TO`` bounding radii ``radius_m`` away from ``center`` (3,) [m]: its points (6, 3) [m]
    and segments (5, 2) int (the shaft, then a head of four barbs)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    # two axes across the arrow: from the display axis least aligned with it
    across = np.cross(d, np.eye(3)[int(np.argmin(np.abs(d)))])
    across /= np.linalg.norm(across)
    other = np.cross(d, across)
    tail, tip = center + ARROW_FROM * radius_m * d, center + ARROW_TO * radius_m * d
    head = 0.18 * radius_m
    barbs = [tip - head * d + 0.45 * head * s * a for a in (across, other) for s in (1.0, -1.0)]
    points = np.vstack([tail, tip, *barbs])
    segments = np.array([[0, 1], [1, 2], [1, 3], [1, 4], [1, 5]])
    return points, segments


def azimuth_elevation_deg(direction_body: np.ndarray) -> tuple[float, float]:
    """A body-frame direction as the Sun control's angles: azimuth from +x towards +y, elevation
    above the x-y plane towards -z (the zenith; simcore.sun.direction_from_angles inverted)."""
    x, y, z = (float(c) for c in direction_body / np.linalg.norm(direction_body))
    return math.degrees(math.atan2(y, x)), math.degrees(math.asin(max(-1.0, min(1.0, -z))))


def sun_and_earth(scene: simcore.Scene, model: simcore.TargetModel, frame: DisplayFrame) -> dict:
    """The state of the scene view's Sun and Earth: an arrow towards each (vtk.js mesh states in
    the display frame, around the target's centre), and the legend's words with their angles in
    the target's frame (as the Sun control gives them), and the lit side (:func:`lit_side`; the
    Earth's only where the scene has its light: ``background.earth`` and an albedo). No arrows,
    empty words and no lit side for ``sun.mode = none`` (the paper's dark sky)."""
    none = {
        "sun_arrow": None,
        "earth_arrow": None,
        "sun_text": "",
        "earth_text": "",
        "lit_side": None,
    }
    if scene.sun.mode == "none":
        return none
    from simcore import sun  # noqa: PLC0415  (the ephemeris and the orbits: only with a Sun)

    geo = sun.sun_geometry(scene)
    if geo is None:
        return none
    center = frame.from_target(model.mesh.bounds.mean(axis=0)[None, :])[0]
    update: dict = {}
    to_earth = np.asarray(geo.earth_center_body_m, dtype=np.float64)
    mesh_dirs = {}
    for name, body in (("sun", geo.direction_body), ("earth", to_earth)):
        mesh_dir = model.body_from_mesh.T @ np.asarray(body, dtype=np.float64)  # the mesh frame
        mesh_dirs[name] = mesh_dir
        points, segments = arrow_lines(
            center, frame.from_target(mesh_dir[None, :])[0], model.radius_m
        )
        update[f"{name}_arrow"] = {
            "mesh": {
                "points": encode.typed_array(points.astype(np.float32)),
                "lines": encode.typed_array(encode.polyline_cells(segments)),
            }
        }
    az, el = azimuth_elevation_deg(geo.direction_body)
    shade = ", the target in the Earth's shadow" if geo.eclipsed else ""
    update["sun_text"] = f"Sun: azimuth {az:.0f}°, elevation {el:.0f}° (target frame){shade}"
    az, el = azimuth_elevation_deg(to_earth)
    altitude_km = (float(np.linalg.norm(to_earth)) - R_EARTH_M) / 1e3
    where = (
        "below (the target's nadir, +z)"
        if el < -89.5
        else f"azimuth {az:.0f}°, elevation {el:.0f}°"
    )
    # which altitude: the orbit's at this time, or the one set for a manual Sun (the two differ:
    # 705 km and 695 km on the paper's orbits)
    which = (
        "the target's altitude in its orbit now"
        if scene.sun.mode == "orbit"
        else "the target's altitude set for a manual Sun"
    )
    update["earth_text"] = f"Earth: {altitude_km:,.0f} km {where}: {which}"
    with_earth = scene.background.earth and scene.background.earth_albedo > 0
    update["lit_side"] = lit_side(
        model,
        None if geo.eclipsed else mesh_dirs["sun"],
        mesh_dirs["earth"] if with_earth else None,
    )
    return update


# the lit side: the facets that face the Sun, and those that face the Earth (its Earthshine)
LIT_NONE_COLOR = "#33363e"  # a facet that faces neither (darker than the hidden facets' grey)
LIT_BOTH_COLOR = "#9ccc65"  # a facet that faces both (the Sun's yellow and the Earth's blue)


def facing(model: simcore.TargetModel, direction_mesh: np.ndarray) -> np.ndarray:
    """(n_faces,) bool: the facets whose outward normal (the mesh's winding) points towards
    ``direction_mesh`` (3,), a direction in the mesh frame: n . d > 0. Geometry only: a facet
    another part shadows still counts."""
    d = np.asarray(direction_mesh, dtype=np.float64)
    return model.mesh.face_normals @ (d / np.linalg.norm(d)) > 0.0


def lit_side(
    model: simcore.TargetModel, sun_mesh: np.ndarray | None, earth_mesh: np.ndarray | None
) -> dict:
    """The scene view's lit side: which facets face the Sun and which the Earth.

    sun_mesh, earth_mesh : (3,) directions towards the Sun and the Earth's centre in the mesh
    frame, or None (the target in the Earth's shadow: no facet sunlit; no Earth in the scene).
    Returns ``sun`` and ``earth``: one bit per facet, in the mesh's facet order, packed eight to
    a byte, the first facet in the high bit (``numpy.packbits``; typed arrays), ``n_facets``,
    ``palette`` (the RGB of a facet lit by neither, the Sun, the Earth, both: indexed by
    sun + 2 earth; ``app/static/lit.js`` turns the bits into the facets' colours) and ``rows``
    (the legend's: label, colour, facets).
    """
    n = len(model.mesh.faces)
    none = np.zeros(n, dtype=bool)
    sun = none if sun_mesh is None else facing(model, sun_mesh)
    earth = none if earth_mesh is None else facing(model, earth_mesh)
    colors = (LIT_NONE_COLOR, SUN_COLOR, EARTH_COLOR, LIT_BOTH_COLOR)
    only = " only" if earth_mesh is not None else ""
    rows = [
        (
            f"faces the Sun{only}" if sun_mesh is not None else "sunlit: none (Earth's shadow)",
            SUN_COLOR,
            sun & ~earth,
        )
    ]
    if earth_mesh is not None:
        rows += [
            ("faces the Earth only (Earthshine)", EARTH_COLOR, earth & ~sun),
            ("faces both", LIT_BOTH_COLOR, sun & earth),
        ]
    rows.append(("faces neither", LIT_NONE_COLOR, ~sun & ~earth))
    return {
        "sun": encode.typed_array(np.packbits(sun)),
        "earth": encode.typed_array(np.packbits(earth)),
        "n_facets": n,
        "palette": [list(encode.rgb_of(c)) for c in colors],
        "rows": [
            {"label": label, "color": color, "facets": int(np.count_nonzero(mask))}
            for label, color, mask in rows
        ],
    }
