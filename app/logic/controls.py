"""The scene controls: what the page's sliders and fields hold, made valid, a child of the logic.

Every change is sanitised (numbers clamped to their range, anything else refused with a message
that names the control), and the value actually used is written back so the page shows it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from app.state import Controls, sanitize_controls, state_keys


class ControlPanel:
    """The controls on a trame state (keys ``app.state.STATE_KEYS``, ``input_message``).

    initial : the controls a reset returns to (the scene the app started with, or the uploaded
        target's)
    current : the controls of the newest valid scene
    """

    def __init__(self, state, initial: Controls):
        self.state = state
        self.initial = initial
        self.current = initial

    def read(self) -> Controls:
        """The page's controls made valid: corrections written back, messages shown."""
        raw = {key: self.state[key] for key in state_keys()}
        controls, messages = sanitize_controls(raw, self.current)
        if messages:
            self.state.input_message = "; ".join(messages)
        fixed = {k: v for k, v in controls.as_state().items() if not _same(raw.get(k), v)}
        if fixed:
            self.state.update(fixed)  # the page shows the value actually used
        self.current = controls
        return controls

    def reset(self) -> None:
        """Back to the initial controls (their change handler submits the scene)."""
        with self.state:
            self.state.update({**self.initial.as_state(), "input_message": ""})

    def use_target(self, initial: Controls) -> None:
        """Another target: ``initial`` is what a reset returns to; its parts' materials apply."""
        self.initial = initial
        self.current = dataclasses.replace(self.current, materials=initial.materials)


def _same(a: Any, b: Any) -> bool:
    """Equal values, with 5 == 5.0 but '5' != 5 and NaN never equal."""
    if isinstance(a, bool) != isinstance(b, bool) or isinstance(a, str) != isinstance(b, str):
        return False
    if isinstance(a, float) and math.isnan(a):
        return False
    return a == b
