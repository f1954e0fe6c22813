"""How many threads one frame may use (the ray cast and the echo features split over them).

Default: 2 (this project's machines have 2 cores; embreex and numpy release the GIL). Where frames
already run side by side, one per core (a Dask worker per core), set 1 to avoid oversubscription.
Results never depend on it.
"""

from __future__ import annotations

import os

_threads = max(1, min(2, os.cpu_count() or 1))


def set_threads(n: int) -> None:
    """Threads per frame, >= 1."""
    global _threads
    if int(n) < 1:
        raise ValueError(f"threads per frame must be >= 1, got {n}")
    _threads = int(n)


def threads() -> int:
    return _threads
