"""Wavefront OBJ: vertices (``v x y z [r g b]``), normals (``vn``), faces (``f``).

Faces may use ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` references, 1-based, and negative
(relative to the vertices defined so far). Polygons are fan-triangulated. Per-vertex
normals come from the ``v//vn`` references of the faces, or, in a file without faces
that has as many ``vn`` as ``v`` lines (MeshLab's point-cloud export), one per vertex
in order. Groups, materials, texture coordinates, lines and curves are skipped.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ._base import InputError, Payload, check_faces, colors_to_uint8, fan_triangulate, parse_table, read_bytes
from .text import format_rows

_KNOWN = (b"v", b"vn", b"vt", b"vp", b"f", b"l", b"p", b"g", b"o", b"s", b"mtllib", b"usemtl",
          b"cstype", b"deg", b"curv", b"curv2", b"surf", b"parm", b"end", b"bmat", b"step", b"trim", b"hole",
          b"con", b"sp", b"mg", b"lod", b"ctech", b"stech", b"bevel", b"c_interp", b"d_interp", b"call",
          b"shadow_obj", b"trace_obj", b"maplib", b"usemap")
_UNKNOWN = re.compile(rb"^[ \t]*(?!(?:" + b"|".join(_KNOWN) + rb")(?:[ \t]|$)|#|$)[^\n]*", re.MULTILINE)
_ROWS = {k: re.compile(rb"^[ \t]*" + k + rb"[ \t]+([^\n]*)", re.MULTILINE) for k in (b"v", b"vn", b"f")}


def _numbers(path, lines: list[bytes], what: str) -> np.ndarray:
    block = b"\n".join(lines) + b"\n"
    return parse_table(path, block, len(lines), what)


def read_obj(path: str | os.PathLike) -> Payload:
    """Vertices, triangles and per-vertex normals / colours of an OBJ file.

    Lines are picked out by regular expressions over the whole text (no Python loop per line).

    Example:
        >>> payload = read_obj("spot.obj")  # doctest: +SKIP
    """
    path = Path(path)
    data = read_bytes(path)
    if b"\x00" in data[:4096]:
        raise InputError(f"{path}: expected OBJ text, found binary data")
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if b"\\\n" in data:  # line continuations
        data = data.replace(b"\\\n", b" ")
    bad = _UNKNOWN.search(data)
    if bad:
        lineno = data.count(b"\n", 0, bad.start()) + 1
        raise InputError(f"{path}: line {lineno} is not OBJ: {bad.group(0)[:60]!r}")
    v_lines = _ROWS[b"v"].findall(data)
    vn_lines = _ROWS[b"vn"].findall(data)
    f_lines = _ROWS[b"f"].findall(data)
    if not v_lines:
        raise InputError(f"{path}: the OBJ file has no vertex ('v') lines")
    table = _numbers(path, v_lines, "vertex ('v') lines")
    if table.shape[1] not in (3, 4, 6, 7):
        raise InputError(f"{path}: 'v' lines need 3 (x y z), 4 (x y z w) or 6 (x y z r g b) numbers, found {table.shape[1]}")
    nv = table.shape[0]
    points = np.ascontiguousarray(table[:, :3])
    colors = colors_to_uint8(table[:, 3:6], path) if table.shape[1] in (6, 7) else None
    vn = _numbers(path, vn_lines, "normal ('vn') lines") if vn_lines else None
    if vn is not None and vn.shape[1] != 3:
        raise InputError(f"{path}: 'vn' lines need 3 numbers, found {vn.shape[1]}")
    faces, normals = _faces(path, data, f_lines, nv, vn)
    if normals is None and vn is not None and not f_lines and vn.shape[0] == nv:
        normals = vn
    check_faces(path, faces, nv)
    return Payload(points, faces if f_lines else None, normals, colors, info={"format": "obj"})


def _ints(path, block: bytes, what: str) -> np.ndarray:
    tokens = block.split()
    try:
        return np.array(tokens, dtype=np.int64) if tokens else np.zeros(0, np.int64)
    except OverflowError:
        bad = next(t for t in tokens if t.lstrip(b"-").isdigit() and abs(int(t)) >= 2**63)
        raise InputError(f"{path}: a face ('f') line has a {what} beyond any file's size: {bad[:30]!r}") from None
    except ValueError:
        bad = next(t for t in tokens if not t.lstrip(b"-").isdigit())
        raise InputError(f"{path}: a face ('f') line has a {what} that is not an integer: {bad[:30]!r}") from None


def _faces(path, data, f_lines, nv, vn):
    if not f_lines:
        return np.zeros((0, 3), np.int64), None
    block = b"\n".join(f_lines)
    # corners per line: count token starts between line breaks (vectorised, no per-line split)
    chars = np.frombuffer(block + b"\n", np.uint8)
    blank = (chars == 32) | (chars == 9) | (chars == 10) | (chars == 13)
    starts = ~blank & np.concatenate([[True], blank[:-1]])
    line_starts = np.concatenate([[0], np.flatnonzero(chars == 10)[:-1] + 1])
    counts = np.add.reduceat(starts.astype(np.int64), line_starts)
    has_refs = b"/" in block
    v_idx = _ints(path, re.sub(rb"/\S*", b"", block) if has_refs else block, "vertex reference")
    if v_idx.size != counts.sum():
        raise InputError(f"{path}: face ('f') lines are malformed")
    if np.any(v_idx == 0):
        raise InputError(f"{path}: a face refers to vertex 0; OBJ indices start at 1")
    written = v_idx
    before = None
    if np.any(v_idx < 0):
        # negative references count back from the vertices defined before that face line
        v_pos = np.array([m.start() for m in _ROWS[b"v"].finditer(data)], dtype=np.int64)
        before = np.repeat(np.searchsorted(v_pos, _face_positions(data)), counts)
        v_idx = np.where(v_idx < 0, before + v_idx, v_idx - 1)
    else:
        v_idx = v_idx - 1
    outside = (v_idx < 0) | (v_idx >= nv)
    if outside.any():
        corner = int(np.flatnonzero(outside)[0])
        line = int(np.searchsorted(np.cumsum(counts), corner, side="right"))
        lineno = data.count(b"\n", 0, int(_face_positions(data)[line])) + 1
        ref = int(written[corner])
        have = f"only {int(before[corner])} vertices come before it" if ref < 0 else f"the file has {nv} vertices"
        raise InputError(f"{path}: line {lineno}: a face refers to vertex {ref}, but {have}")
    tri = fan_triangulate(counts, v_idx)
    normals = None
    if has_refs and vn is not None:
        n_tok = re.findall(rb"(?:^|[ \n])-?\d+/-?\d*/(-?\d+)", block)
        if len(n_tok) == v_idx.size:
            n_idx = _ints(path, b" ".join(n_tok), "normal reference")
            n_idx = np.where(n_idx < 0, vn.shape[0] + n_idx, n_idx - 1)
            if n_idx.min() >= 0 and n_idx.max() < vn.shape[0] and v_idx.min() >= 0 and v_idx.max() < nv:
                seen = np.zeros(nv, bool)
                seen[v_idx] = True
                if seen.all():
                    normals = np.zeros((nv, 3))
                    normals[v_idx] = vn[n_idx]
    return tri, normals


def _face_positions(data: bytes) -> np.ndarray:
    """Byte offsets of the face ('f') lines."""
    return np.array([m.start() for m in _ROWS[b"f"].finditer(data)], dtype=np.int64)


def write_obj(path, points, faces=None, normals=None, colors=None, labels=None, *, precision: int = 17) -> list[str]:
    """Write OBJ (``v``, ``vn`` one per vertex, ``f a//a b//b c//c`` when normals exist), atomically."""
    cols, kinds = [points[:, 0], points[:, 1], points[:, 2]], "fff"
    if colors is not None:
        cols += [colors[:, i].astype(np.float64) / 255.0 for i in range(3)]
        kinds += "fff"
    with atomic_open(path, "wb") as handle:
        handle.write(b"# written by nurbskit\n")
        handle.write(_prefixed(b"v ", format_rows(cols, kinds, precision)))
        if normals is not None:
            handle.write(_prefixed(b"vn ", format_rows([normals[:, i] for i in range(3)], "fff", precision)))
        if faces is not None and faces.shape[0]:
            f = faces + 1
            if normals is not None:
                rows = format_rows([f[:, 0], f[:, 0], f[:, 1], f[:, 1], f[:, 2], f[:, 2]], "dddddd")
                rows = re.sub(rb"(\d+) (\d+) (\d+) (\d+) (\d+) (\d+)", rb"\1//\2 \3//\4 \5//\6", rows)
            else:
                rows = format_rows([f[:, 0], f[:, 1], f[:, 2]], "ddd")
            handle.write(_prefixed(b"f ", rows))
    left = ["alpha"] if colors is not None and colors.shape[1] == 4 else []
    return left + (["labels"] if labels is not None else [])


def _prefixed(prefix: bytes, rows: bytes) -> bytes:
    if not rows:
        return b""
    return prefix + rows[:-1].replace(b"\n", b"\n" + prefix) + b"\n"
