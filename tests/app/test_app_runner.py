"""The runner: computes off the calling thread, debounces bursts, stamps generations, drops
stale results, reports errors as outcomes and keeps working after them."""

from __future__ import annotations

import threading
import time

import pytest
from support.fork import in_forked_child

from app.runner import Outcome, Runner, StaleRequest


class Recorder:
    """A deliver callback that records outcomes and the thread they came from."""

    def __init__(self):
        self.outcomes: list[Outcome] = []
        self.threads: set[str] = set()
        self.event = threading.Event()

    def __call__(self, outcome: Outcome) -> None:
        self.outcomes.append(outcome)
        self.threads.add(threading.current_thread().name)
        self.event.set()


@pytest.fixture
def make_runner():
    runners: list[Runner] = []

    def make(compute, deliver, **options):
        runner = Runner(compute, deliver, **options)
        runners.append(runner)
        return runner

    yield make
    for runner in runners:
        runner.close()


def test_the_computation_runs_in_the_worker_thread_not_the_callers(make_runner):
    seen = Recorder()
    threads: list[str] = []

    def compute(x):
        threads.append(threading.current_thread().name)
        return x * 2

    runner = make_runner(compute, seen, debounce_s=0.0)
    generation = runner.submit(21)
    assert runner.wait_idle(5)
    assert [(o.generation, o.value, o.ok) for o in seen.outcomes] == [(generation, 42, True)]
    assert threads == ["lmapd-runner"] and threading.current_thread().name not in threads


def test_a_burst_of_requests_within_the_debounce_computes_only_the_last(make_runner):
    seen = Recorder()
    computed: list[int] = []
    runner = make_runner(lambda x: computed.append(x) or x, seen, debounce_s=0.1, max_wait_s=1.0)
    for value in range(10):
        runner.submit(value)
    assert runner.wait_idle(5)
    assert computed == [9]
    assert [o.generation for o in seen.outcomes] == [10]


def test_a_result_overtaken_by_a_newer_request_is_dropped(make_runner):
    seen = Recorder()
    started, release = threading.Event(), threading.Event()

    def compute(x):
        if x == "slow":
            started.set()
            release.wait(5)
        return x

    runner = make_runner(compute, seen, debounce_s=0.0)
    runner.submit("slow")
    assert started.wait(5)
    newer = runner.submit("fresh")  # arrives while "slow" is computing
    release.set()
    assert runner.wait_idle(5)
    assert [(o.generation, o.value) for o in seen.outcomes] == [(newer, "fresh")]
    assert runner.n_dropped == 1 and runner.n_computed == 2


def test_a_drag_never_queues_more_than_one_waiting_request(make_runner):
    seen = Recorder()
    computed: list[int] = []

    def compute(x):
        time.sleep(0.05)
        computed.append(x)
        return x

    runner = make_runner(compute, seen, debounce_s=0.0, max_wait_s=0.0)
    for value in range(40):  # a slider drag: one value every 5 ms, faster than the compute
        runner.submit(value)
        time.sleep(0.005)
    assert runner.wait_idle(5)
    assert len(computed) <= 6  # 40 requests, about 200 ms of dragging, 50 ms per computation
    assert computed[-1] == 39 and seen.outcomes[-1].value == 39


def test_max_wait_keeps_a_long_drag_updating_despite_the_debounce(make_runner):
    seen = Recorder()
    runner = make_runner(lambda x: x, seen, debounce_s=0.05, max_wait_s=0.1)
    t_end = time.monotonic() + 0.5
    value = 0
    while time.monotonic() < t_end:  # never quiet for 50 ms
        value += 1
        runner.submit(value)
        time.sleep(0.01)
    assert runner.wait_idle(5)
    assert len(seen.outcomes) >= 3  # delivered during the drag, not only after it


def test_an_error_is_delivered_as_an_outcome_and_the_worker_keeps_going(make_runner):
    seen = Recorder()

    def compute(x):
        if x < 0:
            raise ValueError("negative input")
        return x

    runner = make_runner(compute, seen, debounce_s=0.0)
    runner.submit(-1)
    assert runner.wait_idle(5)
    runner.submit(3)
    assert runner.wait_idle(5)
    first, second = seen.outcomes
    assert not first.ok and isinstance(first.error, ValueError) and first.value is None
    assert second.ok and second.value == 3


def test_a_failing_deliver_does_not_kill_the_worker(make_runner):
    calls: list[int] = []

    def deliver(outcome):
        calls.append(outcome.value)
        if outcome.value == 1:
            raise RuntimeError("broken view")

    runner = make_runner(lambda x: x, deliver, debounce_s=0.0)
    runner.submit(1)
    assert runner.wait_idle(5)
    runner.submit(2)
    assert runner.wait_idle(5)
    assert calls == [1, 2]


def test_generations_increase_and_is_current_tracks_the_newest(make_runner):
    runner = make_runner(lambda x: x, lambda o: None, debounce_s=0.2)
    g1, g2 = runner.submit("a"), runner.submit("b")
    assert g2 == g1 + 1 == 2
    assert runner.is_current(g2) and not runner.is_current(g1)
    assert runner.busy
    assert runner.wait_idle(5) and not runner.busy


def test_a_closed_runner_refuses_requests():
    runner = Runner(lambda x: x, lambda o: None)
    runner.close()
    with pytest.raises(RuntimeError):
        runner.submit(1)


def test_a_computation_can_give_up_once_overtaken(make_runner):
    seen = Recorder()
    started, release = threading.Event(), threading.Event()
    gave_up: list[str] = []
    runner: Runner

    def compute(x):
        if x == "slow":
            started.set()
            release.wait(5)
            if runner.computing_is_stale():
                gave_up.append(x)
                raise StaleRequest
        return x

    runner = make_runner(compute, seen, debounce_s=0.0)
    runner.submit("slow")
    assert started.wait(5)
    assert not runner.computing_is_stale()
    runner.submit("fresh")
    release.set()
    assert runner.wait_idle(5)
    assert gave_up == ["slow"] and [o.value for o in seen.outcomes] == ["fresh"]
    assert runner.n_dropped == 1


def test_a_steady_stream_of_changes_still_shows_frames_every_min_refresh():
    """Changes faster than a frame computes: overtaken frames are shown as interim frames at
    least every min_refresh_s instead of none until the stream stops."""
    delivered = []
    runner = Runner(
        lambda x: (time.sleep(0.05), x)[1],
        delivered.append,
        debounce_s=0.0,
        max_wait_s=0.0,
        min_refresh_s=0.2,
    )
    try:
        t_end = time.perf_counter() + 1.5
        n = 0
        while time.perf_counter() < t_end:
            n += 1
            runner.submit(n)
            time.sleep(0.01)  # a change every 10 ms, a frame takes 50 ms
        assert runner.wait_idle(5.0)
    finally:
        runner.close()
    interim = [o for o in delivered if o.interim]
    assert len(interim) >= 4  # about every 0.2 s of the 1.5 s stream
    assert delivered[-1].value == n and not delivered[-1].interim  # the final state comes last
    generations = [o.generation for o in delivered]
    assert generations == sorted(generations)


def test_after_a_pause_an_overtaken_request_is_dropped_not_shown_as_an_interim_frame():
    """The refresh clock starts with the changes, not with the last frame: after a quiet spell
    longer than min_refresh_s, the first value of a drag that a newer one overtakes is dropped
    (it used to be computed to the end and shown, delaying the value the drag ended on)."""
    delivered = []
    started = threading.Event()
    runner = Runner(
        lambda x: (started.set(), time.sleep(0.1), x)[-1],
        delivered.append,
        debounce_s=0.0,
        max_wait_s=0.0,
        min_refresh_s=0.2,
    )
    try:
        runner.submit("before")
        assert runner.wait_idle(5.0)
        time.sleep(0.3)  # a pause longer than min_refresh_s
        started.clear()
        runner.submit("first move")
        assert started.wait(5.0)
        runner.submit("last move")  # overtakes the first while it computes
        assert runner.wait_idle(5.0)
    finally:
        runner.close()
    assert [o.value for o in delivered] == ["before", "last move"]
    assert not any(o.interim for o in delivered) and runner.n_dropped == 1


def test_a_runner_in_a_forked_process_starts_its_own_worker():
    """The app's sessions are forked from a parent that built their app, runner included; the
    runner's worker thread stays behind in the parent, so the child's first request starts a
    worker of its own (not counted as a restart: nothing died), and is served."""
    got: list = []
    runner = Runner(lambda x: x * 10, got.append, debounce_s=0.0)
    try:

        def child() -> list:
            runner.submit(4)
            served = runner.wait_idle(30)
            return [served, [o.value for o in got], runner.n_restarts]

        answer = in_forked_child(child)
        assert answer == [True, [40], 0]
        runner.submit(5)  # the parent's own worker still serves
        assert runner.wait_idle(30) and [o.value for o in got] == [50]
    finally:
        runner.close()
