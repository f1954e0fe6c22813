"""The declaration of one stage of the imaging chain, written next to the physics it runs.

Each stage module declares its stage with a :class:`Stage` record: its name, the stages whose
outputs it takes, the scene values it reads and the function that computes it. The pipeline
(``simcore.pipeline``) caches each stage's output under its declared reads plus its upstream
stages' keys, so a stage that forgets a value it reads serves a stale output when only that value
changes (``tests/core/test_cache_keys.py`` changes every scene key to catch that).
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .scene import Scene


class Cancelled(Exception):
    """Pipeline.run was told to stop (its result would be stale)."""


# the ``should_stop`` of the Pipeline.run under way in this thread (None: none, or no callback)
_SHOULD_STOP: contextvars.ContextVar[Callable[[], bool] | None] = contextvars.ContextVar(
    "simcore_should_stop", default=None
)


def stop_check() -> Callable[[], bool] | None:
    """The ``should_stop`` of the Pipeline.run under way in this thread, for a long stage to
    poll between its blocks (from its own worker threads too: take it in the stage's thread);
    a True answer should end the stage with :class:`Cancelled`."""
    return _SHOULD_STOP.get()


@dataclass(frozen=True, kw_only=True)
class Stage:
    """One stage of the imaging chain.

    name : the stage's name (one of ``simcore.STAGES``)
    upstream : the stages whose outputs ``compute`` takes, in this order, after the scene
    reads : scene -> a hashable tuple of every scene value the stage reads (with the upstream
        stages' keys, its cache key)
    compute : (scene, *upstream outputs) -> the stage's output (its arrays read-only)
    """

    name: str
    upstream: tuple[str, ...]
    reads: Callable[[Scene], tuple]
    compute: Callable[..., Any]


def readonly(*arrays) -> None:
    """Mark the given arrays read-only (cached stage outputs are shared); skips None."""
    for a in arrays:
        if isinstance(a, np.ndarray):
            a.setflags(write=False)
