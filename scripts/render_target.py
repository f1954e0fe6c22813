"""Render a target seen obliquely (pitch 30 deg, azimuth -35 deg from the lidar's zero pose) to
PNG: its own colours (the thumbnail) and its materials (the check of its material map).

    python scripts/render_target.py NAME_OR_MESH OUT_DIR [--size 256]

Writes OUT_DIR/thumbnail.png (each part in its glTF base colour) and OUT_DIR/materials.png (each
part in its library material's colour, with a legend), orthographic, shaded by the cosine of
incidence, painter's order. Offline, for the catalogue's assets; matplotlib only here.
"""

from __future__ import annotations

import argparse
import json
import struct
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.patches import Patch

from simcore.geometry import front_view_rotation, rotation_x, rotation_y
from simcore.scene import Target
from simcore.target import _resolve, load_target

MATERIAL_COLOURS = {
    "solar_panel": "#1f3fbf",
    "coating_1": "#e0b000",
    "coating_2": "#9a9a9a",
    "ideal_diffuse": "#ffffff",
    "ideal_specular": "#40e0ff",
    "lambertian": "#f0f0f0",
}


def part_colours(path: Path | None, names) -> dict[str, tuple]:
    """Each part's glTF base colour (RGBA 0-1) from a .glb's materials; grey where none."""
    colours = {}
    if path is not None and path.suffix.lower() == ".glb":
        data = path.read_bytes()
        (n,) = struct.unpack_from("<I", data, 12)
        tree = json.loads(data[20 : 20 + n])
        for m in tree.get("materials", []):
            factor = m.get("pbrMetallicRoughness", {}).get("baseColorFactor", [0.7, 0.7, 0.7, 1])
            colours[m.get("name", "")] = tuple(factor)
    return {name: colours.get(name, (0.7, 0.7, 0.7, 1.0)) for name in names}


VIEW_PITCH_DEG, VIEW_AZIMUTH_DEG = 30.0, -35.0  # an oblique view: every face of the box shows


def render(model, face_rgb: np.ndarray, out: Path, size_px: int, legend=None) -> None:
    rot = (
        rotation_x(np.radians(VIEW_PITCH_DEG))
        @ rotation_y(np.radians(VIEW_AZIMUTH_DEG))
        @ front_view_rotation(model.extents_m)
    )
    v = model.vertices_m @ rot.T
    tri = v[model.faces]
    depth = tri[:, :, 2].mean(axis=1)
    order = np.argsort(-depth)  # far first
    shade = 0.35 + 0.65 * np.abs(model.face_normals @ rot.T)[:, 2]
    colours = np.clip(face_rgb * shade[:, None], 0, 1)
    fig = plt.figure(figsize=(size_px / 100, size_px / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.add_collection(
        PolyCollection(tri[order][:, :, :2] * [1, -1], facecolors=colours[order], edgecolors="none")
    )
    half = 0.55 * max(np.ptp(v[:, 0]), np.ptp(v[:, 1]))
    ax.set_xlim(-half, half)
    ax.set_ylim(-half, half)
    ax.set_aspect("equal")
    ax.set_facecolor("black")
    ax.set_xticks([])
    ax.set_yticks([])
    if legend:
        ax.legend(handles=legend, loc="lower left", fontsize=6, framealpha=0.6)
    fig.savefig(out, facecolor="black")
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("target")
    parser.add_argument("out")
    parser.add_argument("--size", type=int, default=256)
    args = parser.parse_args()
    target = Target(mesh=args.target)
    model = load_target(target)
    path, _, _ = _resolve(target)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    own = part_colours(path, model.part_names)
    rgb = np.array([own[n][:3] for n in model.part_names])[model.face_part]
    render(model, rgb, out / "thumbnail.png", args.size)
    lib = np.array([matplotlib.colors.to_rgb(MATERIAL_COLOURS[m]) for m in model.part_materials])
    used = dict.fromkeys(model.part_materials)
    legend = [Patch(color=MATERIAL_COLOURS[m], label=m) for m in used]
    render(model, lib[model.face_part], out / "materials.png", args.size, legend)
    print(f"wrote {out / 'thumbnail.png'} and {out / 'materials.png'}")


if __name__ == "__main__":
    main()
