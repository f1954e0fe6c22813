"""The imaging chain, staged and cached: ``Pipeline().run(scene)``.

Each stage is declared next to its physics (a :class:`simcore.stage.Stage`: name, upstream
stages, the scene values it reads, its function). A stage's cache key is its reads plus its
upstream stages' keys, so a TNR change re-runs only detection and the cloud, a pulse-energy change
only the receiver onwards (echoes are per joule), and a pose change everything but the target and
the rays, and a Sun change only the background onwards (never the ray cast). Cached arrays
are read-only. One Pipeline per thread: it is not shared between threads.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from . import parallel
from .background import BACKGROUND
from .echo import ECHO
from .echo.features import preload
from .geometry import HITS, RAYS, TARGET
from .pointcloud import CLOUD
from .pulse import scene_pulse_shape
from .quality import QUALITY
from .receivers.stages import DETECTION, RECEIVER
from .result import Result, Waveform
from .scene import Scene, SceneError, with_overrides
from .stage import _SHOULD_STOP, Cancelled, Stage, stop_check

__all__ = [
    "CHAIN",
    "STAGES",
    "Cancelled",
    "Pipeline",
    "Result",
    "Waveform",
    "simulate",
    "stop_check",
]

# the imaging chain, in order: each stage takes the scene and its upstream stages' outputs
CHAIN: tuple[Stage, ...] = (
    TARGET,  # the mesh, its parts and materials, the BVH         (geometry)
    RAYS,  # the array's sub-ray directions                        (geometry)
    HITS,  # first hits of every sub-ray, mixed pixels refined     (geometry)
    ECHO,  # per-pixel elements and echo features, per joule        (echo)
    BACKGROUND,  # sunlight from the target and the Earth, per pixel (background)
    RECEIVER,  # the scene's receiver: peak power, SNR, noise       (receivers)
    DETECTION,  # detections, ranges, range sigma, false alarms     (receivers)
    CLOUD,  # points and per-point attributes                      (pointcloud)
)
STAGES = tuple(stage.name for stage in CHAIN)
# stages computed only when asked for (``Pipeline.run(scene, extras=...)``, or on first use
# through the Result): the imaging-quality metrics against the true mesh     (quality)
OPTIONAL: dict[str, Stage] = {QUALITY.name: QUALITY}


class Pipeline:
    """Runs scenes through the chain, re-running only the stages whose inputs changed."""

    def __init__(self):
        self._cache: dict[str, tuple[tuple, Any]] = {}

    def clear(self) -> None:
        self._cache.clear()

    def adopt(
        self, other: Pipeline, stages: tuple[str, ...] = ("target",), scene: Scene | None = None
    ) -> None:
        """Take ``other``'s cached outputs of ``stages`` (read-only, so they can be shared by
        pipelines of one thread: a target's mesh and BVH loaded once for several of them); a
        stage whose key differs is computed again as usual. Without ``scene`` only the stages
        this pipeline has not cached are taken; with it, every one of ``other``'s that is
        ``scene``'s (its inputs unchanged) and not already this pipeline's."""
        keys = self._keys(scene, upto=stages) if scene is not None else {}
        for name in stages:
            theirs = other._cache.get(name)
            if theirs is None:
                continue
            ours = self._cache.get(name)
            if scene is None:
                if ours is None:
                    self._cache[name] = theirs
            elif theirs[0] == keys.get(name) and (ours is None or ours[0] != theirs[0]):
                self._cache[name] = theirs

    @staticmethod
    def _keys(scene: Scene, upto: tuple[str, ...] | None = None) -> dict[str, tuple]:
        """The cache key of each stage of the chain for ``scene`` (its reads and its upstream
        stages' keys), in order; with ``upto``, only as far as the last of those stages (a
        :meth:`run` computes the same keys as it goes)."""
        keys: dict[str, tuple] = {}
        wanted = set(upto) if upto is not None else None
        for stage in CHAIN:
            keys[stage.name] = (stage.reads(scene), *(keys[u] for u in stage.upstream))
            if wanted is not None:
                wanted.discard(stage.name)
                if not wanted:
                    break
        return keys

    def run(
        self,
        scene: Scene,
        should_stop: Callable[[], bool] | None = None,
        extras: tuple[str, ...] = (),
    ) -> Result:
        """Run ``scene``; ``should_stop`` is asked before each stage that must compute, and a
        True answer raises :class:`Cancelled` (the cache keeps every stage finished so far).
        ``extras``: optional stages to run as well (names of OPTIONAL, e.g. "quality")."""
        unknown = [name for name in extras if name not in OPTIONAL]
        if unknown:
            raise ValueError(f"unknown optional stage {unknown[0]!r}: choose from {list(OPTIONAL)}")
        outputs: dict[str, Any] = {}
        keys: dict[str, tuple] = {}
        timings: dict[str, float] = {}
        if "echo" not in self._cache:  # the first frame: the echo kernel loads meanwhile
            preload(scene_pulse_shape(scene))
        chain = (*CHAIN, *(OPTIONAL[name] for name in extras))
        token = _SHOULD_STOP.set(should_stop)
        try:
            with parallel.blas_serial():
                for stage in chain:
                    keys[stage.name] = (stage.reads(scene), *(keys[u] for u in stage.upstream))
                    outputs[stage.name], timings[stage.name] = self._output(
                        stage, scene, keys[stage.name], outputs, should_stop
                    )
        finally:
            _SHOULD_STOP.reset(token)
        return Result(
            scene=scene,
            cloud=outputs["cloud"],
            echo=outputs["echo"],
            background=outputs["background"],
            receiver=outputs["receiver"],
            detection=outputs["detection"],
            hits=outputs["hits"],
            rays=outputs["rays"],
            timings_s=timings,
            caster=outputs["target"].caster,
            extras={name: outputs[name] for name in extras},
        )

    def stages_to_run(self, scene: Scene) -> list[str]:
        """The stages a :meth:`run` of ``scene`` would compute (the others come from the cache),
        in chain order; nothing is computed here."""
        names = []
        for name, key in self._keys(scene).items():
            cached = self._cache.get(name)
            if cached is None or cached[0] != key:
                names.append(name)
        return names

    def cached(self, name: str, scene: Scene) -> Any:
        """Stage ``name``'s cached output if it is ``scene``'s (its inputs unchanged), else None;
        nothing is computed (a caller may look at a finished stage before the next runs)."""
        key = self._keys(scene, upto=(name,)).get(name)
        hit = self._cache.get(name)
        return hit[1] if key is not None and hit is not None and hit[0] == key else None

    def _output(self, stage: Stage, scene: Scene, key: tuple, outputs: dict, should_stop):
        """The stage's output (cached under ``key``, or computed) and its compute time [s]."""
        cached = self._cache.get(stage.name)
        if cached is not None and cached[0] == key:
            return cached[1], 0.0
        if should_stop is not None and should_stop():
            raise Cancelled(f"stopped before the {stage.name} stage")
        t0 = time.perf_counter()
        value = stage.compute(scene, *(outputs[u] for u in stage.upstream))
        elapsed_s = time.perf_counter() - t0
        self._cache[stage.name] = (key, value)
        return value, elapsed_s


def simulate(scene: Scene | None = None, pipeline: Pipeline | None = None, **quick) -> Result:
    """Simulate one flash. ``quick`` takes the flat names (pitch_deg, azimuth_deg, distance_m,
    pixels, pulse_energy_j, tnr, seed) or dotted keys via ``overrides={...}``.

    >>> r = simulate(pixels=32)               # the paper scene, 32 x 32 pixels
    >>> r.summary()["n_pixels"]
    1024
    """
    overrides = quick.pop("overrides", None)
    scene = with_overrides(scene or Scene(), overrides, **quick)
    if not isinstance(scene, Scene):
        raise SceneError("simulate() expects a Scene")
    return (pipeline or Pipeline()).run(scene)
