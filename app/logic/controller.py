"""The app's logic on the UI thread: state changes -> Scene -> runner; frames -> state.

The parent of one child per feature, which it calls (they never call it; where a child must ask
for a new frame, the parent hands it a callback): the controls (``ControlPanel``: sanitised,
corrections written back), the pixel selection (``PixelSelection``), the frame pacing
(``FramePacer``: no more frames than the page draws), the fly-around (``FlyaroundLogic``), the
uploaded targets (``TargetUploads``), the lessons (``LessonGuide``) and the pinned frame
(``FrameCompare``). A valid scene goes to the
runner, which computes in its worker thread; finished frames come back through the event loop and
are applied only if they are still the newest generation.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import threading
import time
from typing import Any

import numpy as np

import simcore
from app.engine import Engine, Frame, FrameRefused, Preview, Request, check_memory
from app.logic import exports
from app.logic.attitudes import AttitudeMap
from app.logic.compare import FrameCompare
from app.logic.controls import ControlPanel
from app.logic.flyaround import FlyaroundLogic
from app.logic.lessons import BY_KEY, LessonGuide
from app.logic.links import controls_from_link, link_names, link_query
from app.logic.pacing import FramePacer
from app.logic.parts import PartHighlight
from app.logic.physics_page import PhysicsPage
from app.logic.scene_map import resolved_materials, scene_from_controls
from app.logic.selection import PixelSelection
from app.logic.studies import DesignStudies
from app.logic.upload import LoadedTarget, TargetUploads
from app.payloads import scene3d, stats, style
from app.payloads import waveforms as waveforms_payload
from app.runner import Outcome, Runner
from app.state import SPECS, Controls, controls_from_scene, preset_of, state_keys
from simcore.target import fov_fill_distance_m, parts_table


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


class AppLogic:
    """Binds the engine and the runner to a trame server's state and triggers."""

    def __init__(
        self,
        server,
        engine: Engine,
        base_scene: simcore.Scene,
        *,
        debounce_s: float = 0.008,
        flow_control: bool = True,
        ack_timeout_s: float = 1.0,
        max_in_flight: int = 2,
        previews: bool = True,
        studies_dir: str | None = None,
    ):
        self.server = server
        self.state = server.state
        self.engine = engine
        self.base_scene = base_scene
        initial_controls, startup_messages = controls_from_scene(
            base_scene, resolved_materials(engine.model, base_scene)
        )
        self.last_frame: Frame | None = None
        self.n_frames_pushed = 0
        self.n_previews_pushed = 0
        self.previews = previews  # a preview first when a frame must recompute its geometry
        self._loop: asyncio.AbstractEventLoop | None = None
        self._applied_faces_key: tuple | None = None
        self._pushed_generation = 0  # generation of the frame the page shows
        # the controls of each request under way, and those of the frame the page shows (a
        # refused frame's controls go back to them)
        self._controls_of: dict[int, Controls] = {}
        self._shown_controls = initial_controls
        self._keep_message = False  # the next frame is the one shown again after a refusal
        # the launcher's memory budget for heavy frames across sessions (a session's process
        # sets it: app.server.frame_memory.FrameGrants); None: this process's own limit only
        self.frame_grants: Any = None
        self.runner: Runner[Request, Frame] = Runner(
            self._compute,
            self._deliver,
            debounce_s=debounce_s,
            refusals=(simcore.SceneError, FrameRefused),
        )
        # the children, one per feature
        self.panel = ControlPanel(self.state, initial_controls)  # the scene's controls
        self.selection = PixelSelection(self.state)  # the waveform chart's pixels
        self.pacer: FramePacer[Outcome[Frame]] = FramePacer(
            enabled=flow_control, max_in_flight=max_in_flight, ack_timeout_s=ack_timeout_s
        )
        self._init_state(startup_messages)
        self.state.change(*state_keys())(self.on_controls_change)  # the receivers' too
        self.flyaround = FlyaroundLogic(  # mode, time slider, play (its own state)
            self.state,
            fov_rad=self.base_scene.receive.fov_rad,
            runner=self.runner,
            resubmit=self.on_controls_change,
            on_ui_thread=self._on_ui_thread,  # the pose track's estimates, from its worker
        )
        self.uploads = TargetUploads(  # users' meshes (their own state)
            server,
            builtin=LoadedTarget(base_scene, engine, None, 0),
            builtin_initial=initial_controls,
            use_target=self.use_target,
        )
        self.attitudes = AttitudeMap(server, lambda: self.engine, self._on_ui_thread)  # the map
        self.lessons = LessonGuide(self.state)  # one-click scenes with a card (their own state)
        self.compare = FrameCompare(self.state)  # a pinned frame beside the new one
        self.studies = DesignStudies(self.state, studies_dir, self.open_scene)  # Design page
        server.trigger("open_design")(self.studies.open_design)
        server.trigger("score_quality")(self.score_quality)
        self.state.update({"quality_rows": [], "quality_busy": False})
        server.trigger("pin_frame")(self.pin_frame)
        server.trigger("unpin_frame")(self.compare.unpin)
        self.parts = PartHighlight(self.state, lambda: self.engine.model)  # in the 3D scene
        server.trigger("pixel_click")(self.on_pixel_click)
        server.trigger("pixel_hover")(lambda *a, **_: self.selection.hover(self.last_frame, *a[:2]))
        server.trigger("frame_shown")(self.on_frame_shown)
        server.trigger("reset_controls")(self.reset_controls)
        server.trigger("open_link")(self.open_link)
        server.trigger("fit_field_of_view")(self.fit_field_of_view)
        server.trigger("export_cloud")(self.export_cloud)
        server.trigger("export_waveforms")(self.export_waveforms)
        server.trigger("export_scene")(self.export_scene)
        server.trigger("open_lesson")(self.open_lesson)
        server.trigger("leave_lesson")(self.lessons.leave)
        # a card's "Read more" and the physics page's sections (their own state)
        self.physics = PhysicsPage(self.state, texts=BY_KEY)
        server.trigger("read_more")(self.physics.read_more)
        server.trigger("open_physics")(self.physics.open)
        server.trigger("close_physics")(self.physics.close)
        server.controller.on_server_exited.add(lambda **_: self.runner.close())
        server.controller.on_server_exited.add(lambda **_: self.flyaround.pose_track.close())

    @property
    def controls(self) -> Controls:
        """The controls of the newest valid scene."""
        return self.panel.current

    @property
    def initial_controls(self) -> Controls:
        """The controls a reset returns to."""
        return self.panel.initial

    # -- state ------------------------------------------------------------------------------------
    def _init_state(self, startup_messages: list[str]) -> None:
        model = self.engine.model
        geometry = self.engine.target_geometry()
        self.state.update(
            {
                **self.initial_controls.as_state(),
                "scene_name": self.base_scene.name,
                "target_name": model.name,
                "credit": model.credit or "",
                "part_names": list(model.part_names),
                "part_info": part_info(model),
                "material_items": [
                    {"title": simcore.MATERIALS[n].label or n, "value": n}
                    for n in simcore.MATERIAL_NAMES
                ],
                "target_points": geometry["points"],
                "target_polys": geometry["polys"],
                "seen_facets": None,
                "home_camera": self.engine.home_camera(),
                "scene_camera": None,
                "frustum": None,
                "footprint_text": "",
                "sun_arrow": None,  # the Sun and the Earth seen from the target (scene3d)
                "earth_arrow": None,
                "sun_text": "",
                "earth_text": "",
                "cloud_points": None,
                "cloud_outliers": None,
                "cloud_colorbar": None,
                "n_target_points": 0,
                "n_outliers": 0,
                "legend": [],
                "array_image": {"png": None, "colorbar": None, "pixels": 0},
                "selected_pixels": [],
                "pixel_readout": None,
                "selection_colors": list(style.SELECTION_COLORS),
                "waveforms": {"data": [], "layout": {}},
                "view_text": waveforms_payload.view_text(self.base_scene.receiver.kind),
                "snr_hist": {"data": [], "layout": {}},
                "stats": [],
                "stages": [],
                "busy": True,
                "error_message": "",
                "memory_message": "",  # a heavy frame waiting for the server's memory
                "input_message": " ".join(startup_messages),
                "frame_key": "",
                "frame_generation": 0,
                "frame_kind": "",
                "frame_label": "",
                "n_points": 0,
                "share_query": link_query(self.panel.current, self.panel.initial),
            }
        )

    def on_controls_change(self, **_: Any) -> None:
        """Any control changed: sanitise, write back corrections, submit the new scene."""
        controls = self.panel.read()
        self.state.share_query = link_query(controls, self.panel.initial)
        try:
            scene = self.flyaround.apply(scene_from_controls(self.base_scene, controls))
        except ValueError as exc:  # SceneError: a value the core refuses
            self.state.error_message = f"Refused: {on_screen(str(exc))}" + self._restore_shown()
            return
        self.submit(scene)

    def submit(self, scene: simcore.Scene) -> int:
        """Hand ``scene`` to the runner; the busy indicator shows until its frame is pushed."""
        if self.server.running:  # the trame server's event loop (not, say, a test tool's)
            self._loop = _running_loop() or self._loop
        request = Request(
            scene=scene,
            color_by=self.controls.color_by,
            image_kind=self.controls.image_kind,
            selection=self.selection.current(),
            selection_pixels=self.selection.array_pixels,
            selection_tangents=self.selection.tangents(),
            # not while the fly-around plays: each of its frames is shown at the preset
            preview_first=self.previews and not self.state.fly_playing,
        )
        self.state.busy = True
        self.attitudes.scene_changed(scene)  # a map of another scene stops
        generation = self.runner.submit(request)
        self._controls_of[generation] = self.panel.current
        return generation

    def use_target(
        self, scene: simcore.Scene, engine: Engine, initial_controls: Controls, name: str
    ) -> None:
        """Compute on another target from now on (the uploads' callback): its base scene and
        engine, the controls a reset returns to, its parts' materials and mesh on the page, then
        a new frame. The target's parts and mesh reach the page in one push with ``busy`` (its
        frame is under way): the page never shows them settled beside the old target's frame."""
        self.base_scene = scene
        self.engine = engine
        self.panel.use_target(initial_controls)
        self._applied_faces_key = None  # its facets are drawn anew with the next frame
        self.compare.unpin()  # the pinned cloud was drawn in the old target's frame
        model = engine.model
        geometry = engine.target_geometry()
        with self.state:  # one push, busy included (on_controls_change submits the frame)
            self.state.update(
                {
                    "target_name": name,
                    "credit": model.credit or "",
                    "part_names": list(model.part_names),
                    "part_info": part_info(model),
                    "materials": dict(initial_controls.materials),
                    "target_points": geometry["points"],
                    "target_polys": geometry["polys"],
                    "seen_facets": None,
                    "home_camera": engine.home_camera(),
                    "scene_camera": None,
                }
            )
            self.on_controls_change()
            self.parts.reset()  # (its own flush ends this one: everything above is set)

    def open_scene(self, scene: simcore.Scene, label: str) -> None:
        """Show ``scene`` (a design study's design): it becomes the scene a reset returns to,
        on its own target (loaded if it is another), its values on the controls."""
        same = scene.target == self.base_scene.target
        engine = self.engine if same else Engine(scene)
        initial, messages = controls_from_scene(scene, resolved_materials(engine.model, scene))
        name = self.state.target_name if same else scene.target.mesh
        with self.state:
            self.state.update(
                {
                    **initial.as_state(),
                    "input_message": "; ".join(messages),  # values the controls cannot show
                    "design_message": f"Showing {label} in the views.",
                }
            )
        self.use_target(scene, engine, initial, name)

    def fit_field_of_view(self, *_: Any, **__: Any) -> None:
        """Set the distance at which the target just fills the field of view at any attitude
        (its bounding sphere about the mesh centre subtends the full field of view)."""
        mesh = self.engine.model.mesh
        radius_m = float(np.max(np.linalg.norm(mesh.vertices - mesh.bounds.mean(axis=0), axis=1)))
        distance_m = fov_fill_distance_m(radius_m, self.base_scene.receive.fov_rad)
        with self.state:
            self.state.distance_m = round(distance_m, 1)  # clamped to the slider's range

    def open_link(self, settings: Any = None, *_: Any, **__: Any) -> None:
        """The page was opened with a shared link: its settings replace the controls (from the
        initial ones; what it leaves out takes its default), the page's display choices stay."""
        controls, messages = controls_from_link(settings, self.panel.initial)
        current = self.panel.current
        controls = dataclasses.replace(
            controls, color_by=current.color_by, image_kind=current.image_kind
        )
        with self.state:
            self.state.update({**controls.as_state(), "input_message": "; ".join(messages)})

    def open_lesson(self, *args: Any, **__: Any) -> None:
        """A lesson's button (its key the first argument): its controls, mode and pixel selection
        in one flush, its card on the page, then its frame (computed once even where nothing but
        the selection changed)."""
        plan = self.lessons.plan(args[0] if args else None, self.panel.initial)
        if plan is None:
            return
        self.selection.array_pixels = plan.controls.pixels  # the selection is on its array
        self.compare.unpin()  # a lesson starts clean: no pinned frame, no highlighted part
        self.parts.reset()
        generation = self.runner.generation
        with self.state:  # the change handlers submit the new scene, if it is one
            self.state.update(
                {
                    **plan.controls.as_state(),
                    **plan.flyaround,
                    "selected_pixels": plan.selection,
                    "input_message": "; ".join(plan.messages),
                    "busy": True,  # with the card: the page waits for the lesson's frame
                    **self.lessons.opened(plan, self.state.target_name),
                }
            )
        if self.runner.generation == generation:  # the same scene: the selection's waveforms
            self.on_controls_change()
        if plan.lesson.attitudes:  # the lesson's scene's map
            self.attitudes.compute_for_lesson()

    # -- downloads (the page's utils.download saves what these return) --------------------------
    def export_cloud(self, fmt: Any = "ply", *_: Any, **__: Any) -> Any:
        """The shown frame's point cloud as PLY or LAS bytes (a binary attachment)."""
        made = self._export(lambda result: exports.cloud_file(result, fmt))
        return None if made is None else self.server.protocol.addAttachment(memoryview(made))

    def export_waveforms(self, *_: Any, **__: Any) -> str | None:
        """The selected pixels' waveforms of the shown frame as CSV text."""
        return self._export(
            lambda result: exports.waveforms_csv(result, self.state.selected_pixels or [])
        )

    def export_scene(self, *_: Any, **__: Any) -> str | None:
        """The shown frame's scene as TOML text (``lmapd simulate`` gives the same points)."""
        return self._export(exports.scene_toml)

    def _export(self, make) -> Any:
        """``make(result)``'s content for the shown frame, or None with a message on the page."""
        if self.last_frame is None:
            self.state.error_message = "Download: no frame yet"
            return None
        try:
            return make(self.last_frame.result)
        except exports.ExportError as exc:
            self.state.error_message = f"Download: {exc}"
            return None

    def pin_frame(self, *_: Any, **__: Any) -> None:
        """Pin the frame shown: its figures and cloud stay beside the frames that follow."""
        if self.last_frame is None:
            self.state.error_message = "Pin: no frame yet"
            return
        self.compare.pin(self.last_frame, self.engine.frame)

    def score_quality(self, *_: Any, **__: Any) -> None:
        """Score the frame shown against the target's true mesh (simcore.quality: 0.1-0.2 s on
        the MRO), in a thread of its own; shown only if that frame is still the one on the page
        (a new frame clears the rows)."""
        frame = self.last_frame
        if frame is None or self.state.quality_busy:
            return
        self.state.quality_busy = True
        if self.server.running:
            self._loop = _running_loop() or self._loop

        def work() -> None:
            try:
                rows = stats.quality_rows(frame.result.quality)
            except Exception as exc:  # shown as a row, never a traceback
                rows = [{"label": "Quality", "value": f"not available ({type(exc).__name__})"}]
            self._on_ui_thread(self._show_quality, frame, rows)

        threading.Thread(target=work, name="lmapd-quality", daemon=True).start()

    def _show_quality(self, frame: Frame, rows: list[dict[str, str]]) -> None:
        with self.state:
            self.state.quality_busy = False
            if frame is self.last_frame:
                self.state.quality_rows = rows

    def reset_controls(self, *_: Any, **__: Any) -> None:
        """Back to the scene the app started with (the paper scene unless --scene was given)."""
        self.panel.reset()

    # -- frames from the worker -------------------------------------------------------------------
    def _compute(self, request: Request) -> Frame:
        """In the worker thread: the engine's frame, abandoned early if overtaken. When the frame
        must recompute its geometry or waveforms, a preview goes to the page first (one ray per
        pixel, no refinement: app.engine.PREVIEW_FIDELITY), so a slider's new value shows in a
        fraction of the frame's time; the frame replaces it when ready."""
        engine, stale = self.engine, self.runner.computing_is_stale
        generation = self.runner.computing_generation
        if request.preview_first and engine.wants_preview(request.scene):
            with self._memory_for(engine, request.scene, generation, preview=True):
                preview = engine.compute_preview(request, stale=stale)
            self._on_ui_thread(self.apply_preview, generation, preview)
        with self._memory_for(engine, request.scene, generation):
            return engine.compute(request, stale=stale)

    def _memory_for(self, engine: Engine, scene: simcore.Scene, generation: int, preview=False):
        """In the worker thread: the launcher's grant for ``scene``'s frame (or its preview), to
        hold while it computes: at once for a light frame, after a wait for a heavy one that does
        not fit beside the other sessions' (the page says how many frames are ahead). Raises
        FrameRefused (over this session's limit, or over the server's budget) and StaleRequest
        (a newer request came while it waited: its place in the queue is given up)."""
        if self.frame_grants is None:
            return contextlib.nullcontext()
        check_memory(scene, engine.frame_budget_bytes)  # this session's own limit first
        runner = self.runner
        return self.frame_grants.ask(
            engine.memory_needed(scene, preview=preview),
            overtaken=lambda: not runner.is_current(generation),
            waiting=lambda ahead: self._on_ui_thread(self._show_memory_wait, generation, ahead),
        )

    def _show_memory_wait(self, generation: int, ahead: int | None) -> None:
        """On the UI thread: the page says that its frame waits for the server's memory."""
        if ahead is None or not self.runner.is_current(generation):
            self.state.memory_message = ""
        else:
            self.state.memory_message = memory_wait_text(ahead)

    def _deliver(self, outcome: Outcome[Frame]) -> None:
        """Called in the worker thread: hand the outcome to the event loop."""
        self._on_ui_thread(self.apply_outcome, outcome)

    def _on_ui_thread(self, call, *args) -> None:
        """From the worker thread: run ``call(*args)`` on the event loop (or at once when there is
        no running loop, as in tests without a server)."""
        loop = self._loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(call, *args)
        else:
            call(*args)

    def apply_preview(self, generation: int, preview: Preview) -> None:
        """On the UI thread: show the preview of request ``generation`` if that request is still
        the newest, its frame has not come yet and the page is not behind (then its frame
        follows soon: a preview would only delay it)."""
        if not self.runner.is_current(generation) or generation <= self._pushed_generation:
            return
        if self.pacer.wait_s() > 0:
            return
        key = f"p{generation}"
        cloud = preview.cloud
        update = {
            "cloud_points": cloud["points"],
            "cloud_outliers": cloud["outliers"],
            "cloud_colorbar": cloud["colorbar"],
            "n_target_points": cloud["n_target"],
            "n_outliers": cloud["n_outliers"],
            "n_points": preview.n_points,
            "frame_kind": "preview",
            "frame_label": PREVIEW_LABEL,
            "frame_key": key,
            "frame_generation": generation,
        }
        if preview.image is not None:
            update["array_image"] = preview.image
        self.pacer.sent(key)
        self.n_previews_pushed += 1
        with self.state:
            self.state.update(update)

    def apply_outcome(self, outcome: Outcome[Frame]) -> None:
        """On the UI thread: drop stale outcomes, show errors, push or hold frames."""
        if not self._still_wanted(outcome):
            return  # a newer request is under way: its frame will come
        if not outcome.ok:
            self._show_error(outcome.error)
            return
        wait_s = self.pacer.wait_s()
        if wait_s > 0:
            self.pacer.hold(outcome)  # replaces any older waiting frame
            if self._loop is not None:
                self._loop.call_later(wait_s + 0.01, self._release_held)
            return
        self._push(outcome)

    def _show_error(self, error: BaseException | None) -> None:
        """A frame that failed or was refused: its message, and the controls back to the values
        of the frame shown (a refused combination must not stay on the sliders)."""
        with self.state:
            if isinstance(error, FrameRefused):
                text = f"Refused: {error}" + self._restore_shown()
            elif isinstance(error, ValueError):  # SceneError, TargetError: meant for users
                text = f"Simulation failed: {on_screen(str(error))}" + self._restore_shown()
            else:
                text = f"Simulation failed ({type(error).__name__}): {error}"
                text += " (showing the last good result)"
            self.state.error_message = text
            self.state.busy = self.pacer.held is not None

    def _restore_shown(self) -> str:
        """Put the scene's controls back to those of the frame shown (the display choices stay
        as they are); what the message adds about it."""
        shown = dataclasses.replace(
            self._shown_controls,
            color_by=self.panel.current.color_by,
            image_kind=self.panel.current.image_kind,
        )
        changed = {k: v for k, v in shown.as_state().items() if self.state[k] != v}
        self.panel.current = shown
        if not changed:
            return " (showing the last good result)"
        self._keep_message = True  # the frame shown comes again: the refusal stays on the page
        self.state.update(changed)  # their change handler resubmits the frame shown (cached)
        return "; the controls are back to the values of the frame shown"

    def on_frame_shown(self, key: str = "", *_: Any, **__: Any) -> None:
        """The page drew frame ``key`` (so every frame sent before it is done too): a waiting
        frame may go."""
        self.flyaround.on_frame_shown(key)  # playing: the next step may go
        if self.pacer.drawn(key):
            self._release_held()

    def _release_held(self) -> None:
        held = self.pacer.release()
        if held is not None and self._still_wanted(held):
            self._push(held)

    def _still_wanted(self, outcome: Outcome[Frame]) -> bool:
        """The newest request's outcome, or an interim frame (a long drag keeps updating) newer
        than what the page shows."""
        if self.runner.is_current(outcome.generation):
            return True
        return outcome.interim and outcome.generation > self._pushed_generation

    def _push(self, outcome: Outcome[Frame]) -> None:
        """Write one frame to the state: a single flush, so the page updates all views at once."""
        frame = outcome.value
        assert frame is not None
        key = f"g{outcome.generation}"
        total_s = time.perf_counter() - outcome.submitted_at_s
        cloud = frame.cloud
        selection, waveforms = self.selection.for_frame(frame)
        update = {
            "frustum": frame.frustum,
            "cloud_points": cloud["points"],
            "cloud_outliers": cloud["outliers"],
            "cloud_colorbar": cloud["colorbar"],
            "n_target_points": cloud["n_target"],
            "n_outliers": cloud["n_outliers"],
            "n_points": int(frame.summary["n_points"]),
            "legend": frame.legend,
            "array_image": frame.image,
            "selected_pixels": selection,
            "waveforms": waveforms,
            "view_text": waveforms_payload.view_text(frame.result.scene.receiver.kind),
            "snr_hist": frame.snr_histogram,
            "stats": stats.frame_rows(frame.stats, frame.result),
            "quality_rows": [],  # the frame shown has not been scored yet
            "stages": stats.stage_rows(
                frame.timings_s,
                {"views (app)": frame.views_s, "request to page": total_s},
            ),
            "footprint_text": scene3d.footprint_text(frame.result.scene),
            **scene3d.sun_and_earth(frame.result.scene, self.engine.model, self.engine.frame),
            "error_message": "",
            "frame_key": key,
            "frame_generation": outcome.generation,
            "frame_kind": "preset",
            "frame_label": frame_label(frame),
            **self.compare.for_frame(frame),
        }
        # the scene view frames the field of view as well as the target: anew when its scale moves
        camera = scene3d.scene_camera(frame.result.scene, self.engine.frame.radius_m)
        reframe = camera != self.state.scene_camera
        if reframe:
            update["scene_camera"] = camera
        if frame.faces_key != self._applied_faces_key:
            update["seen_facets"] = frame.seen_facets
            self._applied_faces_key = frame.faces_key
        if self._keep_message:
            del update["error_message"]
            self._keep_message = False
        self.last_frame = frame
        self._pushed_generation = outcome.generation
        self._shown_controls = self._controls_of.get(outcome.generation, self._shown_controls)
        self._controls_of = {g: c for g, c in self._controls_of.items() if g > outcome.generation}
        self.selection.shown(frame, selection)
        self.pacer.sent(key)  # anything still waiting is older than this frame
        self.n_frames_pushed += 1
        with self.state:
            self.state.update(update)
            # busy while a newer request than this frame's is under way (or a frame is held)
            self.state.busy = not self.runner.is_current(outcome.generation)
            self.flyaround.frame_pushed(frame.result, self.engine.frame)  # its pose track
        if reframe:
            # the camera itself: this call may reach the page before the state does
            self.server.js_call("scene_view", "setCamera", camera)

    # -- pixel selection --------------------------------------------------------------------------
    def on_pixel_click(
        self, row: Any = None, col: Any = None, add: Any = False, *_: Any, **__: Any
    ) -> None:
        """Click on the array image: select pixel (row, col); with shift, add/remove it."""
        self.selection.click(self.last_frame, row, col, add)


PREVIEW_LABEL = "preview: 1 ray per pixel"


def memory_wait_text(ahead: int) -> str:
    """What the page says while its frame waits for the server's memory."""
    if ahead <= 0:
        return "Waiting for memory: this frame is next (other tabs' frames are using it)"
    return f"Waiting for memory: {ahead} frame{'s' if ahead != 1 else ''} ahead"


def scene_key_labels() -> dict[str, str]:
    """The core's names of the settings the page's controls set, with the controls' labels."""
    labels = {name: SPECS[key].label for key, (name, _) in link_names().items() if key in SPECS}
    return labels | {"detector.pixels": "Pixels", "laser.pulse_energy_j": "Pulse energy"}


def on_screen(message: str) -> str:
    """A core message with the names of the settings the page's controls set given as those
    controls' labels (gm.pulses -> 'Pulses per frame')."""
    labels = scene_key_labels()
    for name in sorted(labels, key=len, reverse=True):
        if "." in name:
            message = message.replace(name, f"'{labels[name]}'")
    return message


def frame_label(frame: Frame) -> str:
    """What the page says of a frame it shows: the fidelity preset that made it."""
    preset = preset_of(frame.result.scene)
    return "custom fidelity" if preset == "custom" else f"{preset} preset"


def part_info(model: simcore.TargetModel) -> dict[str, str]:
    """What the materials panel says of each part: its share of the area, its triangles, and
    whether the lidar sees through it (glTF opacity)."""
    info = {}
    for row in parts_table(model):
        text = f"{100 * row['area_share']:.1f} % of the area, {row['triangles']:,} triangles"
        info[row["name"]] = text + (", transparent" if row["transparent"] else "")
    return info
