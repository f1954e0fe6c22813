"""Cancellation: a computation overtaken by a newer request stops between pipeline stages
(simcore.Cancelled) and is dropped like a stale result, never shown as an error."""

from __future__ import annotations

import dataclasses
import threading

import pytest

import simcore
from app.engine import Engine, Request
from app.main import LmapdApp
from app.runner import StaleRequest

SMALL = {"pixels": 32, "fidelity.subrays": 1}


@pytest.fixture(scope="module")
def model():
    return simcore.load_target(simcore.load_scene().target)


def test_the_engine_stops_between_stages_once_the_request_is_stale(model):
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    engine = Engine(scene, model=model)
    asked: list[int] = []

    def stale() -> bool:  # overtaken after the second stage that must compute
        asked.append(1)
        return len(asked) > 2

    with pytest.raises(StaleRequest):
        engine.compute(Request(scene), stale=stale)
    cached = set(engine.pipeline._cache)
    assert "cloud" not in cached and "echo" not in cached
    frame = engine.compute(Request(scene))  # the stages finished so far are reused
    assert frame.timings_s["target"] == 0.0 and frame.summary["n_points"] > 0


def test_an_overtaken_computation_is_dropped_without_an_error(model, monkeypatch):
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    app = LmapdApp(scene, engine=Engine(scene, model=model), flow_control=False, debounce_s=0.0)
    try:
        app.state.ready()
        assert app.logic.runner.wait_idle(60)
        entered, release = threading.Event(), threading.Event()
        chain = simcore.pipeline.CHAIN
        rays = next(stage for stage in chain if stage.name == "rays")

        def slow_rays(s):
            entered.set()
            release.wait(10)
            return rays.compute(s)

        slow = dataclasses.replace(rays, compute=slow_rays)
        monkeypatch.setattr(
            simcore.pipeline, "CHAIN", tuple(slow if s is rays else s for s in chain)
        )
        dropped = app.logic.runner.n_dropped
        with app.state:
            app.state.pixels = 48  # new rays: the worker blocks in the rays stage
        assert entered.wait(10)
        with app.state:
            app.state.tnr = 6.5  # overtakes the 48-pixel request
        release.set()
        assert app.logic.runner.wait_idle(60)
        assert app.logic.runner.n_dropped == dropped + 1
        assert app.state.error_message == ""
        result = app.logic.last_frame.result
        assert result.scene.timing.tnr == 6.5 and result.pixels == 48
    finally:
        app.logic.runner.close()
