"""Pixel selection: which pixels' echoes the waveform chart shows, a child of the app's logic.

A click on the detector-array image selects a pixel (shift-click adds or removes one); each new
frame keeps the selection, rescaled when the array size changed (the engine does that while it
builds the frame), unless the user clicked while the frame was computed: then the clicks win.
"""

from __future__ import annotations

from typing import Any

from app.engine import Frame, selection_tuple
from app.payloads import waveforms
from app.state import MAX_SELECTED_PIXELS


class PixelSelection:
    """The selected pixels on a trame state (``selected_pixels``, ``waveforms``)."""

    def __init__(self, state):
        self.state = state
        self.array_pixels = 0  # pixels per side of the array the page shows

    def current(self) -> tuple:
        """The selection the page holds, as (row, col) tuples."""
        return selection_tuple(self.state.selected_pixels or [])

    def for_frame(self, frame: Frame) -> tuple[list[list[int]], dict]:
        """The frame's selection and waveforms, unless the user clicked pixels of the same array
        while it was computed: then those, with their waveforms from this frame."""
        current = self.current()
        asked = frame.request.selection if frame.request else current
        n = frame.result.pixels
        if current == asked or not current or self.array_pixels != n:
            return frame.selection, frame.waveforms
        pixels = [[r, c] for r, c in current if 0 <= r < n and 0 <= c < n]
        return pixels, waveforms.waveform_figure(frame.result, pixels)

    def shown(self, frame: Frame) -> None:
        """The page now shows ``frame``'s array."""
        self.array_pixels = frame.result.pixels

    def click(self, frame: Frame | None, row: Any, col: Any, add: Any) -> None:
        """Click on the array image of ``frame``: select pixel (row, col); with ``add``,
        add or remove it. Anything that is not a pixel of the array is ignored."""
        if frame is None:
            return
        n = frame.result.pixels
        try:
            r, c = int(row), int(col)
        except (TypeError, ValueError, OverflowError):  # inf, NaN, "x", [1]
            return
        if not (0 <= r < n and 0 <= c < n):
            return
        current = [list(p) for p in self.current()]
        selection = waveforms.toggle_pixel(current, [r, c], bool(add), MAX_SELECTED_PIXELS)
        with self.state:
            self.state.selected_pixels = selection
            self.state.waveforms = waveforms.waveform_figure(frame.result, selection)
