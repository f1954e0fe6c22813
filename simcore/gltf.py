"""glTF files before trimesh reads them: the container and its caps, and Draco-compressed
geometry (``KHR_draco_mesh_compression``) decoded safely.

Over 500 lines: one untrusted format's checks, every one made before an array is, read in the
order a file is (container, buffers, views, accessors, meshes and nodes, Draco streams).

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
- all primitives together, each counted once per node that shows its mesh (trimesh makes one
  mesh of every primitive, with arrays of its own, even where primitives share accessors): at
  most ``MAX_TRIANGLES`` (10 M) triangles and ``MAX_VERTICES`` (30 M) vertices, or the limits a
  caller gives (an upload's are lower). Counted from what the accessors declare, before any array
  is made, and again with what the compressed streams decode to;
- every accessor's data inside its buffer view, every buffer view inside its buffer, every buffer
  holding the bytes it declares; an accessor with no buffer view (trimesh fills it with zeros of
  the declared count) is read only where a compressed primitive fills it or it is sparse;
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
MAX_TRIANGLES = 10_000_000  # [1] triangles of all primitives, each node's instance counted
MAX_VERTICES = 30_000_000  # [1] vertices of all primitives, each node's instance counted
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
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}  # componentType: bytes
_TRIANGLES, _STRIP, _FAN = 4, 5, 6  # primitive modes that make triangles (0-3: points, lines)
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
    n_triangles, n_vertices : int
        Triangles and vertices all primitives declare, each mesh counted once per node showing it.
    draco_instances : list of int
        How many times each compressed stream is counted (the nodes showing its mesh).
    plain_triangles, plain_vertices : int
        The part of ``n_triangles`` and ``n_vertices`` that is not compressed.
    """

    draco_streams: list[bytes] = field(default_factory=list)
    n_accessor_values: int = 0
    n_triangles: int = 0
    n_vertices: int = 0
    draco_instances: list[int] = field(default_factory=list)
    plain_triangles: int = 0
    plain_vertices: int = 0


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


def _buffer_lengths(
    buffers: list[dict], binary: bytes | None, folder: Path | None
) -> tuple[list[int], dict[int, bytes]]:
    """The byte length of every buffer (checked against what it declares), and the bytes of
    those held in the file (the BIN chunk, data URIs); a file beside a ``.gltf`` is measured,
    not read."""
    lengths, held = [], {}
    for i, buffer in enumerate(buffers):
        declared = _count(buffer.get("byteLength"), f"buffer {i} byteLength")
        uri = buffer.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:") and folder is not None:
            try:
                size = (folder / uri).stat().st_size
            except OSError as exc:
                raise GltfError(
                    f"glTF buffer {i}: cannot read {uri[:80]!r} ({exc.strerror})"
                ) from None
        else:  # the BIN chunk or a data URI (an external file with no folder: refused there)
            held[i] = _buffer_bytes(buffer, binary, folder, i)
            size = len(held[i])
        if size < declared:
            raise GltfError(f"glTF buffer {i} declares {declared:,} bytes but holds {size:,}")
        lengths.append(declared)
    return lengths, held


def _check_views(views: list[dict], lengths: list[int]) -> None:
    """Every buffer view inside its buffer, its stride a valid one."""
    for i, view in enumerate(views):
        b = view.get("buffer")
        if isinstance(b, bool) or not isinstance(b, int) or not 0 <= b < len(lengths):
            raise GltfError(f"glTF bufferView {i}: buffer {b!r} does not exist")
        start = _count(view.get("byteOffset", 0), f"bufferView {i} byteOffset")
        length = _count(view.get("byteLength"), f"bufferView {i} byteLength")
        if start + length > lengths[b]:
            raise GltfError(
                f"glTF bufferView {i} runs past the end of buffer {b} "
                f"({start + length:,} of its {lengths[b]:,} bytes)"
            )
        stride = view.get("byteStride")
        if stride is not None and not (isinstance(stride, int) and 4 <= stride <= 252):
            raise GltfError(f"glTF bufferView {i} byteStride {stride!r} is not 4 to 252")


def _compressed_accessors(meshes: list[dict]) -> set[object]:
    """The accessors a compressed primitive fills (its attributes and indices)."""
    filled: set[object] = set()
    for mesh in meshes:
        for primitive in _primitives(mesh):
            extensions = primitive.get("extensions")
            if isinstance(extensions, dict) and DRACO in extensions:
                attributes = primitive.get("attributes")
                filled.update(attributes.values() if isinstance(attributes, dict) else ())
                filled.add(primitive.get("indices"))
    return filled


def _check_accessors(accessors: list[dict], views: list[dict], filled: set, max_values: int) -> int:
    """Every accessor's data inside its buffer view, or filled by a compressed primitive or
    sparse; each under the count cap; their values together under ``max_values``. Returns the
    values they declare."""
    values = 0
    for i, accessor in enumerate(accessors):
        count = _count(accessor.get("count"), f"accessor {i} count")
        if count > MAX_ACCESSOR_COUNT:
            raise GltfError(
                f"glTF accessor {i} declares {count:,} elements (at most {MAX_ACCESSOR_COUNT:,})"
            )
        kind, component = accessor.get("type"), accessor.get("componentType")
        if kind not in _COMPONENTS or component not in _COMPONENT_BYTES:
            raise GltfError(f"glTF accessor {i} has type {kind!r} of component {component!r}")
        values += count * _COMPONENTS[kind]
        element = _COMPONENTS[kind] * _COMPONENT_BYTES[component]
        if "bufferView" not in accessor:
            if i not in filled and "sparse" not in accessor and count:
                raise GltfError(
                    f"glTF accessor {i} declares {count:,} elements and has no bufferView to "
                    "hold them"
                )
            continue
        view = _index(accessor.get("bufferView"), views, f"accessor {i} bufferView")
        start = _count(accessor.get("byteOffset", 0), f"accessor {i} byteOffset")
        stride = view.get("byteStride") or element
        need = start + (stride * (count - 1) + element if count else 0)
        if need > view["byteLength"]:
            raise GltfError(
                f"glTF accessor {i} needs {need:,} bytes of its bufferView, which holds "
                f"{view['byteLength']:,}"
            )
    if values > max_values:
        raise GltfError(f"the glTF accessors declare {values:,} values (at most {max_values:,})")
    return values


def _instances(tree: dict, n_meshes: int) -> list[int]:
    """How many nodes show each mesh (at least 1: trimesh makes the meshes of every one)."""
    shown = [0] * n_meshes
    for node in _list(tree, "nodes"):
        m = node.get("mesh")
        if isinstance(m, int) and not isinstance(m, bool) and 0 <= m < n_meshes:
            shown[m] += 1
    return [max(1, n) for n in shown]


def _primitive_counts(primitive: dict, accessors: list[dict]) -> tuple[int, int]:
    """(triangles, vertices) a primitive declares (points and lines: no triangles)."""

    def count(index, what: str) -> int:
        return int(_index(index, accessors, f"primitive {what} accessor").get("count", 0))

    attributes = primitive.get("attributes")
    if not isinstance(attributes, dict) or "POSITION" not in attributes:
        raise GltfError("a glTF primitive has no POSITION attribute")
    n_vertices = count(attributes["POSITION"], "POSITION")
    n_corners = count(primitive["indices"], "indices") if "indices" in primitive else n_vertices
    mode = primitive.get("mode", _TRIANGLES)
    if mode == _TRIANGLES:
        return n_corners // 3, n_vertices
    if mode in (_STRIP, _FAN):
        return max(0, n_corners - 2), n_vertices
    return 0, n_vertices


def _check_totals(
    triangles: int, vertices: int, max_triangles: int, max_vertices: int, verb: str = "declare"
) -> None:
    if triangles > max_triangles:
        raise GltfError(
            f"the glTF meshes {verb} {triangles:,} triangles in all (at most {max_triangles:,})"
        )
    if vertices > max_vertices:
        raise GltfError(
            f"the glTF meshes {verb} {vertices:,} vertices in all (at most {max_vertices:,})"
        )


def inspect_gltf(
    data: bytes,
    binary_container: bool,
    folder: Path | None = None,
    *,
    max_triangles: int = MAX_TRIANGLES,
    max_vertices: int = MAX_VERTICES,
    max_values: int = MAX_ACCESSOR_VALUES,
) -> GltfInfo:
    """Check a glTF file against the caps and collect its Draco streams, before any array is
    made.

    Parameters
    ----------
    data : bytes
        The whole file.
    binary_container : bool
        True for a ``.glb``, False for a ``.gltf`` (JSON).
    folder : Path or None
        Where the buffers a ``.gltf`` names as files are read from; None: no file is read (an
        upload must be self-contained).
    max_triangles, max_vertices : int
        Triangles and vertices all primitives may declare together, each mesh counted once per
        node that shows it.
    max_values : int
        Scalar values all accessors may declare together.

    Raises
    ------
    GltfError
        A malformed container; an accessor, buffer view or buffer that does not exist, does not
        hold the bytes it needs or is over a cap; totals over the limits.
    """
    if binary_container:
        text, binary = _glb_chunks(data)
    else:
        text, binary = data, None
    tree = _tree(text)
    accessors = _list(tree, "accessors")
    views = _list(tree, "bufferViews")
    buffers = _list(tree, "buffers")
    meshes = _list(tree, "meshes")
    lengths, loaded = _buffer_lengths(buffers, binary, folder)
    _check_views(views, lengths)
    values = _check_accessors(accessors, views, _compressed_accessors(meshes), max_values)
    plain = [0, 0]
    draco = [0, 0]
    compressed, shown = [], []
    for mesh, instances in zip(meshes, _instances(tree, len(meshes)), strict=True):
        for primitive in _primitives(mesh):
            n_triangles, n_vertices = _primitive_counts(primitive, accessors)
            extensions = primitive.get("extensions")
            if isinstance(extensions, dict) and DRACO in extensions:
                compressed.append(extensions[DRACO])
                shown.append(instances)
                totals = draco
            else:
                totals = plain
            totals[0] += n_triangles * instances
            totals[1] += n_vertices * instances
    _check_totals(plain[0] + draco[0], plain[1] + draco[1], max_triangles, max_vertices)
    if len(compressed) > MAX_DRACO_PRIMITIVES:
        raise GltfError(
            f"{len(compressed)} Draco-compressed primitives (at most {MAX_DRACO_PRIMITIVES})"
        )
    streams, total = [], 0
    for extension in compressed:
        if not isinstance(extension, dict):
            raise GltfError(f"glTF {DRACO} is not an object")
        view = _index(extension.get("bufferView"), views, "Draco bufferView")
        b = view["buffer"]
        if b not in loaded:
            loaded[b] = _buffer_bytes(buffers[b], binary, folder, b)
        start, length = view.get("byteOffset", 0), view["byteLength"]
        total += length
        if total > MAX_DRACO_BYTES:
            raise GltfError(f"more than {MAX_DRACO_BYTES >> 20} MiB of Draco-compressed geometry")
        streams.append(bytes(loaded[b][start : start + length]))
    return GltfInfo(
        draco_streams=streams,
        n_accessor_values=values,
        n_triangles=plain[0] + draco[0],
        n_vertices=plain[1] + draco[1],
        draco_instances=shown,
        plain_triangles=plain[0],
        plain_vertices=plain[1],
    )


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


def check_gltf_file(
    data: bytes,
    binary_container: bool,
    folder: Path | None = None,
    *,
    max_triangles: int = MAX_TRIANGLES,
    max_vertices: int = MAX_VERTICES,
    max_values: int = MAX_ACCESSOR_VALUES,
) -> GltfInfo:
    """:func:`inspect_gltf`, then :func:`check_draco` on its streams, and the totals again with
    what the streams decode to: a glTF that passes is safe to hand to trimesh."""
    info = inspect_gltf(
        data,
        binary_container,
        folder,
        max_triangles=max_triangles,
        max_vertices=max_vertices,
        max_values=max_values,
    )
    decoded = check_draco(info.draco_streams)
    triangles, vertices = info.plain_triangles, info.plain_vertices
    for (n_points, n_faces), instances in zip(decoded, info.draco_instances, strict=True):
        triangles += n_faces * instances
        vertices += n_points * instances
    _check_totals(triangles, vertices, max_triangles, max_vertices, "decode to")
    return info
