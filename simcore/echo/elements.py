"""Echo elements: each sub-ray's weight (Eq. 30), split into halves by its cell's range spread,
merged within a window (the two-point rule of each bin's delays)."""

from __future__ import annotations

import numpy as np

from ..illumination import illumination_gain

__all__ = ["element_weights", "illumination_gain", "merge_elements", "split_elements"]


def element_weights(
    range_m,
    cos_theta,
    rho,
    illum_gain,
    *,
    aperture_area_m2,
    eta_t,
    eta_r,
    ifov_rad,
    subrays,
    paper_4pi=False,
):
    """Eq. 30 weights w_k (dimensionless) of each sub-ray: P_r(t) = sum_k w_k P0(t - t_k).

    w_k = eta_r A_r eta_t G_k rho_k cos(theta_k) dA_k / r_k^4, dA_k = (r_k theta_ifov)^2 / K, where
    G_k is the illumination gain (4 / (pi theta_ill^2) for the flat top). With ``paper_4pi`` the
    paper's literal form: an extra 1/(4 pi) and no cos(theta).
    All inputs broadcast; misses carry range inf and give 0.
    """
    r = np.asarray(range_m)
    finite = np.isfinite(r) & (r > 0)
    r_safe = np.where(finite, r, 1.0)
    geom = eta_r * aperture_area_m2 * eta_t * ifov_rad**2 / subrays / r_safe**2
    w = geom * illum_gain * rho
    if paper_4pi:
        w = w / (4.0 * np.pi)
    else:
        w = w * cos_theta
    return np.where(finite, w, 0.0)


def split_elements(arrivals_s, weights, spread_s):
    """Each element as the two-point rule of a delay spread: halves at +- ``spread_s``.

    arrivals_s, weights : (n, K); spread_s : (n,) standard deviation of each element's delays [s]
    (the range spread of a sub-ray's cell, two-way). Returns (n, 2 K) delays and weights; a pixel
    with no spread keeps each element whole (its twin has weight 0).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    s = np.asarray(spread_s, dtype=np.float64)[:, None]
    spread = s > 0
    early = np.where(weights > 0, arrivals - s, arrivals)
    late = np.where(weights > 0, arrivals + s, arrivals)
    half = np.where(spread, 0.5 * weights, weights)
    return (
        np.concatenate([early, late], axis=1),
        np.concatenate([half, np.where(spread, half, 0.0)], axis=1),
    )


def merge_elements(arrivals_s, weights, window_s: float):
    """Merge each pixel's elements that arrive within ``window_s`` of each other into two.

    Delays are cut into bins of ``window_s`` from the pixel's first arrival; each bin's elements
    become the two-point distribution with the same total weight, mean delay, spread and skew
    (the two-point Gauss rule of the bin's delays), so the echo changes only through the fourth
    and higher moments of each bin, O(window^4) times the pulse's fourth derivative. A pixel lit
    by a plane or a few facets keeps a few elements instead of every sub-ray.

    arrivals_s, weights : (n, K) -- delays [s] and weights (0 = none)
    Returns (n, 2 S) delays and weights, S the most bins any pixel uses (unused: weight 0).
    """
    arrivals = np.asarray(arrivals_s, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    n, k = arrivals.shape
    has = weights > 0
    if n == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    t0 = np.where(has, arrivals, np.inf).min(axis=1, keepdims=True)
    t0 = np.where(np.isfinite(t0), t0, 0.0)
    row = np.broadcast_to(np.arange(n)[:, None], (n, k))[has]
    x = ((arrivals - t0) / window_s)[has]  # delay since the pixel's first, in bins
    b = np.floor(x).astype(np.int64)
    w, u = weights[has], x - b  # u: position inside the bin, [0, 1)
    n_bins = int(b.max()) + 1 if len(b) else 1
    key = row * n_bins + b
    if n * n_bins <= 8 * max(n * k, 1):  # dense: number the occupied bins of each row
        occupied = (np.bincount(key, minlength=n * n_bins) > 0).reshape(n, n_bins)
        position = np.cumsum(occupied, axis=1) - 1
        n_seg = max(int(position[:, -1].max()) + 1, 1)
        seg = position.ravel()[key]
    else:  # a few pixels span many bins: number the distinct keys instead
        keys, inverse = np.unique(key, return_inverse=True)
        first = np.searchsorted(keys // n_bins, np.arange(n))
        seg_of_key = np.arange(len(keys)) - first[keys // n_bins]
        n_seg = int(seg_of_key.max()) + 1
        seg = seg_of_key[inverse]
    dest = row * n_seg + seg
    m0 = np.bincount(dest, w, minlength=n * n_seg)
    safe = np.where(m0 > 0, m0, 1.0)
    mu = np.bincount(dest, w * u, minlength=n * n_seg) / safe
    d = u - mu[dest]  # central moments from deviations: no cancellation
    wd2 = w * d * d
    sd = np.sqrt(np.bincount(dest, wd2, minlength=n * n_seg) / safe)
    c3 = np.bincount(dest, wd2 * d, minlength=n * n_seg) / safe
    start = np.zeros(n * n_seg)
    start[dest] = b
    gamma = np.where(sd > 1e-9, c3 / np.maximum(sd, 1e-9) ** 3, 0.0)
    root = np.sqrt(gamma**2 + 4.0)
    z1, z2 = 0.5 * (gamma - root), 0.5 * (gamma + root)  # z1 z2 = -1, z1 + z2 = gamma
    p1 = z2 / (z2 - z1)
    t_nodes = np.stack([start + mu + sd * z1, start + mu + sd * z2], axis=-1) * window_s
    w_out = np.stack([m0 * p1, m0 * (1.0 - p1)], axis=-1).reshape(n, 2 * n_seg)
    t_out = t0 + t_nodes.reshape(n, 2 * n_seg)
    return np.where(w_out > 0, t_out, t0), w_out
