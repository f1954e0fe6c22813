"""Decode Draco streams under resource limits (run as a child process by ``simcore.gltf``).

    python -I _draco_probe.py MEMORY_BYTES CPU_S MAX_POINTS MAX_FACES < framed streams

Sets its own address-space and CPU-time limits before importing the decoder, reads the streams
(a little-endian uint64 count, then each stream as a uint64 length and its bytes) and writes one
JSON line per stream: ``{"points": n, "faces": m}`` or ``{"error": "..."}``. Standalone on
purpose: it imports nothing of simcore, only DracoPy and numpy.
"""

import json
import resource
import struct
import sys


def _limit(memory_bytes: int, cpu_s: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_s, cpu_s + 5))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _streams(raw: bytes) -> list[bytes]:
    (n,) = struct.unpack_from("<Q", raw, 0)
    offset, out = 8, []
    for _ in range(n):
        (size,) = struct.unpack_from("<Q", raw, offset)
        out.append(raw[offset + 8 : offset + 8 + size])
        offset += 8 + size
    return out


def _decode(stream: bytes, max_points: int, max_faces: int) -> dict:
    import DracoPy  # noqa: PLC0415  (after the limits are set)

    try:
        mesh = DracoPy.decode(stream)
    except MemoryError:
        return {"error": "the decoder ran out of memory"}
    except Exception as exc:  # DracoPy raises ValueError, FileTypeException, ...
        return {"error": f"{type(exc).__name__}: {str(exc)[:200]}"}
    faces = getattr(mesh, "faces", None)
    points = getattr(mesh, "points", None)
    if faces is None or points is None or len(faces) == 0:
        return {"error": "it holds no triangles (a point cloud or an empty mesh)"}
    if len(points) > max_points or len(faces) > max_faces:
        return {"error": f"{len(points):,} points, {len(faces):,} triangles: over the caps"}
    if points.ndim != 2 or points.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        return {"error": f"unexpected shapes {points.shape}, {faces.shape}"}
    if int(faces.max()) >= len(points) or int(faces.min()) < 0:
        return {"error": "a triangle refers to a point that does not exist"}
    return {"points": len(points), "faces": len(faces)}


def main() -> int:
    memory_bytes, cpu_s, max_points, max_faces = (int(a) for a in sys.argv[1:5])
    _limit(memory_bytes, cpu_s)
    for stream in _streams(sys.stdin.buffer.read()):
        sys.stdout.write(json.dumps(_decode(stream, max_points, max_faces)) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
