"""Which lit pixels' echoes lost their stop to an earlier false alarm (the app's stats and
charts say so apart from the random misses): docs/physics.md#limited-stops."""

from __future__ import annotations

import numpy as np

from ...constants import C as C_M_S
from .receiver import stop_holdoff_s


def stops_taken_m(result) -> np.ndarray:
    """(n,) per lit pixel (aligned with ``result.echo.pixel``): the range [m] of the false alarm
    that took the stop the echo needed, NaN where none did.

    Read from the receiver's own stops (``detection.outliers``: the false alarms each pixel
    recorded this flash): a linear-mode pixel records at most ``timing.max_stops`` stops and is
    dead for the re-arm hold-off after each, so an echo not detected whose pixel recorded that
    many false alarms before it, or one less than the hold-off before it, was lost to them; the
    range given is the latest of them."""
    d, echo = result.detection, result.echo
    n = len(echo.pixel)
    taken = np.full(n, np.nan)
    if n == 0 or len(d.outliers.pixel) == 0:
        return taken
    holdoff_m = 0.5 * C_M_S * stop_holdoff_s(result.scene, echo)
    max_stops = int(result.scene.timing.max_stops)
    echo_m = np.asarray(d.range_true_m, dtype=np.float64)
    missed = ~np.asarray(d.detected, dtype=bool) & np.isfinite(echo_m)
    lit_of = np.full(result.pixels**2, -1, dtype=np.int64)  # flat pixel -> its lit index
    lit_of[echo.pixel] = np.arange(n)
    j = lit_of[d.outliers.pixel]  # each false alarm's lit pixel (-1: an unlit one)
    fa_m = d.outliers.range_m
    keep = j >= 0
    keep[keep] = missed[j[keep]] & (fa_m[keep] < echo_m[j[keep]])
    count = np.bincount(j[keep], minlength=n)
    latest = np.full(n, -np.inf)
    np.maximum.at(latest, j[keep], fa_m[keep])
    lost = (count > 0) & ((count >= max_stops) | (echo_m - latest < holdoff_m))
    taken[lost] = latest[lost]
    return taken
