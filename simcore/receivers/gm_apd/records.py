"""The Geiger-mode receiver's two records: its response (the frame's avalanches and their
histogram) and its detection (thresholds, peak counts and the first-photon ranges), each the
receivers' shared record with the Geiger-mode fields added.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..records import Detection, Response
from . import events as ev
from . import histogram as gh
from .expected import Prediction


@dataclass(frozen=True, kw_only=True)
class GmResponse(Response):
    """The Geiger-mode array's response; besides :class:`Response` (``snr``: the frame's
    expected signal counts over the square root of signal plus background counts in the peak
    window, S / sqrt(S + B)):

    signal_pe : (n,) mean echo photoelectrons per pulse of each lit pixel, PDE E_r / (h nu) [1]
    rate_hz : (pixels**2,) constant primary event rate of every pixel (background + dark) [1/s]
    events : the frame's recorded avalanches (sorted by pixel, bin, pulse)
    histogram : their sparse per-pixel histogram
    gate_start_s : time of the gate's opening since emission [s]
    expected : the centroid's prediction of each lit pixel from its expected histogram before
        the thresholds (:func:`.figures.expected_prediction`; None for the first-photon fit):
        the costly half of the detection's predicted figures, kept here so that a threshold
        (TNR) change re-runs only the cheap half
    """

    signal_pe: np.ndarray
    rate_hz: np.ndarray
    events: ev.Events
    histogram: gh.Histogram
    gate_start_s: float
    expected: Prediction | None = None


@dataclass(frozen=True, kw_only=True)
class GmDetection(Detection):
    """The Geiger-mode detection; besides :class:`Detection` (``threshold_w``: the band-limited
    peak power of a single-surface echo whose expected peak-window counts reach the threshold):

    threshold_counts : (pixels**2,) counts a pixel's peak window must reach
    peak_counts : (n,) counts in each lit pixel's peak window (0 where it has no event)
    first_photon_range_m : (pixels**2,) range of each pixel's first avalanche of the frame's
        first pulse, NaN where none (the single-pulse first-photon cloud)
    first_photon_is_echo : (pixels**2,) bool, that avalanche came from the echo's window
    """

    threshold_counts: np.ndarray
    peak_counts: np.ndarray
    first_photon_range_m: np.ndarray
    first_photon_is_echo: np.ndarray
