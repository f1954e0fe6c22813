"""Progressive frames: a preview (one ray per pixel, no refinement) goes to the page first when a
frame must recompute its geometry or waveforms, the chosen preset's frame replaces it; binary
payloads; the seen facets are sent only when the set changes."""

from __future__ import annotations

import numpy as np
import pytest
from support.app_helpers import change, small_app

import simcore
from app.engine import PREVIEW_FIDELITY, Engine, Request
from app.logic.controller import PREVIEW_LABEL
from app.main import LmapdApp
from app.server.zygote import warm_up


@pytest.fixture(scope="module")
def model():
    return simcore.load_target(simcore.load_scene().target)


@pytest.fixture
def app(model):
    """The paper scene at 64 x 64 with the interactive preset (refinement on), previews on; the
    previews the page was sent are listed in ``app.previews_shown``."""
    with small_app(64, model, preset="interactive") as app:
        shown: list[dict] = []
        apply_preview = app.logic.apply_preview

        def recording(generation, preview):
            before = app.logic.n_previews_pushed
            apply_preview(generation, preview)
            if app.logic.n_previews_pushed > before:
                shown.append(
                    {
                        "generation": generation,
                        "n_points": app.state.n_points,
                        "kind": app.state.frame_kind,
                        "key": app.state.frame_key,
                    }
                )

        app.logic.apply_preview = recording
        app.previews_shown = shown
        yield app


def test_a_distance_change_shows_the_preview_first_then_the_presets_frame(app, model):
    n0 = len(app.previews_shown)
    change(app, distance_m=450.0)
    assert len(app.previews_shown) == n0 + 1
    preview = app.previews_shown[-1]
    assert preview["kind"] == "preview" and preview["key"] == f"p{preview['generation']}"
    # the preview is the scene at one ray per pixel, no refinement: the same points as the core's
    scene = app.logic.last_frame.result.scene
    expected = simcore.simulate(simcore.with_overrides(scene, PREVIEW_FIDELITY))
    assert preview["n_points"] == len(expected.cloud)
    # ... and then the frame of the chosen preset replaces it, same request
    assert app.state.frame_kind == "preset" and app.state.frame_label == "interactive preset"
    assert app.state.frame_generation == preview["generation"]
    assert app.state.n_points == app.logic.last_frame.summary["n_points"]
    assert scene.fidelity.refine_subrays == 64  # the frame itself is refined
    assert PREVIEW_LABEL.startswith("preview")


def test_a_change_that_reruns_only_the_detection_shows_no_preview(app):
    n0 = len(app.previews_shown)
    change(app, tnr=4.0)
    change(app, pulse_energy_mj=3.0)
    assert len(app.previews_shown) == n0
    assert app.state.frame_kind == "preset"


def test_a_preview_of_an_overtaken_request_or_of_a_shown_frame_is_dropped(app):
    change(app, distance_m=470.0)
    logic = app.logic
    generation = app.state.frame_generation
    preview = logic.engine.compute_preview(Request(logic.last_frame.result.scene))
    n0, key = logic.n_previews_pushed, app.state.frame_key
    logic.apply_preview(generation, preview)  # its frame is on the page already
    logic.apply_preview(generation - 1, preview)  # an older request
    assert logic.n_previews_pushed == n0 and app.state.frame_key == key


def test_no_preview_when_previews_are_off(app):
    n0 = len(app.previews_shown)
    app.logic.previews = False
    change(app, distance_m=480.0)
    assert len(app.previews_shown) == n0 and app.state.frame_kind == "preset"
    app.logic.previews = True
    change(app, distance_m=490.0)
    assert len(app.previews_shown) == n0 + 1


def test_the_engine_wants_a_preview_only_when_it_is_quicker(model):
    scene = simcore.with_overrides(simcore.load_scene(), {"pixels": 32}, preset="interactive")
    engine = Engine(scene, model=model)
    assert engine.wants_preview(scene)  # nothing cached yet
    engine.compute(Request(scene))
    assert not engine.wants_preview(scene)  # cached: the frame itself comes at once
    assert not engine.wants_preview(simcore.with_overrides(scene, tnr=3.0))
    assert engine.wants_preview(simcore.with_overrides(scene, distance_m=520.0))
    at_preview_fidelity = engine.preview_scene(simcore.with_overrides(scene, distance_m=530.0))
    assert not engine.wants_preview(at_preview_fidelity)  # the frame is a preview already


def test_seen_facets_are_rebuilt_and_sent_only_when_the_set_of_facets_seen_changes(
    app, monkeypatch
):
    logic = app.logic
    before = logic.last_frame
    sent = []
    update = type(app.state).update  # the state's attributes are its keys: patch the class

    def recording(state, _dict=None, **values):
        if state is app.state:
            sent.append(set(_dict or {}) | set(values))
        return update(state, _dict, **values)

    monkeypatch.setattr(type(app.state), "update", recording)
    logic.engine.pipeline.clear()  # the next frame casts its rays anew: new hits ...
    change(app, tnr=float(app.state.tnr) + 0.5)
    after = logic.last_frame
    assert after.result.hits is not before.result.hits
    assert np.array_equal(after.result.visible_faces, before.result.visible_faces)  # same set
    assert after.faces_key == before.faces_key and after.seen_facets is before.seen_facets
    frames = [keys for keys in sent if "frame_key" in keys]
    assert frames and all("seen_facets" not in keys for keys in frames)
    change(app, pitch_deg=40.0)  # the target turns: another set of facets
    assert "seen_facets" in [keys for keys in sent if "frame_key" in keys][-1]
    assert logic.last_frame.faces_key != before.faces_key


def test_the_previews_and_the_frames_share_one_target_stage(model):
    """The previews keep a cache of their own, but not a second copy of the target's mesh and
    ray-casting structure: whichever pipeline builds the target stage first, the other takes it
    (and a target the other has not built yet is never taken in place of the right one)."""
    scene = simcore.with_overrides(simcore.load_scene(), pixels=16)
    engine = Engine(scene, model)
    engine.compute_preview(Request(scene=scene))
    engine.compute(Request(scene=scene))
    built = engine.preview_pipeline.cached("target", scene)
    assert built is not None and engine.pipeline.cached("target", scene) is built
    cube = simcore.with_overrides(scene, {"target.mesh": "cube"})
    engine.compute(Request(scene=cube))  # the frames move to another target first
    engine.compute_preview(Request(scene=scene))  # a preview of the first keeps its own
    assert engine.preview_pipeline.cached("target", scene) is built
    engine.compute_preview(Request(scene=cube))
    assert engine.preview_pipeline.cached("target", cube) is engine.pipeline.cached("target", cube)


def test_an_engine_takes_the_target_stage_of_a_shared_pipeline(model):
    """The sessions' preloaded parent builds the target stage once; each session's engine takes
    it for its frames and its previews (app.server.zygote)."""
    scene = simcore.with_overrides(simcore.load_scene(), pixels=8)
    shared = simcore.Pipeline()
    shared.run(scene)
    engine = Engine(scene, model, shared=shared)
    built = shared.cached("target", scene)
    engine.compute(Request(scene=scene))
    engine.compute_preview(Request(scene=scene))
    assert engine.pipeline.cached("target", scene) is built
    assert engine.preview_pipeline.cached("target", scene) is built


def test_a_forked_sessions_first_frame_is_its_parents_and_only_its_views_are_built(model):
    """The sessions' preloaded parent computes the app's first frame (at the controls a page
    starts with) once; a session forked from it takes every stage of that frame and builds only
    its views, instead of computing the same frame again (a class opening the printed address
    together starts many sessions at once)."""
    scene = simcore.load_scene()
    shared = warm_up(scene, model)
    app = LmapdApp(
        scene, engine=Engine(scene, model, shared=shared), flow_control=False, debounce_s=0.0
    )
    try:
        app.state.ready()
        assert app.logic.runner.wait_idle(120)
        frame = app.logic.last_frame
        assert frame is not None and frame.summary["n_points"] > 0
        assert set(frame.timings_s.values()) == {0.0}, frame.timings_s  # every stage cached
        first = frame.result.scene
        for name in simcore.STAGES:
            assert app.engine.pipeline.cached(name, first) is shared.cached(name, first), name
    finally:
        app.logic.runner.close()
