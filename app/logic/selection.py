"""Pixel selection: which pixels' echoes the waveform chart shows, a child of the app's logic.

A click on the detector-array image selects a pixel (shift-click adds or removes one); each new
frame keeps the selection, rescaled when the array size changed (the engine does that while it
builds the frame), unless the user clicked while the frame was computed: then the clicks win.
The selection keeps its directions: the directions of the clicked pixels are remembered while
the page's selection stays the one they gave, so 256 -> 64 -> 256 pixels returns to the very
pixels clicked (and two pixels merged on the small array part again). The pointer over the image
gets a readout of its pixel (``pixel_readout``): looked up here, one pixel at a time.
"""

from __future__ import annotations

from typing import Any

from app.engine import Frame, selection_tuple
from app.payloads import image, waveforms
from app.state import MAX_SELECTED_PIXELS


class PixelSelection:
    """The selected pixels on a trame state (``selected_pixels``, ``waveforms``)."""

    def __init__(self, state):
        self.state = state
        self.array_pixels = 0  # pixels per side of the array the page shows
        self.fov_rad = 0.0  # its field of view
        # (selection, array_pixels, fov_rad, tangents): the directions behind a selection
        self._directions: tuple | None = None
        # the image's zoom (scale s >= 1, top-left corner x, y in image fractions): page-side only
        state.array_zoom = {"s": 1, "x": 0, "y": 0}
        state.client_only("array_zoom")
        state.array_cursor = None  # the keyboard's cursor pixel on the image (app.ui.panels)
        state.client_only("array_cursor")

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

    def tangents(self) -> tuple[tuple[float, float], ...]:
        """The focal-plane tangents (x/f, y/f) of the selection's directions: those remembered
        if the page still holds the selection they gave, else its pixels' centres."""
        current = self.current()
        remembered = self._directions
        if remembered is not None and remembered[:3] == (current, self.array_pixels, self.fov_rad):
            return remembered[3]
        if not self.array_pixels or not self.fov_rad:
            return ()
        return waveforms.pixel_tangents(current, self.array_pixels, self.fov_rad)

    def shown(self, frame: Frame, selection: list | None = None) -> None:
        """The page now shows ``frame``'s array, with ``selection`` (the frame's, by default):
        where that is the frame's rescaled selection, its directions are the request's."""
        request = frame.request
        tangents = request.selection_tangents if request is not None else ()
        pixels = selection_tuple(frame.selection if selection is None else selection)
        self.array_pixels = frame.result.pixels
        self.fov_rad = frame.result.scene.receive.fov_rad
        if tangents and pixels == selection_tuple(frame.selection):
            self._directions = (pixels, self.array_pixels, self.fov_rad, tangents)
        else:
            self._directions = None

    def hover(self, frame: Frame | None, row: Any = None, col: Any = None) -> None:
        """The pointer is over pixel (row, col) of ``frame``'s image (anything else, or None,
        clears the readout)."""
        readout = None
        try:
            r, c = int(row), int(col)
        except (TypeError, ValueError, OverflowError):
            r = c = -1
        if frame is not None and 0 <= r < frame.result.pixels and 0 <= c < frame.result.pixels:
            readout = image.pixel_readout(frame.result, r, c)
        self.state.pixel_readout = readout

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
