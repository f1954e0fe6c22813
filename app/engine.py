"""The engine: simcore's Pipeline plus the view payloads of each result, run in the worker thread.

One Engine per app; ``compute`` is only ever called from the runner's single worker thread (the
Pipeline is not thread-safe). The target is loaded once up front for the page (its parts name the
material drop-downs and its mesh is sent to the 3D view once).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

import simcore
from app.payloads import cloud, image, scene3d, stats, waveforms
from app.runner import StaleRequest
from app.state import MAX_SELECTED_PIXELS
from simcore import receivers

# The server's budget for what one frame's receiver records (a receiver whose declaration
# estimates it, ``frame_load``). A Geiger-mode frame costs about 1.2 us of the two cores and
# 101 bytes per recorded avalanche (receiver and detection stages; 11.5 M avalanches took 14 s):
# 8 M avalanches is about 10 s and 0.8 GB, the most one student's frame may take. One pixel's
# avalanches in one gate are bounded by the core's own limit.
MAX_FRAME_RECORD_BYTES = 8_000_000 * 101

# The memory one frame takes above what the engine holds, at most, per sub-ray of the base grid
# and per pixel (the refinement of mixed pixels, the per-pixel arrays), bounding the peaks
# measured on the paper scene with the target filling the frame (2026-11-26; the arrays' traced
# peak, tests/support/frame_memory.py; the resident peak is 0.6-1.2 times it): reference preset
# (64 sub-rays) 64 px 51 MB, 128 px 204 MB (184 MB at 60 m), 256 px about 785 MB resident;
# interactive 256 px 36 MB, 512 px about 139 MB resident. The estimate is 1.7-1.9 times the
# traced peaks (tests/app/test_app_memory.py checks two frames against their measured peak).
FRAME_BYTES_PER_SUBRAY = 330
FRAME_BYTES_PER_PIXEL = 600
MIB = 2**20
FRAME_BUDGET_BYTES = 1536 * MIB  # one frame of one session, by default


def frame_bytes(scene: simcore.Scene) -> int:
    """The most memory ``scene``'s frame takes above the engine's own [bytes] (an estimate made
    before any stage runs; see FRAME_BYTES_PER_SUBRAY)."""
    n_pixels = scene.detector.pixels**2
    return n_pixels * (FRAME_BYTES_PER_SUBRAY * scene.fidelity.subrays + FRAME_BYTES_PER_PIXEL)


def release_free_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``; elsewhere
    nothing): a heavy frame's temporaries otherwise stay in the process (256 px at the reference
    preset, the next small frame: 349 MB resident, 279 MB after the trim; 2026-11-26)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim():
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def check_memory(scene: simcore.Scene, budget_bytes: int) -> None:
    """Raise FrameRefused if ``scene``'s frame would take more than ``budget_bytes``."""
    need = frame_bytes(scene)
    if need > budget_bytes:
        raise FrameRefused(
            f"this frame would take about {need / 1e9:.2g} GB of memory (at most "
            f"{budget_bytes / 1e9:.2g} GB per frame here): lower the Pixels, or choose a "
            "fidelity preset with fewer sub-rays per pixel"
        )


class FrameRefused(ValueError):
    """A frame over the server's budget, refused before its costly stages run; the message
    names the page's controls that bring it back within the budget."""


def check_budget(pipeline: simcore.Pipeline, scene: simcore.Scene) -> None:
    """Raise FrameRefused if ``scene``'s frame would exceed the server's budget. Called before
    each stage ``pipeline`` computes: once the echo and background stages of ``scene`` are
    done (and the receiver is not), what the receiver will record is estimated as the core does
    before drawing it (the declaration's ``frame_load``: for the Geiger-mode array its
    avalanches, and whether the core's own bounds hold, so that no frame reaches its refusal)."""
    frame_load = receivers.get(scene.receiver.kind).frame_load
    if frame_load is None or pipeline.cached("receiver", scene) is not None:
        return
    echo = pipeline.cached("echo", scene)
    background = pipeline.cached("background", scene)
    if echo is None or background is None:
        return
    load = receivers.resolve(frame_load)(scene, echo, background)
    most = MAX_FRAME_RECORD_BYTES / load.bytes_each
    if load.count > most or not load.within_core_limits:
        raise FrameRefused(
            f"this frame would record about {about(load.count)} {load.units} "
            f"({load.count * load.bytes_each / 1e9:.2g} GB; at most {about(most)} per "
            f"frame here): {load.advice}"
        )


def about(count: float) -> str:
    """A count as a refusal gives it: two significant digits, written out with thousands
    separators (``8,000,000``, ``12,000,000``, ``0.5``), the same way for the figure refused and
    for the limit (they read "about 8e+06 ... at most 8,000,000" before)."""
    rounded = float(f"{count:.2g}")
    return f"{rounded:,.0f}" if abs(rounded) >= 10 else f"{rounded:g}"


@dataclass(frozen=True)
class Request:
    """What one frame needs: the scene and how to show it."""

    scene: simcore.Scene
    color_by: str = "range"
    image_kind: str = "range"
    selection: tuple[tuple[int, int], ...] = ()
    selection_pixels: int = 0  # array size the selection refers to (0: none yet)
    # the selection's directions as focal-plane tangents (x/f, y/f); () : its pixels' centres
    selection_tangents: tuple[tuple[float, float], ...] = ()
    preview_first: bool = False  # show a preview while the frame computes, if one is quicker


@dataclass(frozen=True)
class Frame:
    """One simulated flash and everything the views draw from it (built in the worker)."""

    result: simcore.Result
    summary: dict
    cloud: dict
    frustum: dict
    faces_key: tuple
    seen_facets: dict
    legend: list[dict]
    image: dict
    selection: list[list[int]]
    waveforms: dict
    snr_histogram: dict
    stats: list[dict]
    simulate_s: float
    views_s: float
    timings_s: dict[str, float] = field(default_factory=dict)
    request: Request | None = None


# The preview of a frame (app.logic.controller shows it first while the chosen preset's frame is
# computed): one ray per pixel through its centre, no refinement of mixed pixels, no corner
# probes or cell spread, the statistical noise model (Eqs. 27-28 drawn); the rest of the scene as
# it is (seed included).
PREVIEW_FIDELITY = {
    "fidelity.subrays": 1,
    "fidelity.refine_subrays": 0,
    "fidelity.probe_corners": False,
    "fidelity.cell_spread": False,
    "fidelity.noise_model": "statistical",
}
# The stages whose recomputation makes a preview worth it: the geometry (ray casting and
# refinement) and the waveforms. A change that only re-runs the receiver or the detection (TNR,
# pulse energy, the threshold) is quicker than a preview would be, and is shown at once.
PREVIEW_STAGES = ("hits", "echo")


@dataclass(frozen=True)
class Preview:
    """The quick first look at a request: the point cloud and the array image only."""

    cloud: dict
    image: dict | None  # None: the image waits for the frame
    n_points: int


class Engine:
    """Owns the Pipeline (worker thread only) and the target's static display data."""

    def __init__(
        self,
        scene: simcore.Scene,
        model: simcore.TargetModel | None = None,
        frame_budget_bytes: int = FRAME_BUDGET_BYTES,
        shared: simcore.Pipeline | None = None,
    ):
        """``model``: the scene's target if already loaded (else it is loaded here);
        ``frame_budget_bytes``: a frame estimated to take more memory is refused before it runs
        (frame_bytes); ``shared``: a pipeline whose target stage (the mesh and its ray-casting
        structure) this engine's pipelines take instead of building their own, and whose other
        stages its frames' pipeline takes (the sessions' preloaded parent, app.server.zygote,
        shares one with every session it forks, holding the scene's first frame: a new
        session's first frame then only builds its views)."""
        self.frame_budget_bytes = frame_budget_bytes
        self.model = model if model is not None else simcore.load_target(scene.target)
        self.frame = scene3d.display_frame(self.model)
        self.pipeline = simcore.Pipeline()
        # the previews' own cache: they never evict the frames' stages, and keep their own
        # target stage (the mesh and its ray-casting structure: clearing it cost each preview
        # 90 ms at 128 x 128, ten times the preview itself)
        self.preview_pipeline = simcore.Pipeline()
        # ... but one target stage between the two, built by whichever runs first: the MRO's is
        # 10-20 MB of ray-casting structure and 9 MB of mesh arrays (read-only once built)
        if shared is not None:
            self.pipeline.adopt(shared, stages=simcore.STAGES)
            self.preview_pipeline.adopt(shared)
        self.vertices_d = self.frame.from_target(self.model.mesh.vertices)  # display frame
        # key (the seen set's content), seen-facets mesh, legend
        self._facets: tuple | None = None

    def target_geometry(self) -> dict:
        return scene3d.target_geometry(self.model, self.frame)

    def home_camera(self) -> dict:
        return scene3d.home_camera(self.frame.radius_m)

    def compute(self, request: Request, stale: Callable[[], bool] = lambda: False) -> Frame:
        """Simulate ``request.scene`` and build every view's payload (runs in the worker).

        Raises StaleRequest if ``stale()`` says a newer request has arrived meanwhile: the
        pipeline checks it between stages (simcore.Cancelled), and again before the views.
        """
        t0 = time.perf_counter()
        check_memory(request.scene, self.frame_budget_bytes)

        def should_stop() -> bool:
            check_budget(self.pipeline, request.scene)
            return stale()

        self.pipeline.adopt(self.preview_pipeline, scene=request.scene)  # its target, if built
        try:
            result = self.pipeline.run(request.scene, should_stop=should_stop)
        except simcore.Cancelled:
            raise StaleRequest from None  # dropped by the runner, not an error
        if stale():
            raise StaleRequest
        t1 = time.perf_counter()
        faces_key, seen_facets, legend = self._facets_payload(result)
        selection = self.selection_for(result, request)
        summary = result.summary(quality=False)  # the mesh distances: not on every frame
        frame = Frame(
            result=result,
            summary=summary,
            cloud=cloud.cloud_view(result, self.frame, request.color_by),
            frustum=scene3d.frustum_mesh(result, self.frame),
            faces_key=faces_key,
            seen_facets=seen_facets,
            legend=legend,
            image=image.array_image(result, request.image_kind),
            selection=selection,
            waveforms=waveforms.waveform_figure(result, selection),
            snr_histogram=stats.snr_histogram(result),
            stats=stats.stats_rows({**summary, "noise_figures": result.receiver.noise_figures}),
            simulate_s=t1 - t0,
            views_s=time.perf_counter() - t1,
            timings_s=dict(result.timings_s),
            request=request,
        )
        release_free_memory()
        return frame

    def memory_needed(self, scene: simcore.Scene, preview: bool = False) -> int:
        """The memory ``scene``'s frame (or its preview) would take above the engine's [bytes]:
        its estimate (frame_bytes), or 0 when every stage of it is cached."""
        pipeline = self.preview_pipeline if preview else self.pipeline
        if preview:
            scene = self.preview_scene(scene)
        return frame_bytes(scene) if pipeline.stages_to_run(scene) else 0

    @staticmethod
    def preview_scene(scene: simcore.Scene) -> simcore.Scene:
        """``scene`` at the preview's fidelity (see PREVIEW_FIDELITY)."""
        return simcore.with_overrides(scene, PREVIEW_FIDELITY)

    def wants_preview(self, scene: simcore.Scene) -> bool:
        """Whether a preview would come sooner than ``scene``'s own frame: the scene asks for
        more than the preview does and its frame must recompute the geometry or the waveforms."""
        if self.preview_scene(scene).fidelity == scene.fidelity:
            return False  # the frame is a preview already
        return any(name in PREVIEW_STAGES for name in self.pipeline.stages_to_run(scene))

    def compute_preview(
        self, request: Request, stale: Callable[[], bool] = lambda: False
    ) -> Preview:
        """The preview of ``request`` (runs in the worker): its cloud and array image.

        Raises StaleRequest like :meth:`compute`.
        """
        check_memory(request.scene, self.frame_budget_bytes)  # no preview of a refused frame
        scene = self.preview_scene(request.scene)

        def should_stop() -> bool:
            check_budget(self.preview_pipeline, scene)
            return stale()

        self.preview_pipeline.adopt(self.pipeline, scene=scene)
        try:
            result = self.preview_pipeline.run(scene, should_stop=should_stop)
        except simcore.Cancelled:
            raise StaleRequest from None
        if stale():
            raise StaleRequest
        return Preview(
            cloud=cloud.cloud_view(result, self.frame, request.color_by),
            # the multi-peak marks need every pixel's waveform: they wait for the frame
            image=None
            if request.image_kind == "multi_peak"
            else image.array_image(result, request.image_kind),
            n_points=len(result.cloud),
        )

    def _facets_payload(self, result: simcore.Result) -> tuple[tuple, dict, list[dict]]:
        """The seen facets' mesh and the material legend, rebuilt only when the set of facets
        seen or the materials changed. The key is the set's content (a digest of the facet
        numbers), not the hits: a new pose that sees the same facets keeps the key, and the app
        sends nothing new to the 3D scene's facet colours."""
        visible = np.ascontiguousarray(result.visible_faces, dtype=np.int64)
        digest = hashlib.blake2b(visible.tobytes(), digest_size=16).hexdigest()
        key = (len(visible), digest, result.target.part_materials)
        if self._facets is not None and self._facets[0] == key:
            return key, self._facets[1], self._facets[2]
        mesh = scene3d.seen_facets_mesh(result.target, self.vertices_d, visible)
        legend = scene3d.material_legend(result.target, visible)
        self._facets = (key, mesh, legend)
        return key, mesh, legend

    @staticmethod
    def selection_for(result: simcore.Result, request: Request) -> list[list[int]]:
        """The request's selected pixels on this result's array (the pixels that see their
        directions, if the array changed), or the default pixel when nothing is selected yet."""
        n = result.pixels
        if request.selection_tangents:
            return waveforms.pixels_of_tangents(
                request.selection_tangents, n, result.scene.receive.fov_rad
            )
        if request.selection and request.selection_pixels:
            chosen = waveforms.rescale_selection(
                list(request.selection), request.selection_pixels, n
            )
            return [p for p in chosen if 0 <= p[0] < n and 0 <= p[1] < n]
        pixel = waveforms.default_pixel(result)
        return [pixel] if pixel is not None else []


def selection_tuple(pixels) -> tuple[tuple[int, int], ...]:
    """A hashable copy of a [[row, col], ...] selection; () for anything else (the state may
    hold whatever a client sent: more than MAX_SELECTED_PIXELS pairs is refused as well)."""
    if not isinstance(pixels, list | tuple) or len(pixels) > MAX_SELECTED_PIXELS:
        return ()
    try:
        pairs = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    except (TypeError, ValueError, OverflowError, RecursionError):
        return ()
    return tuple((int(r), int(c)) for r, c in pairs)
