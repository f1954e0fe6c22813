"""The orbits' input checks: times, vectors and rows of vectors as finite float arrays."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .elements import FloatArray, OrbitError


def time_array(t_s: ArrayLike, allow_empty: bool) -> FloatArray:
    """``t_s`` as a finite (n,) float array; OrbitError otherwise."""
    try:
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
    except (TypeError, ValueError):
        raise OrbitError(f"t_s must be an array of times in seconds, got {t_s!r}") from None
    if t.ndim != 1:
        raise OrbitError(f"t_s must be one-dimensional (n,), got shape {t.shape}")
    if not allow_empty and t.size == 0:
        raise OrbitError("t_s is empty: a pose series needs at least one time (duration of zero)")
    if not np.all(np.isfinite(t)):
        raise OrbitError("t_s must be finite (no NaN or inf)")
    return t


def vector3(x: ArrayLike, name: str) -> FloatArray:
    """``x`` as a finite (3,) float array; OrbitError otherwise."""
    array = np.asarray(x, dtype=float)
    if array.shape != (3,):
        raise OrbitError(f"{name} must have shape (3,), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise OrbitError(f"{name} must be finite (no NaN or inf)")
    return array


def rows3(x: ArrayLike, name: str) -> FloatArray:
    """``x`` as a finite (n, 3) float array ((3,) becomes (1, 3)); OrbitError otherwise."""
    array = np.atleast_2d(np.asarray(x, dtype=float))
    if array.ndim != 2 or array.shape[1] != 3:
        raise OrbitError(f"{name} must have shape (n, 3) or (3,), got {np.shape(x)}")
    if not np.all(np.isfinite(array)):
        raise OrbitError(f"{name} must be finite (no NaN or inf)")
    return array
