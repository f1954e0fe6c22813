"""Helpers shared by the app tests that drive the server state without a browser."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

from hypothesis import strategies as st

import simcore
from app.engine import Engine
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


@contextlib.contextmanager
def small_app(pixels: int = 48, model=None, preset: str | None = None) -> Iterator[LmapdApp]:
    """An app on the paper scene at ``pixels`` x ``pixels`` with one ray per pixel (or the
    fidelity ``preset``), its state ready, frames applied at once (no page to pace them); closed
    and its uploads removed after. ``model``: an already loaded target to share (else the paper
    scene's is loaded)."""
    fidelity = {"preset": preset} if preset else {"fidelity.subrays": 1}
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": pixels, **fidelity})
    engine = Engine(scene) if model is None else Engine(scene, model=model)
    app = LmapdApp(scene, engine=engine, flow_control=False, debounce_s=0.0)
    app.state.ready()  # fires the change handlers once, like a server start
    settle(app)
    try:
        yield app
    finally:
        app.logic.runner.close()
        app.uploads.files.cleanup()


def stat(app: LmapdApp, label: str) -> str:
    """The value the stats panel shows on the row ``label``."""
    return next(r["value"] for r in app.state.stats if r["label"] == label)
