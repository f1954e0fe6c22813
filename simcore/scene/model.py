"""The Scene: every key of a scene, validated on construction (``scene.validation``)."""

from __future__ import annotations

from dataclasses import dataclass

from .keys import SceneKeys
from .validation import validate


@dataclass(frozen=True)
class Scene(SceneKeys):
    """A scene: its keys (``SceneKeys``: the sections and the quantities derived from them),
    checked on construction; ``with_overrides`` and ``load_scene`` build one."""

    def __post_init__(self):
        validate(self)
