"""OFF and its variants: OFF, NOFF (normals), COFF (colours), CNOFF, STOFF (texture) and 4OFF/nOFF.

Layout: a keyword line (``[ST][C][N][4][n]OFF``), then ``V F E`` (which may sit on the
keyword line itself, as in the thesis's ``luigi.off``), then V vertex lines
``x y z [nx ny nz] [r g b [a]] [s t]`` and F face lines ``k i_1 .. i_k [colour]``.
``#`` comments and blank lines are allowed anywhere. Faces are fan-triangulated.

Reference: the Geomview OFF description (geomview.org/docs/html/OFF.html).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ._base import (
    InputError, Lines, Payload, check_declared, check_faces, clean_text, colors_to_uint8,
    fan_triangulate, integers, parse_table, read_bytes,
)
from .text import format_rows

_KEYWORD = re.compile(rb"^(ST)?(C)?(N)?(4)?(n)?OFF$")


def read_off(path: str | os.PathLike) -> Payload:
    """Vertices (with normals or colours when the keyword says so) and triangles of an OFF file.

    Example:
        >>> mesh = read_off("cat.off")  # NOFF: 366 vertices, 698 faces  # doctest: +SKIP
    """
    path = Path(path)
    data = read_bytes(path)
    if b"\x00" in data[:4096]:
        raise InputError(f"{path}: expected OFF text, found binary data (binary OFF is not supported)")
    body = clean_text(data)
    if not body:
        raise InputError(f"{path}: the file holds no data lines")
    lines = Lines(body)
    words = lines.line(0).split()
    m = _KEYWORD.match(words[0]) if words else None
    if not m:
        raise InputError(f"{path}: expected an OFF keyword (OFF, NOFF, COFF, ...) on the first line, "
                         f"found {lines.line(0)[:40]!r}")
    st, has_color, has_normal, four, ndim = (g is not None for g in m.groups())
    if four or ndim:
        raise InputError(f"{path}: {words[0].decode()} (4-D or n-D vertices) is not supported; expected 3-D OFF")
    counts = words[1:]
    row = 1
    if not counts:
        if lines.count < 2:
            raise InputError(f"{path}: the OFF header has no vertex and face counts")
        counts = lines.line(1).split()
        row = 2
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        raise InputError(f"{path}: expected 'V F E' counts after {words[0].decode()}, found {b' '.join(counts)[:40]!r}") from None
    check_declared(path, nv, 6, len(body), "vertices")
    check_declared(path, nf, 6, len(body), "faces")
    if lines.count - row < nv + nf:
        raise InputError(
            f"{path}: header declares {nv:,} vertices and {nf:,} faces but only "
            f"{lines.count - row:,} data lines follow"
        )
    table = parse_table(path, lines.block(row, nv), nv, "vertex lines", first_line=row + 1)
    if nv and table.shape[1] < 3:
        raise InputError(f"{path}: vertex lines need at least 3 numbers, found {table.shape[1]}")
    if nv == 0:
        table = np.zeros((0, 3))
    points = np.ascontiguousarray(table[:, :3])
    col = 3
    normals = colors = None
    if has_normal:
        if table.shape[1] < 6:
            raise InputError(f"{path}: NOFF vertex lines need 6 numbers (x y z nx ny nz), found {table.shape[1]}")
        normals = np.ascontiguousarray(table[:, 3:6])
        col = 6
    if has_color:
        k = table.shape[1] - col - (2 if st else 0)
        if k not in (3, 4):
            raise InputError(f"{path}: COFF vertex lines need 3 or 4 colour values after the coordinates")
        # Geomview allows integers 0..255 or floats 0..1; colors_to_uint8 tells them apart by range
        colors = colors_to_uint8(table[:, col: col + k], path)
    faces = _read_faces(path, lines, row + nv, nf)
    extra = lines.count - row - nv - nf
    if extra > 0:
        raise InputError(
            f"{path}: header declares {nv:,} vertices and {nf:,} faces but {extra:,} more data lines follow"
        )
    check_faces(path, faces, nv)
    return Payload(points, faces, normals, colors, info={"format": words[0].decode()})


def _read_faces(path: Path, lines: Lines, row: int, nf: int) -> np.ndarray:
    if nf == 0:
        return np.zeros((0, 3), np.int64)
    block = lines.block(row, nf)
    try:
        table = parse_table(path, block, nf, "face lines", first_line=row + 1)
    except InputError:
        table = None  # ragged: polygons of several sizes, or colours on some faces
    if table is not None:
        k = integers(path, table[:, 0], "face sizes (the first number of a face line)")
        size = int(k[0])
        if np.all(k == size) and table.shape[1] >= size + 1 and size >= 1:
            idx = integers(path, table[:, 1: size + 1], "vertex indices of the faces")
            return idx if size == 3 else fan_triangulate(np.full(nf, size), idx.ravel())
    counts, flat = [], []
    for i, raw in enumerate(block.split(b"\n")[:nf]):
        words = raw.split()
        try:
            k = int(words[0])
            idx = [int(w) for w in words[1: k + 1]] if k >= 0 else []
        except (IndexError, ValueError):
            raise InputError(f"{path}: face line {row + i + 1} is not 'k i_1 .. i_k': {raw[:60]!r}") from None
        if len(idx) != k:
            raise InputError(f"{path}: face line {row + i + 1} declares {k} corners but has {len(idx)}")
        if idx and (min(idx) < -(2**63) or max(idx) >= 2**63):
            raise InputError(f"{path}: face line {row + i + 1} refers to a vertex beyond any file's size")
        counts.append(k)
        flat.extend(idx)
    return fan_triangulate(np.array(counts, dtype=np.int64), np.array(flat, dtype=np.int64))


def write_off(path, points, faces=None, normals=None, colors=None, labels=None, *, precision: int = 17) -> list[str]:
    """Write OFF (NOFF when normals are given, COFF/CNOFF with colours), atomically.

    Returns the attributes the format could not store (labels are not part of OFF).
    """
    keyword = ("C" if colors is not None else "") + ("N" if normals is not None else "") + "OFF"
    nf = 0 if faces is None else faces.shape[0]
    cols, kinds = [points[:, 0], points[:, 1], points[:, 2]], "fff"
    if normals is not None:
        cols += [normals[:, i] for i in range(3)]
        kinds += "fff"
    if colors is not None:
        cols += [colors[:, i] for i in range(colors.shape[1])]
        kinds += "d" * colors.shape[1]
    with atomic_open(path, "wb") as handle:
        handle.write(f"{keyword}\n{points.shape[0]} {nf} 0\n".encode())
        handle.write(format_rows(cols, kinds, precision))
        if nf:
            handle.write(format_rows([np.full(nf, 3), faces[:, 0], faces[:, 1], faces[:, 2]], "dddd"))
    return ["labels"] if labels is not None else []
