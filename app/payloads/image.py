"""The detector array image: range, SNR, peak power or detection per pixel, as a PNG."""

from __future__ import annotations

import numpy as np

import simcore
from app.payloads import encode
from app.payloads.style import NO_ECHO_RGB, POWER_CMAP, RANGE_CMAP, colorbar


def array_image(result: simcore.Result, kind: str) -> dict:
    """The n x n array as a PNG (row 0 at the top) with its colour bar: measured range [m],
    band-limited peak power (log scale, from the 2nd percentile up, weaker echoes saturate at
    the bottom colour) or background power at the detector (log scale) per pixel; pixels without
    a value are dark."""
    if kind == "background":
        values = np.asarray(result.background.power_w, dtype=np.float64)
        valid = values > 0
        logs = np.log10(np.where(valid, values, 1.0))
        lo, hi = _finite_range(logs[valid])
        unit = encode.normalized(logs, lo, hi)
        title = "Background power (log)" if valid.any() else "Background: none (no Sun)"
        bar = colorbar(title, POWER_CMAP, encode.si_text(10**lo, "W"), encode.si_text(10**hi, "W"))
        cmap = POWER_CMAP
    elif kind == "peak_power":
        values = np.asarray(result.peak_power_image_w, dtype=np.float64)
        valid = values > 0
        logs = np.log10(np.where(valid, values, 1.0))
        lo, hi = _finite_range(logs[valid])
        if valid.sum() > 50:  # a few grazing echoes decades below the rest would wash it out
            lo = float(np.percentile(logs[valid], 2.0))
        unit = encode.normalized(logs, lo, hi)
        bar = colorbar(
            "Peak power (log)",
            POWER_CMAP,
            encode.si_text(10**lo, "W"),
            encode.si_text(10**hi, "W"),
        )
        cmap = POWER_CMAP
    else:
        values = np.asarray(result.range_image_m, dtype=np.float64)
        valid = np.isfinite(values)
        lo, hi = _finite_range(values[valid])
        unit = encode.normalized(np.where(valid, values, lo), lo, hi)
        bar = colorbar("Range", RANGE_CMAP, f"{lo:.2f} m", f"{hi:.2f} m")
        cmap = RANGE_CMAP
    rgb = encode.colors_of(unit.ravel(), cmap).reshape(*values.shape, 3)
    rgb[~valid] = NO_ECHO_RGB
    return {"src": encode.png_data_url(rgb), "colorbar": bar, "pixels": int(values.shape[0])}


def _finite_range(values: np.ndarray) -> tuple[float, float]:
    if values.size == 0:
        return 0.0, 1.0
    return float(values.min()), float(values.max())
