"""``python -m app.server.zygote [app options]``: the parent of the launcher's session processes.

A session process spent about 2.3 s importing numpy, scipy, trame and vtk and 1 s loading its
target before it could listen, and held its own copy of all of it and of the compiled kernels its
first frame loaded. The zygote does that once (its kernels on numba's fork-safe workqueue
threads, see :func:`warm_up`), freezes the objects it made out of the garbage collector's reach
(``gc.freeze``: their pages stay shared) and then, for each line ``spawn TOKEN`` on its stdin,
forks a session. The app itself (its page, state, logic and pipelines, its first frame computed)
is built once too, before the first fork: each child serves its own copy of it as ``python -m app
--shared --token-stdin`` would, printing ``lmapd-sim app: http://127.0.0.1:PORT/?token=TOKEN``
once it listens (a new session then takes about 0.2 s to its first frame, against 0.6-0.9 s when
each built its own app and frame: docs/serving.md). The zygote prints ``lmapd-sim zygote:
forked PID for TOKEN-DIGEST`` first (the digest: sha256 of the token, 16 hex digits), so that the
launcher knows the process of each token.

A child stops with SIGTERM (as a session does) and when the zygote dies (the kernel's parent-death
signal); the zygote stops its children and exits when its stdin closes (the launcher is gone) or
on SIGTERM, and reaps them as they exit.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import signal
import sys

from app.server.children import ZYGOTE_READY as READY
from app.server.children import say
from app.server.children import token_digest as digest

PR_SET_PDEATHSIG = 1  # prctl(2)


def _die_with_parent() -> None:
    """SIGTERM this process when its parent (the zygote) dies (Linux; elsewhere nothing)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def warm_up(scene, model):
    """Compute a tiny frame (8 x 8 pixels) at the scene's fidelity and at the preview's, so that
    the compiled kernels and the tables every frame needs are loaded here once, in pages the
    sessions share (a session's own memory after its first 256 x 256 frame: 63 MB instead of
    190 MB). The kernels' threads are numba's workqueue layer (the launcher starts the zygote
    with NUMBA_THREADING_LAYER=workqueue): GNU OpenMP's, the default, aborts a process forked
    after using it.

    Then computes the app's first frame of the scene (``model``: its target; the frame at the
    controls a page starts with, app.logic.scene_map.first_scene) on the same pipeline, and
    returns it: its target stage (the mesh, its parts and the ray-casting structure, read-only
    once built) is every forked session's, so that no session builds its own (the MRO's: 10-20
    MB of BVH and 9 MB of arrays, twice a session with its previews); its other stages are each
    session's first frame, which a session then only turns into its views (a class opening the
    printed address together starts many sessions at once: each would compute the same frame)."""
    import simcore  # noqa: PLC0415
    from app.engine import Engine  # noqa: PLC0415
    from app.logic.scene_map import first_scene  # noqa: PLC0415

    tiny = simcore.with_overrides(scene, pixels=8)
    shared = simcore.Pipeline()
    shared.run(tiny)
    preview = simcore.Pipeline()
    preview.adopt(shared)
    preview.run(Engine.preview_scene(tiny))
    shared.run(first_scene(scene, model))
    return shared


def main(argv: list[str] | None = None) -> int:
    from app import main as app_main  # noqa: PLC0415  (after the version check of app/__main__)

    options = sys.argv[1:] if argv is None else argv
    args = app_main.parse_args(
        ["--shared", "--token-stdin", "--host", "127.0.0.1", "--port", "0", *options]
    )
    from app.server import connections  # noqa: PLC0415  (aiohttp: after the version check)

    # the sessions' logs as the launcher's: one short line per refusal or malformed request,
    # never the request line (it may carry a token) nor a traceback
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    connections.shorten_server_logs()
    import simcore  # noqa: PLC0415
    from app.engine import Engine  # noqa: PLC0415

    try:
        scene = simcore.load_scene(args.scene)
        model = simcore.load_target(scene.target)
        shared = warm_up(scene, model)
    except (simcore.SceneError, simcore.TargetError, OSError) as exc:
        print(f"lmapd app: {exc}", file=sys.stderr)
        return 2
    budget = int(max(1.0, args.frame_memory_mb) * 2**20)
    children: set[int] = set()

    def reap(*_) -> None:
        while children:
            try:
                pid, _status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            children.discard(pid)

    def stop(*_) -> None:
        for pid in list(children):
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                children.discard(pid)
        raise SystemExit(0)

    # the sessions' app (its page, state and logic), built once: about 0.45 s of a session's
    # start on this project's 2-core machine, most of it trame's building of the page
    app = app_main.LmapdApp(
        scene,
        engine=Engine(scene, model, budget, shared),
        previews=not args.no_preview,
        studies_dir=args.studies,
    )
    signal.signal(signal.SIGCHLD, reap)
    signal.signal(signal.SIGTERM, stop)
    gc.collect()
    gc.freeze()  # the modules' and the target's objects: never written by the collector
    say(READY)
    for line in sys.stdin:
        words = line.split()
        if len(words) != 2 or words[0] != "spawn":
            continue
        token = words[1]
        pid = os.fork()
        if pid == 0:  # the session
            signal.signal(signal.SIGCHLD, signal.SIG_DFL)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            _die_with_parent()
            os._exit(_serve(app, args, token, budget))
        children.add(pid)
        say(f"lmapd-sim zygote: forked {pid} for {digest(token)}")
    stop()
    return 0


def _serve(app, args, token: str, budget: int) -> int:
    """A forked session: ``app`` (the parent's, now this process's own copy) on its own server
    until SIGTERM (as ``python -m app --shared --token-stdin`` runs it); its exit status."""
    from app.server import process  # noqa: PLC0415  (after the version check, as app_main)
    from app.server.frame_memory import FrameGrants  # noqa: PLC0415

    try:
        sys.stdin.close()  # the zygote's: the launcher's spawn lines are not for the session
        app.token = token
        # the launcher's budget for frames across sessions (its socket is in the environment)
        app.logic.frame_grants = FrameGrants.from_environment(token)
        app.logic.studies.refresh()  # the study folders written since the app was built
        signal.signal(signal.SIGTERM, process.interrupt)
        process.limit_address_space(budget + process.HEADROOM_BYTES)
        input_idle_s = max(1.0, 60.0 * args.input_idle_min)
        return process.serve_until_stopped(
            lambda: app.start(args.host, args.port, input_idle_s=input_idle_s), args
        )
    except BaseException:  # a session that cannot start says why and exits; never returns
        import traceback  # noqa: PLC0415

        traceback.print_exc()
        return 1
    finally:
        sys.stdout.flush()


if __name__ == "__main__":
    from app.server.versions import FrameworkVersionError, check_framework_versions

    try:
        check_framework_versions()
    except FrameworkVersionError as exc:
        raise SystemExit(f"python -m app.server.zygote: {exc}") from None
    raise SystemExit(main())
