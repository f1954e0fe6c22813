"""Run requests off the UI thread: debounce, one worker thread, a generation counter.

``submit`` stamps each request with the next generation and keeps only the newest one waiting (a
mailbox of one, so a slider drag never builds a queue). The worker waits until the requests have
been quiet for ``debounce_s`` (but no longer than ``max_wait_s`` after the first unserved one, so
a long drag still updates), computes the newest, and hands the outcome to ``deliver`` only if no
newer request arrived meanwhile; stale outcomes are dropped and counted, except that while
changes keep coming faster than a frame computes, an overtaken frame is still delivered (marked
``interim``) when none has been delivered for ``min_refresh_s`` since the changes began (or
since the last delivery), so a long drag keeps updating while the first values of a new drag,
after a pause, are still dropped when overtaken.

``compute`` runs in the worker thread only, so it may own objects that are not thread-safe
(simcore's Pipeline); it may call ``computing_is_stale`` and raise ``StaleRequest`` to give up
early on a request that has been overtaken. ``deliver`` is called from the worker thread too:
it must hand the outcome over to the UI thread itself (the app posts it to the event loop).
"""

from __future__ import annotations

import logging
import os
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

Request = TypeVar("Request")
Value = TypeVar("Value")

log = logging.getLogger(__name__)

# the open runners of this process: a process forked from it has none of their worker threads
_runners: weakref.WeakSet[Runner] = weakref.WeakSet()


def _after_fork_in_child() -> None:
    """In a process forked from this one (the app's sessions, forked from a parent that built
    their app): each runner's worker thread stayed behind, so each gets a new lock and starts a
    new worker at its first request (not counted as a restart: nothing died)."""
    for runner in list(_runners):
        runner._cond = threading.Condition()
        runner._computing = False
        runner._forked = True


if hasattr(os, "register_at_fork"):  # POSIX
    os.register_at_fork(after_in_child=_after_fork_in_child)


class StaleRequest(Exception):
    """Raised by ``compute`` to abandon a request that a newer one has overtaken (see
    ``Runner.computing_is_stale``); the runner drops it like any stale outcome."""


@dataclass(frozen=True)
class Outcome(Generic[Value]):
    """The result of one request: a value, or the exception its computation raised."""

    generation: int
    value: Value | None = None
    error: BaseException | None = None
    compute_s: float = 0.0
    submitted_at_s: float = 0.0  # time.perf_counter() at submit
    interim: bool = False  # overtaken, but delivered so that a long drag keeps updating

    @property
    def ok(self) -> bool:
        return self.error is None


class Runner(Generic[Request, Value]):
    """Debounced, generation-stamped, latest-wins execution of ``compute`` in one worker thread."""

    def __init__(
        self,
        compute: Callable[[Request], Value],
        deliver: Callable[[Outcome[Value]], None],
        *,
        debounce_s: float = 0.02,
        max_wait_s: float = 0.1,
        min_refresh_s: float = 0.5,
        name: str = "lmapd-runner",
        refusals: tuple[type[BaseException], ...] = (),
    ):
        """``refusals``: the exceptions that are answers, not faults (a request the core or the
        server refuses, with a message for the user): logged in one line, without a trace."""
        self._compute = compute
        self.refusals = refusals
        self._deliver = deliver
        self.debounce_s = debounce_s
        self.max_wait_s = max_wait_s
        self.min_refresh_s = min_refresh_s
        self._last_delivered_s = time.perf_counter()
        self._cond = threading.Condition()
        self._generation = 0
        self._pending: tuple[int, Request, float] | None = None
        self._first_unserved_s = 0.0
        self._last_submit_s = 0.0
        self._burst_start_s = 0.0  # the first request after the runner was idle
        self._computing = False
        self._computing_generation = 0
        self._closed = False
        self.n_computed = 0
        self.n_dropped = 0
        self.n_restarts = 0  # workers replaced after dying (see _ensure_worker)
        self._name = name
        self._forked = False  # this process was forked after the worker started (see above)
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()
        _runners.add(self)

    # -- the UI side -----------------------------------------------------------------------------
    def submit(self, request: Request) -> int:
        """Queue ``request`` (replacing any request still waiting); return its generation."""
        now = time.perf_counter()
        with self._cond:
            if self._closed:
                raise RuntimeError("the runner is closed")
            self._ensure_worker()
            if self._pending is None and not self._computing:
                self._burst_start_s = now  # changes begin (again) after a quiet spell
            self._generation += 1
            if self._pending is None:
                self._first_unserved_s = now
            self._pending = (self._generation, request, now)
            self._last_submit_s = now
            self._cond.notify_all()
            return self._generation

    @property
    def generation(self) -> int:
        """The newest generation handed out."""
        with self._cond:
            return self._generation

    def is_current(self, generation: int) -> bool:
        """True if no newer request than ``generation`` has been submitted."""
        with self._cond:
            return generation == self._generation

    def computing_is_stale(self) -> bool:
        """From inside ``compute``: a newer request has arrived and this result will be dropped
        (not when no frame has been delivered for ``min_refresh_s``: then it is shown anyway)."""
        with self._cond:
            overtaken = self._computing and self._computing_generation != self._generation
            return overtaken and not self._refresh_due()

    def _refresh_due(self) -> bool:
        """With the lock held: no outcome delivered for ``min_refresh_s``, counted from the last
        delivery or, if later, from the start of the current run of changes (after a pause the
        page shows a fresh frame already: the first values of a drag are not worth showing)."""
        since_s = max(self._last_delivered_s, self._burst_start_s)
        return time.perf_counter() - since_s >= self.min_refresh_s

    @property
    def computing_generation(self) -> int:
        """From inside ``compute``: the generation of the request being computed."""
        with self._cond:
            return self._computing_generation

    @property
    def busy(self) -> bool:
        """A request is waiting or being computed."""
        with self._cond:
            return self._computing or self._pending is not None

    def wait_idle(self, timeout_s: float = 30.0) -> bool:
        """Block until nothing is waiting or computing (for tests and scripts)."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while self._computing or self._pending is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(remaining)
        return True

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the worker after its current computation."""
        with self._cond:
            self._closed = True
            self._pending = None
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)

    # -- the worker side -------------------------------------------------------------------------
    def _next_request(self) -> tuple[int, Request, float] | None:
        """Wait for a request and for the debounce; None when closed."""
        with self._cond:
            while self._pending is None and not self._closed:
                self._cond.wait()
            while not self._closed:
                now = time.perf_counter()
                quiet_until = self._last_submit_s + self.debounce_s
                deadline = min(quiet_until, self._first_unserved_s + self.max_wait_s)
                if now >= deadline:
                    break
                self._cond.wait(deadline - now)
            if self._closed or self._pending is None:
                return None
            pending, self._pending = self._pending, None
            self._computing = True
            self._computing_generation = pending[0]
            return pending

    def _ensure_worker(self) -> None:
        """With the lock held: start a new worker if the current one died (it raised something
        no ``except Exception`` catches, or its thread ended while the runner is open)."""
        if self._thread.is_alive() or self._closed:
            return
        if self._forked:  # a new process: its worker starts now
            self._forked = False
        else:
            log.warning("the runner's worker thread died; starting a new one")
            self._computing = False
            self.n_restarts += 1
        self._thread = threading.Thread(target=self._loop, name=self._name, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        """The worker: serve requests until closed; if serving dies, report the request it was
        computing as failed and hand over to a new worker."""
        try:
            self._serve()
        except BaseException as exc:  # the worker must survive anything
            log.exception("the runner's worker died")
            with self._cond:
                generation = self._computing_generation if self._computing else 0
                self._computing = False
                self._cond.notify_all()
            if generation and self.is_current(generation):
                try:
                    error = RuntimeError(f"the worker stopped ({type(exc).__name__}); restarted")
                    self._deliver(Outcome(generation, error=error))
                except Exception:
                    log.exception("delivering the worker's failure failed")
            with self._cond:
                if self._thread is threading.current_thread() and not self._closed:
                    self.n_restarts += 1
                    self._thread = threading.Thread(target=self._loop, name=self._name, daemon=True)
                    self._thread.start()

    def _serve(self) -> None:
        while True:
            job = self._next_request()
            if job is None:
                return
            generation, request, submitted_at = job
            t0 = time.perf_counter()
            try:
                outcome = Outcome(generation, value=self._compute(request))
            except StaleRequest:
                outcome = None
            except self.refusals as exc:
                log.info("generation %d refused: %s", generation, exc)
                outcome = Outcome(generation, error=exc)
            except Exception as exc:  # shown to the user as a message, logged with its trace
                log.exception("computation of generation %d failed", generation)
                outcome = Outcome(generation, error=exc)
            self.n_computed += 1
            stale = outcome is None or not self.is_current(generation)
            with self._cond:
                interim = stale and outcome is not None and outcome.ok and self._refresh_due()
            if outcome is not None:
                outcome = Outcome(
                    generation,
                    outcome.value,
                    outcome.error,
                    compute_s=time.perf_counter() - t0,
                    submitted_at_s=submitted_at,
                    interim=interim,
                )
            if stale and not interim:
                self.n_dropped += 1
            else:
                with self._cond:
                    self._last_delivered_s = time.perf_counter()
                try:
                    self._deliver(outcome)
                except Exception:  # a broken deliver must not kill the worker
                    log.exception("delivering generation %d failed", generation)
            with self._cond:
                self._computing = False
                self._cond.notify_all()
