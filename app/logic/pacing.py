"""Frame pacing: frames go to the page no faster than it draws them, a child of the app's logic.

At most ``max_in_flight`` frames (default 2) are sent and not yet reported drawn by the page; a
report older than ``ack_timeout_s`` is not waited for (a hidden tab does not paint). A frame that
must wait is held, and only the newest one is kept, so a slow browser never builds a queue of
stale frames.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class FramePacer(Generic[T]):
    """The frames in flight (sent, not yet drawn) and the one frame held back.

    enabled : False sends every frame at once (tests without a page)
    max_in_flight : frames sent and not yet reported drawn before the next one waits [1]
    ack_timeout_s : how long an unreported frame counts as in flight [s]
    clock : the time [s] the frames in flight are aged by (tests: one that moves only when told)
    """

    def __init__(
        self,
        *,
        enabled: bool = True,
        max_in_flight: int = 2,
        ack_timeout_s: float = 1.0,
        clock: Callable[[], float] = time.perf_counter,
    ):
        self.enabled = enabled
        self.max_in_flight = max_in_flight
        self.ack_timeout_s = ack_timeout_s
        self.clock = clock
        self.held: T | None = None
        self._inflight: dict[str, float] = {}  # frame key -> time sent [s, clock]

    def wait_s(self) -> float:
        """0 if a frame may be sent now, else how long until the oldest unreported frame stops
        counting [s]."""
        if not self.enabled:
            return 0.0
        now = self.clock()
        self._inflight = {k: t for k, t in self._inflight.items() if now - t < self.ack_timeout_s}
        if len(self._inflight) < self.max_in_flight:
            return 0.0
        return self.ack_timeout_s - (now - min(self._inflight.values()))

    def hold(self, frame: T) -> None:
        """Keep ``frame`` until the page catches up (it replaces any older held frame)."""
        self.held = frame

    def release(self) -> T | None:
        """The held frame if it may go now (it is no longer held), else None."""
        if self.held is None or self.wait_s() > 0:
            return None
        frame, self.held = self.held, None
        return frame

    def sent(self, key: str) -> None:
        """Frame ``key`` went to the page; anything held is older and is dropped."""
        self._inflight[key] = self.clock()
        self.held = None

    def drawn(self, key: object) -> bool:
        """The page reports frame ``key`` drawn (so every frame sent before it too); True if it
        was one of ours in flight."""
        sent_at = self._inflight.get(key) if isinstance(key, str) else None
        if sent_at is None:
            return False
        self._inflight = {k: t for k, t in self._inflight.items() if t > sent_at}
        return True
