"""Encodings the page understands: numpy arrays for vtk.js (binary typed arrays), colour maps, PNG
images (binary) and engineering-unit labels.

The state travels to the page as msgpack (wslink), which carries ``bytes`` as raw binary: an array
goes as ``{bytes, dtype, shape}`` (no base64, no JSON number list) and the page turns it into the
typed array vtk.js takes (``app/static/binary.js``), a PNG into an object URL.
"""

from __future__ import annotations

import io
import math
from functools import cache

import numpy as np
from matplotlib import colormaps
from PIL import Image

JS_TYPES = {
    "uint8": "Uint8Array",
    "uint16": "Uint16Array",
    "uint32": "Uint32Array",
    "int32": "Int32Array",
    "float32": "Float32Array",
    "float64": "Float64Array",
}


def typed_array(values: np.ndarray) -> dict | list:
    """A typed array for the page: ``{bytes, dtype, shape}``, the values' bytes in C order
    (little-endian, as the page's typed arrays on every platform the app supports).

    values : (...) uint8, uint16, uint32, int32, float32 or float64. An empty array becomes ``[]``.
    """
    a = np.ascontiguousarray(values)
    if a.dtype.name not in JS_TYPES:
        raise TypeError(f"no vtk.js typed array for dtype {a.dtype}")
    if a.size == 0:
        return []
    return {
        "bytes": a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes(),
        "dtype": a.dtype.name,
        "shape": list(a.shape),
    }


def decoded(typed: dict | list) -> np.ndarray:
    """The numpy array of a :func:`typed_array` (its dtype and shape)."""
    if isinstance(typed, list):
        return np.asarray(typed)
    dtype = np.dtype(typed["dtype"]).newbyteorder("<")
    return np.frombuffer(typed["bytes"], dtype=dtype).reshape(typed["shape"])


def rgb_field(rgb: np.ndarray, location: str = "PointData") -> dict:
    """A vtk.js scalar field of direct colours. rgb : (n, 3) uint8."""
    return {
        "name": "rgb",
        "values": typed_array(np.asarray(rgb, dtype=np.uint8)),
        "numberOfComponents": 3,
        "type": "Uint8Array",
        "location": location,
    }


def compact_indices(values: np.ndarray) -> np.ndarray:
    """Non-negative indices as uint16 when they fit (half the bytes), else uint32."""
    v = np.asarray(values)
    return v.astype(np.uint16 if v.size == 0 or v.max() < 2**16 else np.uint32)


def polyline_cells(segments: np.ndarray) -> np.ndarray:
    """vtk legacy cell array of 2-point lines. segments : (n, 2) int -> (3 n,) uint32."""
    seg = np.asarray(segments, dtype=np.uint32).reshape(-1, 2)
    return np.column_stack([np.full(len(seg), 2, np.uint32), seg]).ravel()


def triangle_cells(faces: np.ndarray) -> np.ndarray:
    """vtk legacy cell array of triangles. faces : (n, 3) int -> (4 n,) uint16 or uint32."""
    tri = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return compact_indices(np.column_stack([np.full(len(tri), 3), tri]).ravel())


@cache
def colormap_lut(name: str) -> np.ndarray:
    """(256, 3) uint8 colours of a matplotlib colour map."""
    rgba = colormaps[name](np.linspace(0.0, 1.0, 256))
    lut = np.round(rgba[:, :3] * 255).astype(np.uint8)
    lut.setflags(write=False)
    return lut


def normalized(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """values mapped linearly from [lo, hi] to [0, 1], clipped; 0.5 if lo == hi."""
    v = np.asarray(values, dtype=np.float64)
    if not hi > lo:
        return np.full(v.shape, 0.5)
    return np.clip((v - lo) / (hi - lo), 0.0, 1.0)


def colors_of(unit_values: np.ndarray, cmap: str) -> np.ndarray:
    """(n, 3) uint8 colours of values in [0, 1] (NaN maps to 0)."""
    u = np.nan_to_num(np.asarray(unit_values, dtype=np.float64), nan=0.0)
    return colormap_lut(cmap)[np.clip((u * 255).round().astype(np.int64), 0, 255)]


def css_gradient(cmap: str, stops: int = 9) -> str:
    """A left-to-right CSS linear-gradient that matches ``colors_of`` for the same map."""
    lut = colormap_lut(cmap)
    idx = np.linspace(0, 255, stops).round().astype(int)
    colors = ", ".join(hex_color(lut[i]) for i in idx)
    return f"linear-gradient(to right, {colors})"


def hex_color(rgb) -> str:
    r, g, b = (int(c) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


def rgb_of(hex_text: str) -> tuple[int, int, int]:
    h = hex_text.lstrip("#")
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)


def png_bytes(rgb: np.ndarray) -> bytes:
    """The PNG file of an (h, w, 3) uint8 image (sent as binary; the page shows it through an
    object URL)."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), "RGB").save(
        buf, "PNG", compress_level=1
    )
    return buf.getvalue()


_PREFIXES = ((1e0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"), (1e-15, "f"))


def si_prefix(magnitude: float) -> tuple[float, str]:
    """(scale, prefix) so that magnitude / scale lies in [1, 1000) where possible."""
    if not math.isfinite(magnitude) or magnitude <= 0:
        return 1.0, ""
    for scale, prefix in _PREFIXES:
        if magnitude >= scale:
            return scale, prefix
    return _PREFIXES[-1]


def si_text(value: float, unit: str, digits: int = 3) -> str:
    """``value`` with an SI prefix: si_text(3.2e-7, 'W') -> '320 nW'."""
    if not math.isfinite(value):
        return "–"
    scale, prefix = si_prefix(abs(value))
    return f"{value / scale:.{digits}g} {prefix}{unit}"
