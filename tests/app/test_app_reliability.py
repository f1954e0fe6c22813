"""Reliability and security of the app without a browser: it listens on 127.0.0.1 unless told
otherwise; every value a client can write into the websocket state or send with a trigger is
clamped or refused with a short message (never a crash, never a trace); users' uploaded meshes are
checked, kept in a private directory and never opened by a client-given path; a failing pipeline
stage keeps the last good frame; a worker thread that dies is replaced."""

from __future__ import annotations

import math
import os
import stat
import struct
import sys
import threading
import time
from pathlib import Path
from urllib.parse import urlsplit

import msgpack
import numpy as np
import pytest
import trimesh
from support.app_helpers import change, settle
from support.launch import app_server

import simcore
from app.engine import Engine
from app.logic import upload as upload_mod
from app.main import LmapdApp
from app.runner import Runner
from app.state import MAX_ECHO_CHARS, SPECS, STATE_KEYS, sanitize_controls

SMALL = {"pixels": 48, "fidelity.subrays": 1}


@pytest.fixture(scope="module")
def engine():
    return Engine(simcore.load_scene())


@pytest.fixture
def app(engine):
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    fresh = Engine(scene, model=engine.model)
    lmapd = LmapdApp(scene, engine=fresh, flow_control=False, debounce_s=0.0)
    lmapd.state.ready()
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()
    lmapd.uploads.files.cleanup()


def assert_healthy(app: LmapdApp) -> None:
    """The app still works: no trace anywhere, a frame of the current controls is shown."""
    s = app.state
    for key in ("input_message", "error_message", "upload_error", "upload_message"):
        assert "Traceback" not in str(s[key]) and len(str(s[key])) < 2000, key
    assert app.logic.runner._thread.is_alive()
    assert s.frame_key and not s.busy


# -- 1. the address the server listens on --------------------------------------------------------
def test_main_listens_on_loopback_unless_a_host_is_given(monkeypatch):
    from app import main as main_mod

    started: list[tuple[str, int]] = []

    class FakeApp:
        def __init__(self, scene, **_):
            pass

        def start(self, host, port, origins=(), input_idle_s=None):
            assert input_idle_s is None  # a --shared server's sessions are its pages: no reaping
            started.append((host, port))

    monkeypatch.setattr(main_mod, "LmapdApp", FakeApp)
    assert main_mod.main(["--shared"]) == 0
    assert main_mod.main(["--shared", "--host", "0.0.0.0", "--port", "9001"]) == 0
    assert started == [("127.0.0.1", 8080), ("0.0.0.0", 9001)]
    # without --shared: the launcher (each tab its own session), on the same address
    launched: list[tuple[str, int, int | None]] = []
    monkeypatch.setattr(
        main_mod, "run_launcher", lambda a: launched.append((a.host, a.port, a.max_sessions)) or 0
    )
    assert main_mod.main([]) == 0 and main_mod.main(["--port", "9002", "--max-sessions", "3"]) == 0
    assert launched == [("127.0.0.1", 8080, None), ("127.0.0.1", 9002, 3)]


def test_the_start_message_names_the_address_and_warns_off_loopback():
    from app.server.addresses import start_message

    assert start_message("127.0.0.1", 8080, "T0k-en_") == [
        "lmapd-sim app: http://127.0.0.1:8080/?token=T0k-en_  (Ctrl+C stops it)"
    ]
    lines = start_message("0.0.0.0", 9000, "abc", lan=["192.168.1.20", "10.0.0.5"])
    assert lines[0].startswith("lmapd-sim app: http://127.0.0.1:9000/?token=abc ")
    assert lines[1] == "lmapd-sim app: on the network: http://192.168.1.20:9000/?token=abc"
    assert lines[2] == "lmapd-sim app: on the network: http://10.0.0.5:9000/?token=abc"
    assert "warning: listening on 0.0.0.0, not only on this machine" in lines[3]
    assert not any("0.0.0.0:" in line for line in lines)  # no address a student could not open
    assert "no network address found" in start_message("0.0.0.0", 9000, "abc", lan=[])[1]
    assert start_message("::1", 8080, "abc")[0].startswith("lmapd-sim app: http://[::1]:8080/?")


def _listening_addresses(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp*) of the sockets listening on ``port``."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            address, port_hex = fields[1].rsplit(":", 1)
            if int(port_hex, 16) == port and fields[3] == "0A":  # 0A: LISTEN
                found.add(address)
    return found


@pytest.mark.slow
def test_the_server_binds_127_0_0_1_only_and_says_so_at_start(tmp_path):
    log_path = tmp_path / "server.log"
    with app_server(log_path=log_path) as url:
        port = urlsplit(url).port
        announced = f"lmapd-sim app: http://127.0.0.1:{port}/?token="
        deadline = time.monotonic() + 10
        while announced not in log_path.read_text() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert announced in log_path.read_text()
        assert _listening_addresses(port) == {"0100007F"}  # 127.0.0.1, not 0.0.0.0 or ::


# -- 2. whatever the websocket state holds ---------------------------------------------------------
BAD_VALUES = [
    math.nan,
    math.inf,
    -math.inf,
    "x" * 1_000_000,
    "9" * 5000,
    list(range(100_000)),
    {"a": {"b": [1, {"c": None}]}},
    [[[[[[1]]]]]],
    None,
    True,
    -(2**63),
]


@pytest.mark.parametrize("key", STATE_KEYS)
def test_every_control_survives_every_kind_of_garbage(app, key):
    for bad in BAD_VALUES:
        change(app, **{key: bad})
        controls = app.logic.controls
        value = getattr(controls, key)
        if key in SPECS:
            spec = SPECS[key]
            assert spec.lo <= value <= spec.hi and math.isfinite(value), (key, bad)
        assert app.state[key] == controls.as_state()[key], (key, type(bad))
        assert len(app.state.input_message) < 1000, (key, type(bad))
        assert_healthy(app)
    assert app.logic.last_frame.result.scene.detector.pixels == app.logic.controls.pixels


def test_a_refused_huge_string_is_quoted_short():
    from app.state import Controls

    _, messages = sanitize_controls({"tnr": "y" * 10_000_000}, Controls())
    assert len(messages) == 1 and len(messages[0]) < MAX_ECHO_CHARS + 40
    _, messages = sanitize_controls({"materials": {str(i): "x" for i in range(10_000)}}, Controls())
    assert messages == ["Materials: 10000 entries is too many; kept"]


def test_garbage_selections_triggers_and_unknown_keys_change_nothing(app):
    before = app.state.selected_pixels
    for selection in (list(range(1_000_000)), [[1, 2]] * 1000, [[math.nan, 1]], "x" * 10**6):
        with app.state:
            app.state.selected_pixels = selection
        change(app, tnr=float(np.random.default_rng().uniform(2, 9)))
        assert len(app.state.selected_pixels) <= 8
    app.logic.on_pixel_click(math.inf, math.nan, {"x": 1})
    app.logic.on_pixel_click([1], {"a": 2}, None, 5, 6, extra=7)
    app.logic.on_frame_shown(["not", "hashable"])
    app.logic.on_frame_shown({"a": 1}, 2, 3, k=4)
    app.logic.reset_controls("unexpected", argument=1)
    settle(app)
    with app.state:
        app.state.update({"some_key_of_its_own": "z" * 1_000_000, "frame_key": [1, 2]})
    change(app, seed=11)
    assert app.logic.last_frame.result.scene.seed == 11
    assert before is not None
    assert_healthy(app)


# -- 3. uploads ---------------------------------------------------------------------------------
def box_stl(extents=(2.0, 1.0, 0.5)) -> bytes:
    return trimesh.creation.box(extents=extents).export(file_type="stl")


def two_part_obj() -> bytes:
    return (
        b"mtllib ../../../../../../etc/passwd\n"
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
        b"usemtl alpha\nf 1 2 3\nf 1 2 4\nusemtl beta\nf 1 3 4\nf 2 3 4\n"
    )


def upload(app: LmapdApp, data: bytes, name: str = "box.stl", **extra) -> None:
    item = {"name": name, "size": len(data), "type": "", "lastModified": 0, "content": data}
    with app.state:
        app.state.upload_file = [{**item, **extra}]
    settle(app)


_opened: list[str] = []
_watching = threading.Event()


def _audit(event: str, args: tuple) -> None:
    if _watching.is_set() and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
        _opened.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)


def test_an_uploaded_mesh_becomes_the_target_from_a_private_copy(app):
    _opened.clear()
    _watching.set()
    try:
        upload(app, box_stl(), name="../../../tmp/evil/../box.STL")
    finally:
        _watching.clear()
    s = app.state
    assert s.upload_error == "" and s.upload_message.startswith("Loaded 'box.STL': 12 triangles")
    assert s.target_is_upload and s.target_name == "box.STL (uploaded)"  # the base name only
    folder = app.uploads.files.path
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    source = Path(app.logic.last_frame.result.target.source)
    assert source.parent == folder and source.suffix == ".glb"
    assert not any("evil" in p or "box.STL" in p for p in _opened), _opened
    assert s.part_names == list(app.logic.engine.model.part_names)
    assert set(s.materials) == set(s.part_names)
    assert len(s.target_polys["shape"]) == 1 and s.target_polys["shape"][0] == 4 * 12
    assert app.logic.last_frame.result.summary()["n_points"] > 0
    extent = app.logic.engine.model.mesh.extents.max()
    assert extent == pytest.approx(2.0)
    change(app, upload_scale=3)  # 3 m per unit: 6 m long
    assert app.logic.engine.model.mesh.extents.max() == pytest.approx(6.0)
    assert "6 m long" in s.upload_message
    assert app.logic.last_frame.result.target.mesh.extents.max() == pytest.approx(6.0)
    assert_healthy(app)

    app.uploads.use_builtin()
    settle(app)
    assert s.target_name == "Mars Reconnaissance Orbiter" or "foil" in s.part_names
    assert not s.target_is_upload and not source.exists()
    assert "foil" in app.logic.last_frame.result.target.part_names
    app.uploads.files.cleanup()
    assert not folder.exists()


def test_an_obj_never_has_its_mtllib_opened_and_its_parts_get_drop_downs(app):
    _opened.clear()
    _watching.set()
    try:
        upload(app, two_part_obj(), name="parts.obj")
    finally:
        _watching.clear()
    assert app.state.upload_error == ""
    assert not any("passwd" in p for p in _opened), _opened
    parts = app.state.part_names
    assert len(parts) == 2 and set(app.state.materials) == set(parts)
    change(app, materials={parts[0]: "lambertian", parts[1]: "coating_1"})
    assert dict(app.logic.last_frame.result.scene.target.materials)[parts[0]] == "lambertian"
    assert_healthy(app)


DEGENERATE = [
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "x.obj", "no triangles"),
    (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 1 2 4\n", "x.obj", "zero surface area"),
    (
        b"\0" * 80
        + struct.pack("<I", 1)
        + np.array([[0, 0, 1, 0, 0, 0, np.nan, 0, 0, 0, 1, 0]], np.float32).tobytes()
        + b"\0\0",
        "nan.stl",
        "the mesh has NaN or infinite vertex coordinates",  # not a triangle silently dropped
    ),
    (b"glTF\x02\x00\x00\x00" + b"\xff" * 40, "x.glb", "cannot read the .glb file"),
    (b"solid x\nfacet garbage\n", "x.stl", ""),
    (box_stl(), "x.exe", "is not a mesh file"),
    (box_stl(), "noextension", "is not a mesh file"),
    (b"", "x.stl", "the file is empty"),
]


@pytest.mark.parametrize(("data", "name", "message"), DEGENERATE)
def test_bad_uploads_are_refused_with_a_message_and_the_target_kept(app, data, name, message):
    parts, good = list(app.state.part_names), app.logic.last_frame
    upload(app, data, name=name)
    s = app.state
    assert s.upload_error.startswith("Upload refused: ") and message in s.upload_error
    assert "Traceback" not in s.upload_error and len(s.upload_error) < 400
    assert s.part_names == parts and app.logic.last_frame is good and not s.target_is_upload
    assert s.upload_file is None


def test_upload_caps_size_faces_scale_and_shape(app, monkeypatch):
    upload(app, box_stl(), size=upload_mod.MAX_UPLOAD_BYTES + 1)
    assert "uploads are limited to 32 MiB" in app.state.upload_error
    monkeypatch.setattr(upload_mod, "MAX_UPLOAD_FACES", 10)
    upload(app, box_stl())
    assert "the .stl file declares 12 triangles; the limit is 10" in app.state.upload_error
    monkeypatch.undo()
    change(app, upload_scale="lots")
    assert "scale 'lots' is not a number" in app.state.upload_error
    change(app, upload_scale=math.inf)
    assert "outside 1e-06 to 10000 m per unit" in app.state.upload_error
    change(app, upload_scale=9000)  # a 2-unit box at 9 km per unit: 18 km long
    upload(app, box_stl())
    assert "targets must be 0.001 m to 10000 m long" in app.state.upload_error
    for value in (None, "text", 42, [1, 2], [{"name": "a.stl"}], {"name": "a.stl", "content": 5}):
        with app.state:
            app.state.upload_file = value
        settle(app)
        assert app.state.upload_file is None
    assert not app.state.target_is_upload
    assert_healthy(app)


def test_the_core_refuses_targets_of_an_implausible_size(tmp_path):
    path = tmp_path / "box.stl"
    path.write_bytes(box_stl())
    for scale in (1e-5, 1e5):
        with pytest.raises(simcore.TargetError, match="m long once scaled"):
            simcore.load_target(simcore.scene.Target(mesh=str(path), scale_m_per_unit=scale))
    model = simcore.load_target(simcore.scene.Target(mesh=str(path), scale_m_per_unit=1.0))
    assert model.mesh.extents.max() == pytest.approx(2.0)


# -- 5. faults -----------------------------------------------------------------------------------
def test_an_exception_inside_a_pipeline_stage_keeps_the_last_good_result(app, monkeypatch):
    good, points = app.logic.last_frame, app.state.n_points

    def broken(*args, **kwargs):
        raise FloatingPointError("receiver blew up")

    monkeypatch.setattr(simcore.receivers.lm_apd.apd, "receiver_model", broken)
    change(app, pulse_energy_mj=1.5)
    s = app.state
    assert s.error_message.startswith("Simulation failed (FloatingPointError): receiver blew up")
    assert "showing the last good result" in s.error_message and "Traceback" not in s.error_message
    assert app.logic.last_frame is good and s.n_points == points and not s.busy
    monkeypatch.undo()
    change(app, pulse_energy_mj=1.6)
    assert s.error_message == "" and app.logic.last_frame is not good


def test_a_worker_killed_mid_computation_is_replaced_and_the_app_goes_on(app, monkeypatch):
    compute = app.logic.runner._compute
    calls = []

    def dying(request):
        calls.append(1)
        if len(calls) == 1:
            raise SystemExit("killed")  # not an Exception: the worker thread itself dies
        return compute(request)

    monkeypatch.setattr(app.logic.runner, "_compute", dying)
    first = app.logic.runner._thread
    change(app, tnr=7.5)
    assert "the worker stopped (SystemExit); restarted" in app.state.error_message
    runner = app.logic.runner
    assert runner.n_restarts == 1 and runner._thread is not first and runner._thread.is_alive()
    change(app, tnr=7.7)
    assert app.state.error_message == ""
    assert app.logic.last_frame.result.scene.timing.tnr == 7.7


def test_a_worker_thread_that_ended_is_noticed_at_the_next_request():
    class Fragile(Runner):
        died = False

        def _loop(self):
            if not Fragile.died:  # the first worker just ends, as if killed
                Fragile.died = True
                return
            super()._loop()

    got = []
    runner = Fragile(lambda x: x + 1, got.append, debounce_s=0.0)
    runner._thread.join(2)
    assert not runner._thread.is_alive()
    runner.submit(1)
    assert runner.wait_idle(5)
    assert [o.value for o in got] == [2] and runner.n_restarts == 1
    runner.close()


@pytest.mark.parametrize("key", ["mode", "fly_t_s", "fly_j2", "fly_playing"])
def test_the_fly_around_controls_survive_garbage_too(app, key):
    initial = {k: app.state[k] for k in ("mode", "fly_t_s", "fly_j2")}
    for bad in BAD_VALUES:
        change(app, **{key: bad})
        change(app, fly_playing=False)
        for k in ("input_message", "error_message"):
            assert len(str(app.state[k])) < 1000 and "Traceback" not in str(app.state[k])
        assert app.logic.runner._thread.is_alive()
    change(app, fly_playing=False, **initial)
    change(app, seed=21)
    assert app.logic.last_frame.result.scene.seed == 21
    assert_healthy(app)


def test_websocket_messages_over_the_cap_are_refused_before_allocation():
    from wslink import chunking

    from app.server.security import (
        MAX_MESSAGE_BYTES,
        BoundedUnChunker,
        Limits,
        PendingBudget,
        Refused,
    )

    limits = Limits()
    unchunker = BoundedUnChunker(limits, PendingBudget(limits.total_budget_bytes))
    unchunker.set_max_message_size(4 * 1024**3)  # what wslink grants an authenticated client
    assert limits.message_bytes == MAX_MESSAGE_BYTES
    header = chunking._encode_header(7, 0, 2 * 1024**3)  # "a 2 GB message follows"
    with pytest.raises(Refused, match="the limit is"):
        unchunker.process_chunk(header + b"x")
    assert not unchunker.pending and unchunker.budget.reserved_bytes == 0
    message = next(chunking.generate_chunks(msgpack.packb({"a": 1}), 0))
    assert unchunker.process_chunk(message) == {"a": 1}


# -- issue 20: NaN meshes in every format, upload files, partial-message budgets ------------------
def _nan_mesh() -> trimesh.Trimesh:
    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 1], [0, 1, 1]]
    return trimesh.Trimesh(vertices, [[0, 1, 2], [0, 1, 3], [0, 2, 4]], process=False)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".glb"])
def test_a_nan_vertex_refuses_the_mesh_in_every_format(app, tmp_path, suffix):
    data = _nan_mesh().export(file_type=suffix[1:])
    data = data.encode() if isinstance(data, str) else data
    path = tmp_path / f"nan{suffix}"
    path.write_bytes(data)
    scene = simcore.with_overrides(simcore.load_scene(), {"target.mesh": str(path)})
    with pytest.raises(simcore.TargetError, match="NaN or infinite vertex coordinates"):
        simcore.load_target(scene.target)  # the CLI's loading
    upload(app, data, name=f"mesh{suffix}")  # and the app's
    assert "the mesh has NaN or infinite vertex coordinates" in app.state.upload_error
    assert not app.state.target_is_upload


def test_a_refused_or_replaced_upload_leaves_no_file(app):
    change(app, upload_scale=9000)  # the core refuses the converted mesh: 18 km long
    upload(app, box_stl())
    assert "targets must be" in app.state.upload_error
    folder = app.uploads.files.path
    assert list(folder.iterdir()) == []
    change(app, upload_scale=1.0)
    upload(app, box_stl())
    first = app.uploads.current.path
    assert app.state.target_is_upload and list(folder.iterdir()) == [first]
    upload(app, box_stl((3.0, 1.0, 1.0)))  # replaced
    assert list(folder.iterdir()) == [app.uploads.current.path] != [first]
    outcome = upload_mod.load_uploaded(
        app.uploads.builtin.scene, app.uploads.files.write(box_stl(), ".stl"), 1.0
    )
    app.uploads._finish(app.uploads._ticket - 1, outcome)  # an overtaken upload's late result
    assert not outcome.path.exists()
    app.uploads.use_builtin()
    assert list(folder.iterdir()) == []


class _Clock:
    def __init__(self):
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def test_partial_messages_are_bounded_per_connection_in_total_and_in_time():
    from wslink.chunking import _encode_header

    from app.server.security import BoundedUnChunker, Limits, PendingBudget, Refused

    limits = Limits(
        message_bytes=1000,
        connection_budget_bytes=1500,
        total_budget_bytes=2500,
        max_pending_messages=3,
        partial_timeout_s=10.0,
    )
    budget, clock = PendingBudget(limits.total_budget_bytes), _Clock()
    one = BoundedUnChunker(limits, budget, clock)
    one.process_chunk(_encode_header(1, 0, 1000) + b"x" * 13)
    with pytest.raises(Refused, match="connection's budget"):  # 1000 + 1000 > 1500
        one.process_chunk(_encode_header(2, 0, 1000) + b"x" * 13)
    assert budget.reserved_bytes == 1000 and len(bytes(one.pending[1].content)) == 13
    two = BoundedUnChunker(limits, budget, clock)
    two.process_chunk(_encode_header(1, 0, 1000) + b"y")
    with pytest.raises(Refused, match="server's budget"):  # 2000 + 1000 > 2500
        BoundedUnChunker(limits, budget, clock).process_chunk(_encode_header(1, 0, 1000))
    with pytest.raises(Refused, match="out of order"):
        two.process_chunk(_encode_header(1, 500, 1000) + b"y")
    assert budget.reserved_bytes == 1000  # the broken message was dropped
    for i in range(3):
        two.process_chunk(_encode_header(10 + i, 0, 100) + b"z")
    with pytest.raises(Refused, match="more than 3 partial"):
        two.process_chunk(_encode_header(20, 0, 100) + b"z")
    clock.now_s = 10.5
    assert one.expired()
    with pytest.raises(Refused, match="took over 10 s"):
        one.process_chunk(_encode_header(1, 13, 1000) + b"x")
    one.release_pending_messages()
    two.release_pending_messages()
    assert budget.reserved_bytes == 0
    with pytest.raises(Refused, match="past the end"):
        one.process_chunk(_encode_header(3, 0, 4) + b"12345")
    with pytest.raises(Refused, match="undecodable"):
        one.process_chunk(_encode_header(4, 0, 1) + b"\xc1")
    assert budget.reserved_bytes == 0


def test_the_lan_addresses_leave_out_loopback_and_link_local(monkeypatch):
    import socket
    from types import SimpleNamespace

    import psutil

    from app.server.addresses import lan_addresses

    def addr(family, address):
        return SimpleNamespace(family=family, address=address)

    interfaces = {
        "lo": [addr(socket.AF_INET, "127.0.0.1"), addr(socket.AF_INET6, "::1")],
        "eth0": [
            addr(socket.AF_INET, "192.168.1.20"),
            addr(socket.AF_INET6, "fe80::1%eth0"),
            addr(socket.AF_INET6, "2001:db8::5"),
        ],
        "wlan0": [addr(socket.AF_INET, "169.254.3.4"), addr(socket.AF_INET, "10.0.0.5")],
    }
    monkeypatch.setattr(psutil, "net_if_addrs", lambda: interfaces)
    assert lan_addresses("0.0.0.0") == ["192.168.1.20", "10.0.0.5"]
    assert lan_addresses("::") == ["192.168.1.20", "2001:db8::5", "10.0.0.5"]
    assert lan_addresses("127.0.0.1") == []
