"""Users' own target meshes, uploaded from the page.

Only the upload's bytes are used: the client's file name is ignored except for its extension
(from an allow-list), and no path given by the client is ever opened. The bytes are parsed in
memory by trimesh with no file resolver (an OBJ's ``mtllib``, a glTF's external ``uri`` or a PLY's
texture file are never looked up on the server), checked against the caps below, and re-encoded as
one self-contained binary glTF in a private temporary directory (mode 0700, named by the process:
``app.logic.upload_folders``), removed at exit, or by the launcher when the session dies. The core
then loads that file like any scene's mesh
(``simcore.with_overrides(scene, {"target.mesh": path, "target.scale_m_per_unit": s})``), which
refuses meshes with no triangles, NaN vertices, zero area or an implausible size.

Parsing and loading run off the event loop; the page shows a message for every refusal.
"""

from __future__ import annotations

import asyncio
import atexit
import base64
import dataclasses
import io
import logging
import math
import os
import shutil
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

import simcore
from app.engine import Engine
from app.logic import upload_folders
from app.logic.scene_map import resolved_materials
from app.state import Controls, echo
from simcore.target import (
    TARGETS_DIR,
    TargetError,
    builtin_settings,
    builtin_targets,
    load_mesh_file,
)

log = logging.getLogger(__name__)

ALLOWED_SUFFIXES = (".glb", ".gltf", ".obj", ".stl", ".ply")
MAX_UPLOAD_BYTES = 32 * 2**20  # 32 MiB per file
MAX_UPLOAD_FACES = 1_000_000  # triangles per uploaded target
MAX_UPLOAD_VERTICES = 3 * MAX_UPLOAD_FACES  # vertices per uploaded target (unshared corners)
# scalar values a glTF upload's accessors may declare together: a million triangles with their
# positions, normals and texture coordinates (3 + 9 + 9 + 6 M) and margin
MAX_UPLOAD_VALUES = 40_000_000
SCALE_RANGE = (1e-6, 1e4)  # metres per mesh unit
DEFAULT_SCALE = 1.0


class UploadError(ValueError):
    """An upload that cannot be used; the message is shown on the page as it is."""


def upload_suffix(name: Any) -> str:
    """The lower-case extension of the client's file name, if it is an allowed mesh format (the
    rest of the name is never used)."""
    suffix = os.path.splitext(str(name)[-260:])[1].lower() if isinstance(name, str) else ""
    if suffix not in ALLOWED_SUFFIXES:
        allowed = ", ".join(ALLOWED_SUFFIXES)
        raise UploadError(f"{echo(name)} is not a mesh file: use one of {allowed}")
    return suffix


def upload_content(value: Any) -> tuple[bytes, str]:
    """The bytes and the extension of an upload as trame's client sends it (a dict with ``name``,
    ``size`` and ``content``, or a list holding one). Raises UploadError."""
    if isinstance(value, list | tuple):
        if len(value) != 1:
            raise UploadError("upload one mesh file at a time")
        value = value[0]
    if not isinstance(value, dict):
        raise UploadError(f"not a file upload ({echo(value)})")
    suffix = upload_suffix(value.get("name"))
    size = value.get("size")
    if isinstance(size, int | float) and size > MAX_UPLOAD_BYTES:
        raise UploadError(_too_big(size))
    content = value.get("content")
    if isinstance(content, memoryview | bytearray):
        content = bytes(content)
    if isinstance(content, str):
        raise UploadError("the file's content came as text, not as the file's bytes")
    if not isinstance(content, bytes):
        error = value.get("error")
        why = f": {echo(error)}" if error else ""
        raise UploadError(f"the browser could not read the file{why}")
    if len(content) > MAX_UPLOAD_BYTES:
        raise UploadError(_too_big(len(content)))
    if not content:
        raise UploadError("the file is empty")
    return content, suffix


def upload_name(value: Any) -> str:
    """The client's file name, quoted short, for messages only (never used as a path)."""
    if isinstance(value, list | tuple) and len(value) == 1:
        value = value[0]
    name = value.get("name") if isinstance(value, dict) else None
    if not isinstance(name, str) or not name:
        return "the file"
    return echo(name.replace("\\", "/").rsplit("/", 1)[-1])  # a Windows path too


def _too_big(size: float) -> str:
    limit = MAX_UPLOAD_BYTES >> 20
    return f"the file is {size / 2**20:.1f} MiB; uploads are limited to {limit} MiB"


def self_contained_glb(data: bytes, suffix: str) -> tuple[bytes, int]:
    """Parse a mesh file from its bytes alone and re-encode it as one binary glTF (parts kept as
    its geometries); also return its triangle count. Raises UploadError for files that cannot
    be read, hold no triangles, too many, or non-finite vertices."""
    try:  # declared counts over the limits, and NaN or infinite vertices, refused (the core's)
        loaded = load_mesh_file(
            io.BytesIO(data),
            file_type=suffix[1:],
            max_faces=MAX_UPLOAD_FACES,
            max_vertices=MAX_UPLOAD_VERTICES,
            max_values=MAX_UPLOAD_VALUES,
            resolver=None,
        )
    except TargetError as exc:
        raise UploadError(str(exc)) from None
    except Exception as exc:  # trimesh raises many types for malformed files
        text = f"cannot read the {suffix} file ({type(exc).__name__}: {exc})"
        raise UploadError(text[:300]) from None
    scene = loaded if isinstance(loaded, trimesh.Scene) else trimesh.Scene(loaded)
    meshes = [g for g in scene.geometry.values() if isinstance(g, trimesh.Trimesh)]
    n_faces = sum(len(g.faces) for g in meshes)
    if n_faces == 0:
        raise UploadError("the mesh has no triangles")
    if n_faces > MAX_UPLOAD_FACES:
        raise UploadError(f"the mesh has {n_faces:,} triangles; the limit is {MAX_UPLOAD_FACES:,}")
    if not all(np.isfinite(g.vertices).all() for g in meshes):
        raise UploadError("the mesh has NaN or infinite vertex coordinates")
    try:
        return bytes(scene.export(file_type="glb")), n_faces
    except Exception as exc:
        raise UploadError(f"cannot convert the mesh ({type(exc).__name__}: {exc})"[:300]) from None


def scale_value(value: Any) -> float:
    """A valid scale in metres per mesh unit, or UploadError."""
    try:
        scale = float(value)
    except (TypeError, ValueError, OverflowError):
        raise UploadError(f"scale {echo(value)} is not a number") from None
    lo, hi = SCALE_RANGE
    if not (math.isfinite(scale) and lo <= scale <= hi):
        raise UploadError(f"scale {echo(value)} is outside {lo:g} to {hi:g} m per unit")
    return scale


class PrivateDir:
    """A private temporary directory (0700), created on first use and removed at exit."""

    def __init__(self) -> None:
        self._path: Path | None = None
        self._lock = threading.Lock()
        self._count = 0

    @property
    def path(self) -> Path:
        with self._lock:
            if self._path is None:  # named by this process: the launcher removes a dead one's
                self._path = upload_folders.new_folder()
                atexit.register(self.cleanup)
            return self._path

    def write(self, data: bytes, suffix: str) -> Path:
        """A new file in the directory holding ``data`` (a name of our own, never the client's)."""
        folder = self.path
        with self._lock:
            self._count += 1
            path = folder / f"upload-{self._count}{suffix}"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        return path

    def cleanup(self) -> None:
        with self._lock:
            path, self._path = self._path, None
        if path is not None:
            shutil.rmtree(path, ignore_errors=True)


@dataclasses.dataclass(frozen=True)
class LoadedTarget:
    scene: simcore.Scene
    engine: Engine
    path: Path | None
    n_faces: int


def target_scene(base: simcore.Scene, path: Path, scale: float) -> simcore.Scene:
    """``base`` with the uploaded mesh as its target (no material map, no part overrides: the
    parts are new)."""
    return simcore.with_overrides(
        base,
        {
            "target.mesh": str(path),
            "target.scale_m_per_unit": scale,
            "target.material_map": "",
            "target.materials": {},
        },
    )


def load_builtin(base: simcore.Scene, name: str) -> LoadedTarget:
    """Built-in target ``name`` (the catalogue's spacecraft or a calibration shape) at its own
    size and materials, in the app's base scene."""
    scene = simcore.with_overrides(
        base,
        {
            "target.mesh": name,
            "target.scale_m_per_unit": 0.0,
            "target.size_m": 0.0,
            "target.material_map": "",
            "target.materials": {},
        },
    )
    engine = Engine(scene)
    return LoadedTarget(scene, engine, None, len(engine.model.mesh.faces))


UPLOAD_CHOICE = "upload:"  # the drop-down's value of the uploaded mesh shown (its item's prefix)


def upload_item(name: str) -> dict:
    """The drop-down's item of the uploaded mesh shown (``name``: as messages quote it)."""
    title = name.strip("'") if name != "the file" else "your mesh"
    return {"title": f"{title} (uploaded)", "value": UPLOAD_CHOICE + title}


def catalogue_items() -> list[dict]:
    """The drop-down's built-in targets: name, size and a thumbnail where the target has one."""
    items = []
    for name in builtin_targets():
        settings = builtin_settings(name)
        size = settings.get("longest_extent_m")
        title = settings.get("name", name).split(" (")[0]
        item = {"title": f"{title} ({size:g} m)" if size else title, "value": name}
        thumbnail = TARGETS_DIR / name / "thumbnail.png"
        if thumbnail.is_file() and thumbnail.stat().st_size < 256 * 1024:
            data = base64.b64encode(thumbnail.read_bytes()).decode("ascii")
            item["prependAvatar"] = f"data:image/png;base64,{data}"
        items.append(item)
    return items


def load_uploaded(base: simcore.Scene, path: Path, scale: float) -> LoadedTarget:
    """Load our own copy of an upload as the target of ``base`` (in a worker thread).
    Raises UploadError with the core's message for meshes it refuses."""
    try:
        scene = target_scene(base, path, scale)
        model = simcore.load_target(scene.target)
    except ValueError as exc:  # TargetError, SceneError: messages meant for users
        text = str(exc).replace(f"{path}: ", "").replace(str(path), "the mesh")
        raise UploadError(text) from None
    return LoadedTarget(scene, Engine(scene, model=model), path, len(model.mesh.faces))


class TargetUploads:
    """The upload controls' logic, a child of the app's logic: state ``upload_file`` (from the
    file input), ``upload_scale``, trigger ``use_builtin_target``; ``upload_message`` /
    ``upload_error`` / ``upload_busy`` for the page.

    builtin : the target the app started with
    builtin_initial : its controls (an uploaded target starts from them, with its own materials)
    use_target : (scene, engine, initial controls, name) -> None, the parent's switch to another
        target (called on the event loop when a mesh has loaded)
    """

    def __init__(
        self,
        server,
        *,
        builtin: LoadedTarget,
        builtin_initial: Controls,
        use_target: Callable[[simcore.Scene, Engine, Controls, str], None],
    ) -> None:
        self.server = server
        self.state = server.state
        self.builtin = builtin
        self.builtin_initial = builtin_initial
        self.use_target = use_target
        self.current = self.builtin
        self.files = PrivateDir()
        self._ticket = 0
        self._file_name = "the file"  # the current upload's name, for messages
        self._raw: bytes | None = None  # the current upload's glb, to re-load with a new scale
        self.state.update(
            {
                "upload_file": None,
                "upload_scale": DEFAULT_SCALE,
                "upload_message": "",
                "upload_error": "",
                "upload_busy": False,
                "target_is_upload": False,
                "upload_max_mib": MAX_UPLOAD_BYTES >> 20,
                "upload_max_faces": MAX_UPLOAD_FACES,
                "upload_input_key": 0,  # a new value re-creates the file input (empty)
                "target_items": catalogue_items(),
                "target_choice": builtin.scene.target.mesh,
            }
        )
        self.state.change("upload_file")(self.on_upload)
        self.state.change("target_choice")(self.on_target_choice)
        self.state.change("upload_scale")(self.on_scale)
        server.trigger("use_builtin_target")(self.use_builtin)
        server.controller.on_server_exited.add(lambda **_: self.files.cleanup())

    # -- handlers (event loop) --------------------------------------------------------------------
    def on_upload(self, upload_file: Any = None, **_: Any) -> None:
        if upload_file is None or (isinstance(upload_file, list) and not upload_file):
            return  # nothing, or an empty selection (the input was cleared)
        # drop the bytes from the shared state at once, and empty the input: the same file can
        # be picked again (after a refusal, or with another scale)
        self.state.upload_file = None
        self.state.upload_input_key = int(self.state.upload_input_key or 0) + 1
        self._file_name = name = upload_name(upload_file)
        try:
            content, suffix = upload_content(upload_file)
            scale = scale_value(self.state.upload_scale)
        except UploadError as exc:
            self._fail(f"{name}: {exc}")
            return

        def work() -> LoadedTarget:
            glb, _ = self_contained_glb(content, suffix)
            path = self.files.write(glb, ".glb")
            try:
                return load_uploaded(self.builtin.scene, path, scale)
            except BaseException:
                path.unlink(missing_ok=True)  # a refused upload leaves nothing on disk
                raise

        self._start(work)

    def refusals(self) -> dict[str, Callable[[Any], None]]:
        """What the page is told of an upload value refused before it reached the state (a
        list of files, a scale that is a list): state key -> called with the refused value."""

        def refused_file(value: Any) -> None:
            try:
                upload_content(value)
                text = f"not a file upload ({echo(value)})"
            except UploadError as exc:
                text = str(exc)
            self._fail(f"{upload_name(value)}: {text}")

        def refused_scale(value: Any) -> None:
            try:
                scale_value(value)
                text = f"scale {echo(value)} is not a number"
            except UploadError as exc:
                text = str(exc)
            self.state.upload_error = f"{text}; kept the previous scale"

        return {"upload_file": refused_file, "upload_scale": refused_scale}

    def on_scale(self, upload_scale: Any = None, **_: Any) -> None:
        try:
            scale = scale_value(upload_scale)
        except UploadError as exc:
            self.state.upload_error = f"{exc}; kept the previous scale"
            return
        current = self.current
        if current.path is None:
            return  # the built-in target has its own scale
        if current.scene.target.scale_m_per_unit == scale:
            return
        self._start(lambda: load_uploaded(self.builtin.scene, current.path, scale))

    def on_target_choice(self, target_choice: Any = None, **_: Any) -> None:
        """A built-in target picked from the drop-down: load it off the event loop."""
        if target_choice is None or (
            target_choice == self.current.scene.target.mesh and self.current.path is None
        ):
            return  # no choice, or the choice is the target shown
        if isinstance(target_choice, str) and target_choice.startswith(UPLOAD_CHOICE):
            return  # the uploaded mesh: shown already (its item exists only while it is)
        if target_choice == self.builtin.scene.target.mesh:
            self.use_builtin()
            return
        if not isinstance(target_choice, str) or target_choice not in builtin_targets():
            self.state.upload_error = f"No built-in target {echo(target_choice)}"
            return
        self._file_name = target_choice
        self._start(lambda: load_builtin(self.builtin.scene, target_choice))

    def use_builtin(self, *_: Any, **__: Any) -> None:
        self._ticket += 1  # any upload still loading is dropped
        self._switch(self.builtin, "")
        self.state.update({"upload_busy": False, "upload_error": ""})

    # -- off the loop and back -------------------------------------------------------------------
    def _start(self, work: Callable[[], LoadedTarget]) -> None:
        self._ticket += 1
        ticket = self._ticket
        self.state.update({"upload_busy": True, "upload_error": "", "upload_message": ""})
        loop = _running_loop() if self.server.running else None
        if loop is None:  # tests without a server: run it here
            self._finish(ticket, _attempt(work))
            return
        future = loop.run_in_executor(None, _attempt, work)
        future.add_done_callback(lambda f: f.cancelled() or self._finish(ticket, f.result()))

    def _finish(self, ticket: int, outcome: LoadedTarget | str) -> None:
        if ticket != self._ticket:  # overtaken by a newer upload or the built-in target
            self._discard(outcome)
            return
        with self.state:
            self.state.upload_busy = False
            if isinstance(outcome, str):
                self._fail(f"{self._file_name}: {outcome}")
                return
            model = outcome.engine.model
            extent = float(model.mesh.extents.max())
            what = self._file_name if outcome.path is not None else model.name
            text = (
                f"Loaded {what}: {outcome.n_faces:,} triangles in {len(model.part_names)} "
                f"part(s), {extent:.3g} m long"
            )
            self._switch(outcome, text)

    def _discard(self, outcome: LoadedTarget | str) -> None:
        """Remove the file of an upload that will never be shown (unless it is in use)."""
        path = outcome.path if isinstance(outcome, LoadedTarget) else None
        if path is not None and path != self.current.path:
            path.unlink(missing_ok=True)

    def _fail(self, text: str) -> None:
        self.state.update({"upload_error": f"Upload refused: {text}", "upload_busy": False})

    def _switch(self, target: LoadedTarget, message: str) -> None:
        """Make ``target`` the app's target (the parent swaps engine, base scene, materials and
        mesh, then asks for a new frame)."""
        old = self.current
        self.current = target
        model = target.engine.model
        materials = resolved_materials(model, target.scene)
        items = catalogue_items()
        if target.path is not None:  # the drop-down names the uploaded mesh while it is shown
            item = upload_item(self._file_name)
            items.append(item)
        self.use_target(  # the target's parts and mesh, with busy (its frame is under way) ...
            target.scene,
            target.engine,
            dataclasses.replace(self.builtin_initial, materials=materials),
            model.name if target.path is None else item["title"],
        )
        with self.state:  # ... then the message: a page that sees it never sees the old parts
            self.state.update(
                {
                    "upload_message": message,
                    "target_is_upload": target.path is not None,
                    "target_items": items,
                    "target_choice": item["value"] if target.path else target.scene.target.mesh,
                }
            )
        if old.path is not None and old.path != target.path:
            old.path.unlink(missing_ok=True)


def _attempt(work: Callable[[], LoadedTarget]) -> LoadedTarget | str:
    """``work()``, or the message of why it failed (never a trace on the page)."""
    try:
        return work()
    except UploadError as exc:
        return str(exc)
    except Exception as exc:
        log.exception("loading an upload failed")
        return f"the mesh could not be loaded ({type(exc).__name__})"


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None
