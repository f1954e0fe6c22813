"""Scene files: the built-in scenes, loading a TOML file (a mesh path relative to it) and dumping
a scene as TOML that loads back to an equal Scene."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import tomli_w

from .._assets import ASSETS_DIR
from ..errors import SceneError
from ..tomlfile import clip, read_toml_file
from .fields import to_plain
from .model import Scene
from .overrides import scene_from_dict, with_overrides

SCENES_DIR = ASSETS_DIR / "scenes"


def builtin_scenes() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def read_toml(path: Path, error: type[SceneError] = SceneError) -> dict[str, Any]:
    """The tables of a TOML file; ``error`` (a SceneError) names the file if it is missing, not a
    file, larger than ``tomlfile.MAX_TOML_BYTES`` or not TOML."""
    return read_toml_file(path, "scene file", error)


def _is_builtin(name: str) -> bool:
    """Whether ``name`` is a built-in scene (``paper``); False for anything not a plain name."""
    return name in builtin_scenes()


def load_scene(source: str | Path | None = None) -> Scene:
    """Load a scene: None or a built-in name (``paper``) or a path to a TOML file."""
    if source is None:
        source = "paper"
    path = Path(source)
    if not path.suffix and _is_builtin(str(source)):
        path = SCENES_DIR / f"{source}.toml"
    if not os.path.lexists(path):  # never raises (a path too long for the system is not there)
        names = ", ".join(builtin_scenes())
        raise SceneError(f"scene file not found: {clip(source)} (built-in scenes: {names})")
    data = read_toml(path)
    data.setdefault("name", path.stem)
    scene = scene_from_dict(data)
    # a relative mesh path in a scene file is relative to that file
    mesh = scene.target.mesh
    if any(mesh.lower().endswith(ext) for ext in MESH_SUFFIXES) and not Path(mesh).is_absolute():
        scene = with_overrides(scene, {"target.mesh": str((path.parent / mesh).resolve())})
    return scene


MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".stl", ".ply")


def dump_scene(scene: Scene) -> str:
    """The scene as TOML text that load_scene reads back to an equal Scene (TOML has inf)."""
    return tomli_w.dumps(to_plain(scene, inf_as_text=False))
