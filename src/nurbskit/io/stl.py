"""STL, ASCII and binary.

Binary: an 80-byte header, a uint32 triangle count, then per triangle 12 float32
(normal, three corners) and a uint16 attribute: one structured ``np.frombuffer``.
STL repeats each corner per triangle; the reader merges corners with equal coordinates
(exactly equal, as trimesh does by default) to give an indexed mesh.
A file is binary when its size is exactly ``84 + 50 * count``; otherwise a file
starting with ``solid`` is read as ASCII.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ..errors import OptionError
from ._base import InputError, Payload, check_declared, parse_table, read_bytes
from .text import format_rows

_DTYPE = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attr", "<u2")])
_VERTEX = re.compile(rb"^[ \t]*vertex[ \t]+([^\n]*)$", re.MULTILINE)


def merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique vertices ``(V, 3)`` and faces ``(F, 3)`` from triangle corners ``(F, 3, 3)``.

    Vertices keep the order of their first appearance.
    """
    flat = np.ascontiguousarray(corners.reshape(-1, 3).astype(np.float64))
    flat = flat + 0.0  # -0.0 and 0.0 are the same point
    _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    vertices = flat[first[order]]
    faces = rank[inverse.reshape(-1)].reshape(-1, 3).astype(np.int64)
    return vertices, faces


def read_stl(path: str | os.PathLike) -> Payload:
    """Vertices (merged) and triangles of an ASCII or binary STL file."""
    path = Path(path)
    data = read_bytes(path)
    binary = len(data) >= 84 and len(data) == 84 + 50 * int(np.frombuffer(data, "<u4", 1, 80)[0])
    if not binary and data.lstrip()[:5].lower() == b"solid":
        if b"\x00" in data[:4096]:
            raise InputError(f"{path}: STL starts with 'solid' but holds binary data of the wrong size")
        return _read_ascii(path, data)
    if len(data) < 84:
        raise InputError(f"{path}: a binary STL needs at least 84 bytes, the file has {len(data)}")
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    check_declared(path, n, 50, len(data) - 84, "triangles")
    if not binary:
        raise InputError(
            f"{path}: binary STL header declares {n:,} triangles ({84 + 50 * n:,} bytes) but the file has "
            f"{len(data):,} bytes"
        )
    if n == 0:
        raise InputError(f"{path}: the binary STL holds 0 triangles; expected a mesh, found an empty one")
    rec = np.frombuffer(data, _DTYPE, n, 84)
    vertices, faces = merge_corners(rec["corners"])
    return Payload(vertices, faces, info={"format": "stl binary", "triangles": n})


def _read_ascii(path: Path, data: bytes) -> Payload:
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n")
    rows = _VERTEX.findall(data)
    nfacet = len(re.findall(rb"^\s*facet\b", data, re.MULTILINE))
    if not rows and nfacet == 0:
        raise InputError(f"{path}: ASCII STL has no 'facet' / 'vertex' lines")
    if len(rows) != 3 * nfacet:
        raise InputError(f"{path}: ASCII STL has {nfacet} facets but {len(rows)} vertex lines (expected 3 per facet)")
    table = parse_table(path, b"\n".join(rows) + b"\n", len(rows), "vertex lines")
    if table.shape[1] != 3:
        raise InputError(f"{path}: STL vertex lines need 3 numbers, found {table.shape[1]}")
    vertices, faces = merge_corners(table.reshape(-1, 3, 3))
    return Payload(vertices, faces, info={"format": "stl ascii", "triangles": nfacet})


def write_stl(path, vertices, faces, normals=None, colors=None, labels=None, *, binary: bool = True) -> list[str]:
    """Write STL (binary by default), with facet normals from the corner order, atomically.

    STL stores float32: coordinates come back to float32 precision, and a coordinate
    beyond float32's range is refused (it would become ``inf``). Per-vertex normals,
    colours and labels are not part of STL: their names are returned.
    """
    big = float(np.abs(vertices).max()) if vertices.size else 0.0
    if big > float(np.finfo(np.float32).max):
        raise OptionError(f"{path}: a coordinate ({big:.3g}) is beyond float32's range, the only type STL has; "
                          "write .ply or .obj instead")
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    with atomic_open(path, "wb") as handle:
        if binary:
            rec = np.zeros(faces.shape[0], _DTYPE)
            rec["normal"] = normal
            rec["corners"] = tri
            head = b"binary STL written by nurbskit".ljust(80, b" ")
            handle.write(head + np.uint32(faces.shape[0]).tobytes() + rec.tobytes())
        else:
            handle.write(b"solid nurbskit\n")
            t = tri.astype(np.float32).astype(np.float64)
            cols = []
            for c in range(3):
                cols += [normal[:, c]]
            for k in range(3):
                cols += [t[:, k, 0], t[:, k, 1], t[:, k, 2]]
            rows = format_rows(cols, "f" * 12, 17)  # the float32 values, exactly
            out = []
            for line in rows.split(b"\n")[:-1]:
                v = line.split(b" ")
                out.append(b"facet normal %s %s %s\n outer loop\n  vertex %s %s %s\n  vertex %s %s %s\n"
                           b"  vertex %s %s %s\n endloop\nendfacet\n" % tuple(v))
            handle.write(b"".join(out))
            handle.write(b"endsolid nurbskit\n")
    return [n for n, v in (("normals", normals), ("colors", colors), ("labels", labels)) if v is not None]
