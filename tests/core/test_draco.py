"""Draco-compressed glTF: a round trip through the loader, and hostile streams (malformed,
truncated, mutated, over the caps) refused with one clear message, nothing cached.

The fuzzing runs under a time and memory bound: every stream the loader sees is decoded first
in a child process limited to simcore.gltf.DECODER_MEMORY_BYTES (3 GiB) of address space and
DECODER_CPU_S (60 s) of CPU time; the raw decoder fuzz runs in a subprocess of its own under a
2 GiB address-space limit and a 300 s timeout, on streams of at most 4 KiB.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.gltf import QUANTIZATION_BITS, draco_glb, draco_stream, glb

import simcore
from simcore import gltf
from simcore.gltf import GltfError, check_draco
from simcore.scene import Target
from simcore.target import TargetError, load_target, mesh_geometry

ROOT = Path(__file__).resolve().parents[2]


def icosphere():
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.5)
    return sphere.vertices + [0.2, -0.1, 3.0], sphere.faces


def test_a_draco_mesh_loads_with_the_same_triangles(tmp_path):
    vertices, faces = icosphere()
    path = tmp_path / "sphere.glb"
    path.write_bytes(draco_glb(vertices, faces))
    geometry = mesh_geometry(path)
    assert geometry.part_names == ("hull",)
    assert np.array_equal(geometry.faces, faces)
    # Draco quantizes each coordinate onto 2**bits steps over the box: half a step at most
    step = np.ptp(vertices, axis=0).max() / (2**QUANTIZATION_BITS - 1)
    assert np.abs(geometry.vertices - vertices).max() <= 0.5 * step + 1e-6
    model = load_target(Target(mesh=str(path), scale_m_per_unit=1.0))
    assert len(model.faces) == len(faces)
    assert model.extents_m == pytest.approx(np.ptp(vertices, axis=0), abs=step)


def test_a_draco_mesh_simulates(tmp_path):
    vertices, faces = icosphere()
    path = tmp_path / "sphere.glb"
    path.write_bytes(draco_glb(vertices, faces))
    result = simcore.simulate(overrides={"target.mesh": str(path), "target.size_m": 3.0}, pixels=32)
    assert result.summary()["n_hit_pixels"] > 0
    assert np.isfinite(result.points).all()


def broken(tmp_path, stream: bytes, name="broken.glb", material="hull") -> Path:
    vertices, faces = icosphere()
    path = tmp_path / name
    path.write_bytes(draco_glb(vertices, faces, stream=stream, material=material))
    return path


def cache_entries() -> set[Path]:
    from simcore.cache import cache_dir

    return set((cache_dir() / "targets").glob("*.npz"))


@pytest.mark.parametrize(
    "damage",
    [
        lambda s: s[: len(s) // 2],  # truncated
        lambda s: b"",  # empty
        lambda s: b"not draco at all" * 8,  # garbage
        lambda s: s[:8] + bytes(b ^ 0xFF for b in s[8:40]) + s[40:],  # header fields flipped
    ],
    ids=["truncated", "empty", "garbage", "flipped"],
)
def test_a_broken_draco_stream_gives_one_clear_message_and_nothing_cached(tmp_path, damage):
    vertices, faces = icosphere()
    path = broken(tmp_path, damage(draco_stream(vertices, faces)))
    before = cache_entries()
    with pytest.raises(TargetError, match=r"broken\.glb: .*Draco") as error:
        load_target(Target(mesh=str(path)))
    assert "\n" not in str(error.value)
    assert cache_entries() == before


def test_a_stream_that_decodes_over_the_caps_is_refused(tmp_path, monkeypatch):
    vertices, faces = icosphere()
    monkeypatch.setattr(gltf, "MAX_DRACO_FACES", len(faces) - 1)
    path = broken(tmp_path, draco_stream(vertices, faces), material="capped")  # not cached
    with pytest.raises(TargetError, match="over the caps"):
        load_target(Target(mesh=str(path)))


def test_an_accessor_over_the_caps_is_refused_before_any_decoding(tmp_path):
    vertices, faces = icosphere()
    data = draco_glb(vertices, faces)
    (n,) = struct.unpack_from("<I", data, 12)
    tree = json.loads(data[20 : 20 + n])
    tree["accessors"][1]["count"] = gltf.MAX_ACCESSOR_COUNT + 1  # trimesh would allocate it
    path = tmp_path / "huge.glb"
    path.write_bytes(glb(tree, data[20 + n + 8 :]))
    with pytest.raises(
        TargetError, match=r"huge\.glb: cannot read the \.glb file \(glTF accessor 1 declares"
    ):
        load_target(Target(mesh=str(path)))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"glTF\x02\0\0\0\xff\xff\0\0", "not a binary glTF"),
        (b"glTF" + struct.pack("<II", 2, 1 << 20) + b"\0" * 20, "truncated"),
        (
            b"glTF" + struct.pack("<II", 2, 28) + struct.pack("<II", 8, 0x4E4F534A) + b"[1,2,3] ",
            "not an object",
        ),
    ],
    ids=["short", "truncated", "json-not-object"],
)
def test_a_malformed_container_is_refused_with_its_reason(tmp_path, data, message):
    path = tmp_path / "bad.glb"
    path.write_bytes(data)
    with pytest.raises(TargetError, match=message):
        load_target(Target(mesh=str(path)))


def test_a_decoder_that_crashes_or_runs_away_is_contained(monkeypatch, tmp_path):
    """The child's fate, not the decoder's, is what the parent sees: a crash and a timeout."""
    crash = tmp_path / "crash.py"
    crash.write_text("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    monkeypatch.setattr(gltf, "_PROBE", crash)
    with pytest.raises(GltfError, match=r"crashed \(SIGSEGV\)"):
        check_draco([b"x"])
    hang = tmp_path / "hang.py"
    hang.write_text("import time\ntime.sleep(60)\n")
    monkeypatch.setattr(gltf, "_PROBE", hang)
    monkeypatch.setattr(gltf, "DECODER_WALL_S", 0.5)
    with pytest.raises(GltfError, match="took more than 0.5 s"):
        check_draco([b"x"])


def _mutations():
    vertices, faces = icosphere()
    valid = draco_stream(vertices, faces)
    flips = st.lists(
        st.tuples(st.integers(0, len(valid) - 1), st.integers(1, 255)), min_size=1, max_size=8
    )

    def flip(pairs):
        data = bytearray(valid)
        for at, mask in pairs:
            data[at] ^= mask
        return bytes(data)

    return st.one_of(
        flips.map(flip),
        st.integers(0, len(valid)).map(lambda n: valid[:n]),
        st.binary(max_size=512).map(lambda b: valid[:16] + b),
    )


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stream=_mutations())
def test_mutated_streams_decode_or_give_a_gltf_error_through_the_guard(stream):
    try:
        counts = check_draco([stream])
    except GltfError as exc:
        assert str(exc) and "\n" not in str(exc)
    else:
        ((n_points, n_faces),) = counts
        assert 0 < n_faces <= gltf.MAX_DRACO_FACES and n_points <= gltf.MAX_ACCESSOR_COUNT


FUZZ = textwrap.dedent(
    """
    import resource, sys
    resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))
    sys.path[:0] = [{tests!r}, {simcore!r}]
    from hypothesis import given, settings, strategies as st
    import trimesh
    from support.gltf import draco_stream
    from _draco_probe import _decode
    s = trimesh.creation.icosphere(subdivisions=2)
    valid = draco_stream(s.vertices, s.faces)
    outcomes = {{"decoded": 0, "refused": 0}}

    @settings(max_examples=400, deadline=None, database=None, derandomize=True)
    @given(st.lists(st.tuples(st.integers(0, len(valid) - 1), st.integers(1, 255)), max_size=16),
           st.integers(0, len(valid)))
    def fuzz(flips, keep):
        data = bytearray(valid[:keep])
        for at, mask in flips:
            if at < len(data):
                data[at] ^= mask
        answer = _decode(bytes(data), 15_000_000, 5_000_000)
        if "error" in answer:
            assert isinstance(answer["error"], str) and answer["error"]
            outcomes["refused"] += 1
        else:
            assert 0 < answer["faces"] and 0 < answer["points"]
            outcomes["decoded"] += 1

    fuzz()
    print(outcomes)
    """
)


def test_the_decoder_survives_mutated_streams_under_a_memory_bound():
    """400 mutated and truncated streams through the child's decode-and-check (DracoPy, then the
    counts and indices checked), in a subprocess limited to 2 GiB of address space and 300 s: each
    decodes within the caps or gives an error; nothing crashes or runs out of its bounds."""
    script = FUZZ.format(tests=str(ROOT / "tests"), simcore=str(ROOT / "simcore"))
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "refused" in done.stdout
