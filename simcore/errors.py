"""The scene's error, in a module that imports nothing: the scene's modules and the orbits' epoch
and TLE parsing (``simcore.orbit.epoch``, ``simcore.orbit.tle``) raise it."""

from __future__ import annotations


class SceneError(ValueError):
    """A scene key, value or file is invalid. The message names the key and its valid range."""
