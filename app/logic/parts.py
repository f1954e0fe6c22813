"""The part highlight, a child of the app's logic: the target part whose row of the materials
panel is under the pointer (``part_hover``) or was last chosen there (``part_chosen``) is drawn
in yellow in the 3D scene. Its facets travel as cells into the mesh the page already holds;
names the target does not have highlight nothing."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import simcore
from app.payloads import scene3d

STATE_KEYS = ("part_hover", "part_chosen")  # what a page sets: part names (anything else: none)


class PartHighlight:
    """``highlight_part`` (the shown part's name, "" for none) and ``highlight_cells`` (its
    facets) on a trame state, from ``part_hover`` and ``part_chosen``."""

    def __init__(self, state, model: Callable[[], simcore.TargetModel]):
        self.state = state
        self.model = model  # the current target (it changes with an upload)
        self._cells: dict[str, Any] = {}  # part -> cells, for the current target
        self._model_id = 0
        state.update(
            {"part_hover": None, "part_chosen": None, "highlight_part": "", "highlight_cells": []}
        )
        state.change(*STATE_KEYS)(self.update)

    def update(self, **_: Any) -> None:
        """Show the hovered part, else the chosen one, else none."""
        model = self.model()
        if id(model) != self._model_id:
            self._cells, self._model_id = {}, id(model)
        names = model.part_names
        hover, chosen = self.state.part_hover, self.state.part_chosen
        part = next((p for p in (hover, chosen) if isinstance(p, str) and p in names), "")
        if part == self.state.highlight_part:
            return
        if part and part not in self._cells:
            self._cells[part] = scene3d.part_cells(model, part)
        with self.state:
            self.state.highlight_part = part
            self.state.highlight_cells = self._cells[part] if part else []

    def reset(self) -> None:
        """A new target: nothing chosen on it yet."""
        with self.state:
            self.state.part_hover = self.state.part_chosen = None
        self.update()
