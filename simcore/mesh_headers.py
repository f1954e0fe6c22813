"""What an OBJ, PLY or STL file declares, read from its bytes before trimesh parses it.

trimesh sizes its arrays by what a file says: a PLY's ``element`` counts, a binary STL's triangle
count, an OBJ's lines. :func:`declared_counts` reads those figures (and checks that a binary
file holds the bytes its header promises) so that a caller can refuse a file over its limits
before any array is made:

- STL: a binary file's header count (its length must be exactly 84 + 50 bytes per triangle); an
  ASCII file's ``endfacet`` lines;
- PLY: the header's ``element vertex`` and ``element face`` counts (a polygon counts as at least
  one triangle); every element's rows must fit in the bytes after the header (binary: the fixed
  size of a row, a face's list counted as a triangle, other lists as empty; ASCII: two
  characters a value);
- OBJ: the ``v`` lines, and the triangles of the ``f`` lines (a polygon of n corners makes n - 2).

Only the standard library is used.
"""

from __future__ import annotations

import re
import struct

MAX_PLY_HEADER_BYTES = 64 * 1024  # [byte] a PLY header longer than this is refused
_PLY_TYPES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}  # fmt: skip
# an OBJ face line's corners from the third on: one triangle each
_OBJ_FACE = re.compile(rb"^[ \t]*f[ \t]+\S+[ \t]+\S+[ \t]+(\S[^\r\n]*)", re.MULTILINE)
_OBJ_VERTEX = re.compile(rb"^[ \t]*v[ \t]", re.MULTILINE)


class MeshHeaderError(ValueError):
    """A file's header is malformed or promises more than the file holds (no file named)."""


def declared_counts(data: bytes, kind: str) -> tuple[int, int]:
    """The triangles and vertices a mesh file declares.

    Parameters
    ----------
    data : bytes
        The whole file.
    kind : str
        ``"obj"``, ``"ply"`` or ``"stl"`` (other kinds: (0, 0), nothing read).

    Returns
    -------
    (n_triangles, n_vertices) : tuple of int
        Lower bounds of what trimesh will make of the file (exact for STL and OBJ triangles).

    Raises
    ------
    MeshHeaderError
        A malformed PLY header, or a binary file shorter than its header says.
    """
    if kind == "stl":
        return _stl_counts(data)
    if kind == "ply":
        return _ply_counts(data)
    if kind == "obj":
        return _obj_counts(data)
    return 0, 0


def _stl_counts(data: bytes) -> tuple[int, int]:
    if len(data) >= 84:
        (n,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * n == len(data):
            return n, 3 * n
    if data.lstrip()[:5].lower() == b"solid":
        n = data.count(b"endfacet")
        return n, 3 * n
    raise MeshHeaderError(
        "a binary STL must be 84 bytes plus 50 a triangle: this one's length does not match "
        "the triangle count in its header"
    )


def _ply_counts(data: bytes) -> tuple[int, int]:
    end = data.find(b"end_header", 0, MAX_PLY_HEADER_BYTES)
    if not data.startswith(b"ply") or end < 0:
        raise MeshHeaderError(
            f"not a PLY file (no 'ply' ... 'end_header' in its first {MAX_PLY_HEADER_BYTES} bytes)"
        )
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    body = len(data) - data.find(b"\n", end) - 1
    is_ascii = any(line.split()[:2] == ["format", "ascii"] for line in lines)
    elements: list[list] = []  # [name, count, fixed bytes of a row, values of a row]
    for number, line in enumerate(lines, 1):
        words = line.split()
        if words[:1] == ["element"]:
            if len(words) != 3 or not words[2].isdigit():
                raise MeshHeaderError(f"PLY header line {number} is not 'element NAME COUNT'")
            elements.append([words[1], int(words[2]), 0, 0])
        elif words[:1] == ["property"] and elements:
            corners = 3 if elements[-1][0] == "face" else 0  # a face: a triangle at least
            elements[-1][2] += _ply_property_bytes(words, number, corners)
            elements[-1][3] += 1 + (corners if words[1:2] == ["list"] else 0)
    need = sum(count * (2 * values if is_ascii else size) for _, count, size, values in elements)
    if need > body:
        raise MeshHeaderError(
            f"the PLY header declares {' and '.join(f'{c:,} {n!r}' for n, c, _, _ in elements)}"
            f" rows, at least {need:,} bytes of data; the file holds {max(body, 0):,}"
        )
    counts = {name: count for name, count, _, _ in elements}
    return counts.get("face", 0), counts.get("vertex", 0)


def _ply_property_bytes(words: list[str], number: int, corners: int) -> int:
    """The fewest bytes a binary row spends on one property (a list: its length and
    ``corners`` values)."""
    try:
        if words[1] == "list":
            return _PLY_TYPES[words[2]] + corners * _PLY_TYPES[words[3]]
        return _PLY_TYPES[words[1]]
    except (IndexError, KeyError):
        raise MeshHeaderError(f"PLY header line {number} is not a known property") from None


_OBJ_CHUNK_BYTES = 1 << 20  # read in pieces of about this size, cut at line ends


def _obj_counts(data: bytes) -> tuple[int, int]:
    """Counted a piece at a time (the matches of one piece only are held: a 4 M-face file's
    lines all at once would be some 250 MB of small objects)."""
    triangles = vertices = 0
    start = 0
    while start < len(data):
        end = data.find(b"\n", start + _OBJ_CHUNK_BYTES)
        end = len(data) if end < 0 else end + 1
        piece = data[start:end]
        triangles += len(b" ".join(_OBJ_FACE.findall(piece)).split())
        vertices += sum(1 for _ in _OBJ_VERTEX.finditer(piece))
        start = end
    return triangles, vertices
