"""Helpers shared by the app tests that drive the server state without a browser."""

from __future__ import annotations

import time

from hypothesis import strategies as st

from app.main import LmapdApp

# any value a page (or a hostile client) might send for a state variable
ANYTHING = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.integers(), max_size=2),
)


def settle(app: LmapdApp, timeout_s: float = 60.0) -> None:
    """Wait until the runner is idle and the page state is no longer busy."""
    assert app.logic.runner.wait_idle(timeout_s)
    deadline = time.monotonic() + timeout_s
    while app.state.busy and time.monotonic() < deadline:
        time.sleep(0.01)


def change(app: LmapdApp, wait_busy: bool = True, **values) -> None:
    """Write state values as the page would, then wait for the result (or only for the runner)."""
    with app.state:
        app.state.update(values)
    if wait_busy:
        settle(app)
    else:
        assert app.logic.runner.wait_idle(30)
