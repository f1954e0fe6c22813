"""How many threads one frame may use (the ray cast and the echo features split over them).

Default: the cores this process may use (``os.sched_getaffinity``; embreex, numpy and the compiled
kernel release the GIL), or ``LMAPD_THREADS``; ``lmapd --threads N`` and :func:`set_threads` set it.
Where frames already run side by side, one per core (a Dask worker per core), they set 1 to avoid
oversubscription. Results never depend on it (tests/core/test_threads.py).

A frame runs with the BLAS libraries single-threaded (:func:`blas_serial`): OpenBLAS's threads
spin-wait after each call, holding the cores the frame's own threads need (measured: a 2-thread ray
cast ran no faster than one thread after a single small matrix product).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import threadpoolctl

T = TypeVar("T")
R = TypeVar("R")

THREADS_ENV = "LMAPD_THREADS"


def available_cores() -> int:
    """The CPUs this process may run on (its affinity mask; all of them where there is none)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def default_threads() -> int:
    """Threads per frame unless set: ``LMAPD_THREADS`` if it is a whole number >= 1 (otherwise a
    warning names it and the cores are used), else :func:`available_cores`."""
    text = os.environ.get(THREADS_ENV, "").strip()
    if text:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n >= 1:
            return n
        import warnings  # noqa: PLC0415  (only for a bad setting)

        warnings.warn(
            f"{THREADS_ENV}={text!r} is not a whole number >= 1: using the "
            f"{available_cores()} cores this process may use",
            stacklevel=2,
        )
    return available_cores()


_threads = default_threads()


def set_threads(n: int) -> None:
    """Threads per frame, >= 1."""
    global _threads
    if int(n) < 1:
        raise ValueError(f"threads per frame must be >= 1, got {n}")
    _threads = int(n)


def threads() -> int:
    return _threads


def threads_for(n_items: int, serial_below: int) -> int:
    """Threads for a compiled parallel region over ``n_items``: :func:`threads`, or 1 below
    ``serial_below`` items. Waking a second thread costs tens of microseconds on an idle machine
    and milliseconds on a busy one (it waits for a core), whatever the work: a region of well
    under a millisecond of work gains nothing from it (measured, 2 cores at load 7: the cloud's
    ground truth and the detection's stops of a 256 x 256 frame, 0.1-0.3 ms each, no faster on
    two threads). Results never depend on it."""
    return threads() if n_items >= serial_below else 1


_PREFIX = "simcore-pool"
_pool = None
_pool_size = 0
_pool_lock = threading.Lock()


def _forget_pool_in_child() -> None:
    """In a process forked from this one: the pool's threads did not come along (only the
    forking thread does), so the pool is dropped and a new one made at the next call; the lock
    is new too (another thread may have held it at the fork). Without this, a frame in a child
    forked after a parallel frame (the app's sessions, forked from a parent that computed their
    first frame) waited for ever on threads that do not exist."""
    global _pool, _pool_size, _pool_lock
    _pool, _pool_size, _pool_lock = None, 0, threading.Lock()


if hasattr(os, "register_at_fork"):  # POSIX
    os.register_at_fork(after_in_child=_forget_pool_in_child)


def map_threads(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(x) for x in items]`` on the shared pool of ``threads()`` threads (kept alive between
    frames: starting threads per call costs more than small frames gain). Serial for one item or
    one thread, and inside one of the pool's own threads (a nested call would wait for threads
    that wait for it)."""
    global _pool, _pool_size
    if len(items) <= 1 or _threads == 1 or threading.current_thread().name.startswith(_PREFIX):
        return [fn(x) for x in items]
    with _pool_lock:
        if _pool is None or _pool_size != _threads:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=_threads, thread_name_prefix=_PREFIX)
            _pool_size = _threads
        pool = _pool
    return list(pool.map(fn, items))


_controller: threadpoolctl.ThreadpoolController | None = None


def blas_serial():
    """Context manager: the loaded BLAS libraries run single-threaded inside it."""
    global _controller
    with _pool_lock:
        if _controller is None:  # found once, after numpy and scipy have loaded their BLAS
            _controller = threadpoolctl.ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")
