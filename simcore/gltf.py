"""glTF files before trimesh reads them: the container and its caps, and Draco-compressed
geometry (``KHR_draco_mesh_compression``) decoded safely.

NASA publishes its glTF models with their geometry Draco-compressed. trimesh decodes such
primitives through DracoPy (Google's Draco decoder), but first fills each compressed accessor with
zeros of the count the file declares, and the decoder is native code fed with the file's bytes.
A mesh file is untrusted data (an upload, a download), so before trimesh sees a glTF:

1. :func:`inspect_gltf` reads the container (a binary ``.glb``: header and chunks; a ``.gltf``:
   JSON with its buffers) and checks it against the caps below: the JSON's size, every accessor's
   count and the values all accessors together declare, the compressed bytes, the number of
   compressed primitives;
2. :func:`check_draco` decodes every compressed primitive in a child process that runs under a
   memory limit (``RLIMIT_AS``), a CPU-time limit and a wall-clock timeout, and checks what it
   decodes (point and triangle counts within the caps, every index in range). A stream the
   decoder rejects, that crashes it, exhausts its memory or runs too long gives one
   :class:`GltfError` naming what happened; the calling process is never at risk;
3. only then does trimesh read the file and decode the streams again, in process (the same
   library on the same bytes: it is now known to finish within the limits).

The caps (each well above NASA's models: MRO 250 k triangles, the largest model of NASA's 3D
Resources about 2 M):

- JSON chunk: at most ``MAX_JSON_BYTES`` (64 MiB);
- one accessor: at most ``MAX_ACCESSOR_COUNT`` (15 M) elements (the indices of 5 M triangles);
- all accessors together: at most ``MAX_ACCESSOR_VALUES`` (120 M) scalar values (what trimesh
  allocates for them: under 1 GB as float64);
- compressed streams: at most ``MAX_DRACO_BYTES`` (256 MiB) in all, ``MAX_DRACO_PRIMITIVES``
  (10 000) of them;
- the decoding child: ``DECODER_MEMORY_BYTES`` (3 GiB) of address space, ``DECODER_CPU_S`` (60 s)
  of CPU time, ``DECODER_WALL_S`` (120 s) of wall-clock time; each stream decodes to at most
  ``MAX_ACCESSOR_COUNT`` points and ``MAX_DRACO_FACES`` (5 M) triangles.

Only the standard library is imported here; the child imports DracoPy (and numpy).
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import signal
import struct
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

DRACO = "KHR_draco_mesh_compression"

MAX_JSON_BYTES = 64 * 2**20  # [byte] the JSON chunk of a glb, a whole .gltf
MAX_ACCESSOR_COUNT = 15_000_000  # [1] elements of one accessor (3 indices x 5 M triangles)
MAX_ACCESSOR_VALUES = 120_000_000  # [1] scalar values of all accessors together
MAX_DRACO_BYTES = 256 * 2**20  # [byte] compressed geometry in all
MAX_DRACO_PRIMITIVES = 10_000  # [1] compressed primitives
MAX_DRACO_FACES = 5_000_000  # [1] triangles one compressed primitive may decode to
DECODER_MEMORY_BYTES = 3 * 2**30  # [byte] address space of the decoding child
DECODER_CPU_S = 60  # [s] CPU time of the decoding child
DECODER_WALL_S = 120.0  # [s] wall-clock time of the decoding child

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_PROBE = Path(__file__).with_name("_draco_probe.py")


class GltfError(ValueError):
    """A glTF file is malformed, over a cap, or its compressed geometry cannot be decoded. The
    message names no file: callers add it."""


@dataclass(frozen=True)
class GltfInfo:
    """What :func:`inspect_gltf` found.

    Attributes
    ----------
    draco_streams : list of bytes
        The compressed geometry of each ``KHR_draco_mesh_compression`` primitive, in file order.
    n_accessor_values : int
        Scalar values all accessors declare together.
    """

    draco_streams: list[bytes] = field(default_factory=list)
    n_accessor_values: int = 0


def _glb_chunks(data: bytes) -> tuple[bytes, bytes | None]:
    """The JSON and BIN chunks of a binary glTF; GltfError if the container is malformed."""
    if len(data) < 20 or data[:4] != _GLB_MAGIC:
        raise GltfError("not a binary glTF (no glTF header)")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise GltfError(f"glTF version {version}: only version 2 is read")
    if length > len(data):
        raise GltfError(f"the file is truncated ({len(data)} of the {length} bytes it declares)")
    chunks: list[tuple[int, bytes]] = []
    offset = 12
    while offset + 8 <= length:
        size, kind = struct.unpack_from("<II", data, offset)
        if offset + 8 + size > length:
            raise GltfError("a chunk runs past the end of the file (truncated or corrupt)")
        chunks.append((kind, data[offset + 8 : offset + 8 + size]))
        offset += 8 + size
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise GltfError("the first chunk is not the JSON chunk")
    binary = next((c for k, c in chunks[1:] if k == _CHUNK_BIN), None)
    return chunks[0][1], binary


def _tree(text: bytes) -> dict:
    if len(text) > MAX_JSON_BYTES:
        raise GltfError(
            f"the glTF JSON is {len(text) / 2**20:.0f} MiB (at most {MAX_JSON_BYTES >> 20})"
        )
    try:
        tree = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise GltfError(f"the glTF JSON is not valid ({type(exc).__name__})") from None
    if not isinstance(tree, dict):
        raise GltfError("the glTF JSON is not an object")
    return tree


def _list(tree: dict, key: str) -> list:
    value = tree.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise GltfError(f"glTF {key!r} is not a list of objects")
    return value


def _index(value, items: list, what: str) -> dict:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < len(items):
        raise GltfError(f"glTF {what} {value!r} does not exist")
    return items[value]


def _count(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise GltfError(f"glTF {what} {value!r} is not a count")
    return value


def _buffer_bytes(buffer: dict, binary: bytes | None, folder: Path | None, index: int) -> bytes:
    """The bytes of glTF buffer ``index``: the BIN chunk, a data URI or (with ``folder``) a
    file beside the glTF."""
    uri = buffer.get("uri")
    if uri is None:
        if index != 0 or binary is None:
            raise GltfError(f"glTF buffer {index} has no data")
        return binary
    if not isinstance(uri, str):
        raise GltfError(f"glTF buffer {index}: uri is not a string")
    if uri.startswith("data:"):
        head, _, payload = uri.partition(",")
        if not head.endswith(";base64"):
            raise GltfError(f"glTF buffer {index}: only base64 data URIs are read")
        try:
            return base64.b64decode(payload, validate=True)
        except (binascii.Error, ValueError):
            raise GltfError(f"glTF buffer {index}: the data URI is not valid base64") from None
    if folder is None:
        raise GltfError(
            f"glTF buffer {index} is the external file {uri[:80]!r}: give a self-contained .glb"
        )
    path = folder / uri
    try:
        return path.read_bytes()
    except OSError as exc:
        raise GltfError(f"glTF buffer {index}: cannot read {uri[:80]!r} ({exc.strerror})") from None


def inspect_gltf(data: bytes, binary_container: bool, folder: Path | None = None) -> GltfInfo:
    """Check a glTF file against the caps and collect its Draco streams.

    Parameters
    ----------
    data : bytes
        The whole file.
    binary_container : bool
        True for a ``.glb``, False for a ``.gltf`` (JSON).
    folder : Path or None
        Where the buffers a ``.gltf`` names as files are read from; None: no file is read (an
        upload must be self-contained).

    Raises
    ------
    GltfError
        A malformed container, an accessor or buffer view that does not exist or is over a cap.
    """
    if binary_container:
        text, binary = _glb_chunks(data)
    else:
        text, binary = data, None
    tree = _tree(text)
    accessors = _list(tree, "accessors")
    views = _list(tree, "bufferViews")
    buffers = _list(tree, "buffers")
    values = 0
    for i, accessor in enumerate(accessors):
        count = _count(accessor.get("count"), f"accessor {i} count")
        if count > MAX_ACCESSOR_COUNT:
            raise GltfError(
                f"glTF accessor {i} declares {count:,} elements (at most {MAX_ACCESSOR_COUNT:,})"
            )
        values += count * _COMPONENTS.get(accessor.get("type"), 16)
    if values > MAX_ACCESSOR_VALUES:
        raise GltfError(
            f"the glTF accessors declare {values:,} values (at most {MAX_ACCESSOR_VALUES:,})"
        )
    compressed = [
        primitive["extensions"][DRACO]
        for mesh in _list(tree, "meshes")
        for primitive in _primitives(mesh)
        if isinstance(primitive.get("extensions"), dict) and DRACO in primitive["extensions"]
    ]
    if len(compressed) > MAX_DRACO_PRIMITIVES:
        raise GltfError(
            f"{len(compressed)} Draco-compressed primitives (at most {MAX_DRACO_PRIMITIVES})"
        )
    streams, total, loaded = [], 0, {}
    for extension in compressed:
        if not isinstance(extension, dict):
            raise GltfError(f"glTF {DRACO} is not an object")
        view = _index(extension.get("bufferView"), views, "Draco bufferView")
        b = view.get("buffer")
        buffer = _index(b, buffers, "buffer")
        if b not in loaded:
            loaded[b] = _buffer_bytes(buffer, binary, folder, b)  # type: ignore[arg-type]  # an int: _index checked it
        start = _count(view.get("byteOffset", 0), "bufferView byteOffset")
        length = _count(view.get("byteLength"), "bufferView byteLength")
        if start + length > len(loaded[b]):
            raise GltfError("a Draco bufferView runs past the end of its buffer (truncated?)")
        total += length
        if total > MAX_DRACO_BYTES:
            raise GltfError(f"more than {MAX_DRACO_BYTES >> 20} MiB of Draco-compressed geometry")
        streams.append(bytes(loaded[b][start : start + length]))
    return GltfInfo(draco_streams=streams, n_accessor_values=values)


def _primitives(mesh: dict) -> list[dict]:
    primitives = mesh.get("primitives", [])
    if not isinstance(primitives, list) or not all(isinstance(p, dict) for p in primitives):
        raise GltfError("glTF mesh primitives are not a list of objects")
    return primitives


def _frame(streams: list[bytes]) -> bytes:
    parts = [struct.pack("<Q", len(streams))]
    for s in streams:
        parts += [struct.pack("<Q", len(s)), s]
    return b"".join(parts)


def check_draco(streams: list[bytes]) -> list[tuple[int, int]]:
    """Decode every stream in a child process under the memory, CPU and time limits.

    Parameters
    ----------
    streams : list of bytes
        Draco-compressed meshes.

    Returns
    -------
    list of (n_points, n_faces)
        What each stream decodes to.

    Raises
    ------
    GltfError
        A stream that does not decode, decodes over the caps or to indices out of range; a
        decoder that crashes, runs out of memory or time; DracoPy not installed.
    """
    if not streams:
        return []
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    limits = f"{DECODER_MEMORY_BYTES} {DECODER_CPU_S} {MAX_ACCESSOR_COUNT} {MAX_DRACO_FACES}"
    try:
        done = subprocess.run(
            [sys.executable, "-I", str(_PROBE), *limits.split()],
            input=_frame(streams),
            capture_output=True,
            timeout=DECODER_WALL_S,
            env=env,
            check=False,
        )
    except subprocess.TimeoutExpired:
        raise GltfError(
            f"decoding the Draco-compressed geometry took more than {DECODER_WALL_S:g} s"
        ) from None
    if done.returncode < 0:
        name = signal.Signals(-done.returncode).name
        why = "ran out of CPU time" if name == "SIGXCPU" else f"crashed ({name})"
        raise GltfError(f"the Draco decoder {why} on this file's compressed geometry")
    lines = done.stdout.decode(errors="replace").splitlines()
    results: list[tuple[int, int]] = []
    for i, line in enumerate(lines):
        answer = json.loads(line)
        if "error" in answer:
            raise GltfError(f"Draco-compressed primitive {i} cannot be decoded: {answer['error']}")
        results.append((int(answer["points"]), int(answer["faces"])))
    if done.returncode != 0 or len(results) != len(streams):
        tail = done.stderr.decode(errors="replace").strip().splitlines()[-1:] or ["no message"]
        raise GltfError(f"the Draco decoder failed ({tail[0][:200]})")
    return results


def check_gltf_file(data: bytes, binary_container: bool, folder: Path | None = None) -> GltfInfo:
    """:func:`inspect_gltf`, then :func:`check_draco` on its streams: a glTF that passes is
    safe to hand to trimesh."""
    info = inspect_gltf(data, binary_container, folder)
    check_draco(info.draco_streams)
    return info
