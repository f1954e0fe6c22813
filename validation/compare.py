"""The comparison's arithmetic, numpy alone (tested in the normal suite without Mitsuba).

Two renderings of one scene meet here as per-pixel arrays (n x n: energy per joule, 0 where dark;
mean delays, NaN where dark) and as echo elements (delays [s] and weights). Every figure is a
plain statistic of their differences.
"""

from __future__ import annotations

import numpy as np

C = 299_792_458.0  # [m/s]


def moments(delays_s, weights) -> tuple[float, float]:
    """Weighted mean [s] and rms width [s] of a set of echo elements (or histogram bins)."""
    t = np.asarray(delays_s, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    total = w.sum()
    if not total > 0:
        raise ValueError("moments of an echo with no energy")
    mean = float((w * t).sum() / total)
    return mean, float(np.sqrt((w * (t - mean) ** 2).sum() / total))


def interior(lit: np.ndarray) -> np.ndarray:
    """(n, n) bool: lit pixels whose eight neighbours are lit too (away from every edge)."""
    lit = np.asarray(lit, dtype=bool)
    padded = np.pad(lit, 1, constant_values=False)
    n, m = lit.shape
    out = lit.copy()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            out &= padded[1 + di : 1 + di + n, 1 + dj : 1 + dj + m]
    return out


def lit_pixels(energy_a: np.ndarray, energy_b: np.ndarray) -> dict:
    """Which pixels receive light in each rendering: counts, the pixels only one has and the
    share of that rendering's energy they carry."""
    a, b = np.asarray(energy_a) > 0, np.asarray(energy_b) > 0
    only_a, only_b = a & ~b, b & ~a
    return {
        "a": int(a.sum()),
        "b": int(b.sum()),
        "both": int((a & b).sum()),
        "only_a": int(only_a.sum()),
        "only_b": int(only_b.sum()),
        "only_a_energy_share": _share(energy_a, only_a),
        "only_b_energy_share": _share(energy_b, only_b),
    }


def _share(energy, mask) -> float:
    total = float(np.sum(energy))
    return float(np.sum(np.asarray(energy)[mask]) / total) if total > 0 else 0.0


def spread(values) -> dict:
    """Median, 95th percentile and maximum of |values| (and the count), NaNs left out."""
    v = np.abs(np.asarray(values, dtype=np.float64))
    v = v[np.isfinite(v)]
    if not len(v):
        return {"n": 0, "median": None, "p95": None, "max": None}
    return {
        "n": int(len(v)),
        "median": float(np.median(v)),
        "p95": float(np.percentile(v, 95)),
        "max": float(v.max()),
    }


def relative(a, b, mask) -> dict:
    """spread() of a / b - 1 over ``mask``, with the mean of the signed ratio."""
    a, b = np.asarray(a)[mask], np.asarray(b)[mask]
    rel = a / b - 1.0
    out = spread(rel)
    out["mean"] = float(rel.mean()) if len(rel) else None
    return out


def plate_echo(corners_m: np.ndarray, nodes: int = 64) -> tuple[float, float]:
    """Mean delay [s] and rms width [s] of the whole echo of a flat quadrilateral plate, lit
    everywhere by a flat-top beam from the origin and seen from there (Eq. 30: each element of
    area dA weighs rho cos(theta)^2 dA / r^4, its delay 2 r / c), by Gauss-Legendre quadrature
    over the plate's bilinear map from the unit square (``nodes`` per side: converged to double
    precision for a smooth integrand).

    corners_m : (4, 3) the plate's corners in the sensor frame, in order around it (coplanar).
    """
    p0, p1, p2, p3 = np.asarray(corners_m, dtype=np.float64)
    x, w = np.polynomial.legendre.leggauss(nodes)
    u, v = ((x + 1.0) / 2.0)[:, None, None], ((x + 1.0) / 2.0)[None, :, None]
    p = (1 - u) * (1 - v) * p0 + u * (1 - v) * p1 + u * v * p2 + (1 - u) * v * p3
    du = (1 - v) * (p1 - p0) + v * (p2 - p3)  # dp/du (nodes, nodes or 1, 3)
    dv = (1 - u) * (p3 - p0) + u * (p2 - p1)
    cross = np.cross(np.broadcast_to(du, p.shape), np.broadcast_to(dv, p.shape))
    area = np.linalg.norm(cross, axis=-1)  # the map's Jacobian
    normal = cross / area[..., None]
    r = np.linalg.norm(p, axis=-1)
    cos = np.abs(np.einsum("ijk,ijk->ij", p, normal)) / r
    weight = (w[:, None] * w[None, :] / 4.0) * area * cos**2 / r**4
    return moments(2.0 * r / C, weight)


def far_field_plate_width_s(side_m: float, incidence_deg: float) -> float:
    """The closed form of a square plate's echo width far from it: delays uniform over the
    plate's two-way depth 2 s sin(b) / c, an rms width of 2 s sin(b) / (c sqrt(12))."""
    return 2.0 * side_m * np.sin(np.radians(incidence_deg)) / (C * np.sqrt(12.0))
