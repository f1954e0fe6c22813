"""The detector array image: range, peak power, background or multi-peak echoes per pixel, as
a PNG; and the readout of one pixel (range, SNR, echo peaks) for the pointer over the image."""

from __future__ import annotations

import math

import numpy as np

import simcore
from app.payloads import encode
from app.payloads.style import NO_ECHO_RGB, POWER_CMAP, RANGE_CMAP, colorbar
from simcore.result import n_peaks

MULTI_PEAK_RGB = (255, 64, 200)  # magenta: a pixel whose echo has two or more peaks
ONE_PEAK_RGB = (118, 122, 134)  # grey: one peak


def array_image(result: simcore.Result, kind: str) -> dict:
    """The n x n array as a PNG (row 0 at the top) with its colour bar: measured range [m],
    band-limited peak power (log scale, from the 2nd percentile up, weaker echoes saturate at
    the bottom colour), background power at the detector (log scale) or, ``multi_peak``, the
    pixels whose echo has two or more peaks (also listed as ``multi_peak``: [[row, col], ...]);
    pixels without a value are dark."""
    if kind == "multi_peak":
        return multi_peak_image(result)
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
    return {"png": encode.png_bytes(rgb), "colorbar": bar, "pixels": int(values.shape[0])}


def _finite_range(values: np.ndarray) -> tuple[float, float]:
    if values.size == 0:
        return 0.0, 1.0
    return float(values.min()), float(values.max())


# ----------------------------------------------------------------------------------------------
# echo peaks: the multi-peak mode and the pointer's readout
# ----------------------------------------------------------------------------------------------
def echo_peaks(result: simcore.Result, i: int) -> int:
    """Peaks of lit pixel ``i``'s noise-free band-limited echo, counted as
    ``simcore.result.n_peaks`` does (at least 15 % of the maximum high and as prominent):
    the double peaks of Eq. 29 where one pixel sees surfaces at two depths
    (docs/physics.md#eq-29)."""
    return n_peaks(result.echo.waveform_per_j(int(i))[2])


_SEPARATION_S: dict[tuple, float] = {}  # (pulse shape, time step) -> the separation [s]


def _two_peak_separation_s(result: simcore.Result) -> float:
    """The smallest delay [s] between two equal copies of the band-limited pulse whose sum
    ``echo_peaks`` counts as two peaks (bisection on the pulse table, 0.01 ns)."""
    from simcore.echo.stage import echo_waveform  # noqa: PLC0415

    e = result.echo
    key = (e.shape.tau_s, e.shape.a, e.shape.sigma_h_s, e.dt_s)
    if key not in _SEPARATION_S:
        ones = np.ones(2)

        def double(d_s: float) -> bool:
            return n_peaks(echo_waveform(e.shape, np.array([0.0, d_s]), ones, e.dt_s)[2]) >= 2

        lo_s, hi_s = 0.0, 1e-9
        while not double(hi_s):
            lo_s, hi_s = hi_s, 2.0 * hi_s
        while hi_s - lo_s > 1e-11:
            mid_s = 0.5 * (lo_s + hi_s)
            lo_s, hi_s = (lo_s, mid_s) if double(mid_s) else (mid_s, hi_s)
        _SEPARATION_S[key] = hi_s
    return _SEPARATION_S[key]


def multi_peak_pixels(result: simcore.Result) -> np.ndarray:
    """(m,) flat indices (row * n + col) of the pixels whose echo has two or more peaks.

    A pixel's echo is the sum of copies of one pulse, delayed by its sub-rays' round trips
    (Eq. 29): copies spread over less than the pulse's width merge into one peak. For a Gaussian
    pulse of standard deviation sigma the sum is log-concave, so single-peaked, whenever the
    delays span at most 2 sigma, which is also the separation at which two equal copies split.
    Only the pixels whose delays span more than half the measured two-copy separation are
    therefore counted peak by peak (a few hundred of the paper scene's 14,000 lit pixels); the
    others have one peak.
    """
    e = result.echo
    if len(e.pixel) == 0:
        return np.zeros(0, np.int64)
    has = e.weights > 0
    arrivals = np.asarray(e.arrivals_s, dtype=np.float64)
    span_s = np.where(has, arrivals, -np.inf).max(axis=1) - np.where(has, arrivals, np.inf).min(
        axis=1
    )
    candidates = np.flatnonzero(span_s > 0.5 * _two_peak_separation_s(result))
    double = [i for i in candidates if echo_peaks(result, i) >= 2]
    return np.asarray(e.pixel, dtype=np.int64)[np.asarray(double, dtype=np.int64)]


def multi_peak_image(result: simcore.Result) -> dict:
    """The array with the multi-peak pixels in magenta, one-peak echoes grey, no echo dark."""
    n = result.pixels
    rgb = np.empty((n * n, 3), np.uint8)
    rgb[:] = NO_ECHO_RGB
    rgb[np.asarray(result.echo.pixel, dtype=np.int64)] = ONE_PEAK_RGB
    flat = multi_peak_pixels(result)
    rgb[flat] = MULTI_PEAK_RGB
    grey, magenta = encode.hex_color(ONE_PEAK_RGB), encode.hex_color(MULTI_PEAK_RGB)
    bar = {
        "title": f"Echo peaks: {len(flat):,} of {len(result.echo.pixel):,} lit pixels have two+",
        "gradient": f"linear-gradient(to right, {grey} 0 50%, {magenta} 50% 100%)",
        "lo": "one peak",
        "hi": "two or more",
    }
    rows, cols = np.divmod(flat, n)
    return {
        "png": encode.png_bytes(rgb.reshape(n, n, 3)),
        "colorbar": bar,
        "pixels": int(n),
        "multi_peak": [[int(r), int(c)] for r, c in zip(rows, cols, strict=True)],
    }


def pixel_readout(result: simcore.Result, row: int, col: int) -> dict:
    """What the page shows for the pixel under the pointer: its row and column, measured range,
    SNR (band-limited peak over the noise, Eq. 20) and number of echo peaks; ``text`` one line."""
    n = result.pixels
    e = result.echo
    i = int(np.searchsorted(e.pixel, row * n + col))
    lit = i < len(e.pixel) and int(e.pixel[i]) == row * n + col
    range_m = float(result.detection.range_m[i]) if lit else math.nan
    snr = float(result.receiver.snr[i]) if lit else math.nan
    peaks = echo_peaks(result, i) if lit else 0
    parts = [f"pixel ({row}, {col})"]
    if not lit:
        parts.append("no echo")
    else:
        parts.append(f"R = {range_m:.3f} m" if math.isfinite(range_m) else "not detected")
        parts.append(f"SNR {snr:.3g}")
        parts.append(f"{peaks} echo peak{'s' if peaks != 1 else ''}")
    return {
        "row": int(row),
        "col": int(col),
        "range_m": range_m if math.isfinite(range_m) else None,
        "snr": snr if math.isfinite(snr) else None,
        "peaks": int(peaks),
        "text": " · ".join(parts),
    }
