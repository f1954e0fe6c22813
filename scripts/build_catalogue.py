"""Build a catalogue target from one of NASA's Draco-compressed GLB models (a one-off, offline).

    python scripts/build_catalogue.py SOURCE.glb NAME OUT_DIR [SOURCE_MATERIAL=PART ...]

Reads SOURCE.glb through simcore's loader (the Draco streams checked in a child process, then
decoded), applies the scene's transforms and regroups the triangles into parts by what they are
made of: a part's own glTF material name when the material rules (assets/material_rules.toml)
know it (foil_gold, solarArray), else the colour the model paints the triangle (its texture
sampled at the triangle's corners: NASA's converted models keep their colours in palette
textures with names such as PaletteMaterial001 or tex_01):

- ``transparent``: a material with opacity below 0.5 (glTF alpha, BLEND or MASK);
- ``solar_cells``: blue (the blue channel 30 above red and green) or near black (every channel
  below 60): photovoltaic cells under cover glass;
- ``foil``: gold (red at least 30 % above blue, green above blue): multilayer insulation;
- ``white_paint``: every channel above 215;
- ``structure``: the rest (grey, silver, aluminium).

A ``SOURCE_MATERIAL=PART`` argument puts every triangle of that source material in PART (where
a model's colour misleads: TESS paints its solar arrays white); ``SOURCE_MATERIAL=PART@outboard``
only its triangles whose centres lie beyond 30 % of the model's half length from the middle of
its longest side (wings, not the bus).

Writes OUT_DIR/NAME.glb without Draco and without textures (one material per part, its base
colour the part's mean colour; a transparent part keeps its alpha), and prints each part's
triangles, area share and source materials for the target's README. Nothing here runs at run
time: the catalogue ships the files this wrote.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

from simcore.materials import read_material_map
from simcore.target import MATERIAL_RULES, load_mesh_file, part_materials
from simcore.target_mesh import opacity

PART_OF_MATERIAL = {"solar_panel": "solar_cells", "coating_1": "foil"}


def face_colours(mesh: trimesh.Trimesh) -> np.ndarray:
    """(n_faces, 3) float RGB 0-255 of each triangle: its corners' colours (texture sampled at
    the corners' UV coordinates times the base colour factor), averaged."""
    try:
        colours = np.asarray(mesh.visual.to_color().vertex_colors, dtype=np.float64)[:, :3]
    except Exception:
        colours = np.full((len(mesh.vertices), 3), 180.0)
    return colours[mesh.faces].mean(axis=1)


def colour_part(rgb: np.ndarray) -> np.ndarray:
    """(n,) part name of each triangle from its (n, 3) colour (the rules of the docstring)."""
    r, g, b = rgb.T
    out = np.full(len(rgb), "structure", dtype=object)
    out[(rgb.min(axis=1) > 215)] = "white_paint"
    out[(r - b >= 0.3 * np.maximum(r, 1.0)) & (g > b)] = "foil"
    out[((b > r + 30) & (b > g + 30)) | (rgb.max(axis=1) < 60)] = "solar_cells"
    return out


def regroup(source: Path, forced: dict[str, str] | None = None) -> dict[str, dict]:
    """The model's triangles regrouped into parts: name -> vertices, faces, colour, alpha,
    source material names."""
    rules = read_material_map(MATERIAL_RULES)
    loaded = load_mesh_file(source, "glb")
    bounds = loaded.bounds
    axis = int(np.argmax(np.ptp(bounds, axis=0)))
    middle, half = bounds[:, axis].mean(), np.ptp(bounds[:, axis]) / 2.0
    parts: dict[str, dict] = {}
    for mesh in loaded.dump(concatenate=False):
        if not isinstance(mesh, trimesh.Trimesh) or not len(mesh.faces):
            continue
        material = getattr(getattr(mesh, "visual", None), "material", None)
        name = str(getattr(material, "name", "") or mesh.metadata.get("name") or "unnamed")
        alpha = opacity(mesh)
        colours = face_colours(mesh)
        forced_part, _, where = (forced or {}).get(name, "").partition("@")
        if alpha < 0.5:
            labels = np.full(len(mesh.faces), "transparent", dtype=object)
        else:
            (by_name,), (known,) = part_materials([name], [""], rules)
            if known and by_name in PART_OF_MATERIAL:
                labels = np.full(len(mesh.faces), PART_OF_MATERIAL[by_name], dtype=object)
            else:
                labels = colour_part(colours)
            if forced_part:
                pick = np.ones(len(mesh.faces), dtype=bool)
                if where == "outboard":
                    centre = mesh.triangles_center[:, axis]
                    pick = np.abs(centre - middle) > 0.3 * half
                labels[pick] = forced_part
        areas = mesh.area_faces
        for label in np.unique(labels):
            pick = labels == label
            part = parts.setdefault(
                label, {"meshes": [], "colour": [], "area": [], "sources": set(), "alpha": 1.0}
            )
            part["meshes"].append(mesh.submesh([np.flatnonzero(pick)], append=True))
            part["colour"].append(colours[pick])
            part["area"].append(areas[pick])
            part["sources"].add(name)
            if label == "transparent":
                part["alpha"] = alpha
    return parts


def write(parts: dict[str, dict], out: Path) -> None:
    scene = trimesh.Scene()
    total = sum(float(np.concatenate(p["area"]).sum()) for p in parts.values())
    for label in sorted(parts):
        p = parts[label]
        mesh = trimesh.util.concatenate(p["meshes"])
        area = np.concatenate(p["area"])
        rgb = (np.concatenate(p["colour"]) * area[:, None]).sum(axis=0) / max(area.sum(), 1e-30)
        rgba = [*(int(c) for c in np.clip(np.round(rgb), 0, 255)), round(255 * p["alpha"])]
        material = trimesh.visual.material.PBRMaterial(
            name=label,
            baseColorFactor=rgba,
            metallicFactor=0.0,
            roughnessFactor=0.8,
            alphaMode="BLEND" if label == "transparent" else None,
        )
        clean = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        clean.visual = trimesh.visual.TextureVisuals(material=material)
        scene.add_geometry(clean, geom_name=label, node_name=label)
        print(
            f"{label:12s} {len(mesh.faces):7d} triangles  {area.sum() / total:6.1%} of the area  "
            f"rgba {rgba}  from {', '.join(sorted(p['sources']))}"
        )
    out.write_bytes(scene.export(file_type="glb"))
    print(f"wrote {out} ({out.stat().st_size / 2**20:.2f} MiB), extents {scene.extents}")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__.split("\n\n")[1])
    source, name, folder = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
    forced = dict(a.split("=", 1) for a in sys.argv[4:])
    folder.mkdir(parents=True, exist_ok=True)
    write(regroup(source, forced), folder / f"{name}.glb")
