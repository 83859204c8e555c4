"""Plain-text point files: XYZ / TXT / CSV / PTS / XYZC.

Columns (whitespace, tab or comma separated; ``#`` comments and blank lines ignored):

=========  ===============================================================
extension  columns
=========  ===============================================================
.xyz .txt  ``x y z`` | ``x y z label`` | ``x y z nx ny nz`` | ``x y z nx ny nz label``
.csv       same as .xyz, comma separated
.xyzc      ``x y z label`` (the ABC data set's labelled clouds)
.pts       optional first line with the count, then ``x y z`` | ``x y z intensity``
           | ``x y z r g b`` | ``x y z intensity r g b`` (Leica PTS)
=========  ===============================================================

Numbers go through numpy's C text parser (``np.loadtxt``) in one call per file; writing
formats whole blocks of rows with one ``%`` operation, not a Python loop per row.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ..errors import OptionError
from ._base import (
    InputError, Lines, Payload, check_declared, check_fits, clean_text, colors_to_uint8, integers, parse_table,
    read_bytes,
)

_BOM = b"\xef\xbb\xbf"
TEXT_EXTENSIONS = (".xyz", ".txt", ".csv", ".xyzc", ".pts", ".xyzn", ".asc")


def format_rows(columns, kinds, precision: int = 17, delimiter: str = " ") -> bytes:
    """Rows of text from equal-length columns: ``kinds`` has 'f' (float, ``%.{precision}g``) or
    'd' (integer) per column. 17 significant digits give float64 back exactly.

    Example:
        >>> format_rows([np.array([1.5, 2.0]), np.array([3, 4])], "fd")
        b'1.5 3\\n2 4\\n'
    """
    cols = [np.asarray(c) for c in columns]
    n = cols[0].shape[0] if cols else 0
    if n == 0:
        return b""
    line = delimiter.join(f"%.{precision}g" if k == "f" else "%d" for k in kinds) + "\n"
    table = np.empty((n, len(cols)), dtype=object) if any(k == "d" for k in kinds) else None
    chunks = []
    step = 100_000
    for s in range(0, n, step):
        if table is None:
            flat = np.column_stack([c[s: s + step] for c in cols]).astype(np.float64).ravel().tolist()
        else:
            parts = [c[s: s + step].astype(np.float64).tolist() if k == "f" else c[s: s + step].astype(np.int64).tolist()
                     for c, k in zip(cols, kinds)]
            flat = [v for row in zip(*parts) for v in row]
        rows = len(flat) // len(cols)
        chunks.append(((line * rows) % tuple(flat)).encode("ascii"))
    return b"".join(chunks)


def read_table(path: Path, *, skip_count_line: bool = False):
    """The numeric table of a text file: ``(rows, cols)`` float64 (``#`` comments, blank lines dropped).

    The file goes straight to numpy's C parser (``np.loadtxt`` on the path); only its head
    is looked at in Python, for binary junk and the delimiter.
    """
    size = path.stat().st_size
    # the parsed table takes at most ~3x the text (one float64 per number of >= 2 characters)
    check_fits(path, 3 * size, "the parsed numbers")
    with open(path, "rb") as handle:
        head = handle.read(1 << 16)
    if b"\x00" in head[:4096]:
        raise InputError(f"{path}: expected a text file of numbers, found binary data")
    if skip_count_line:
        return _read_table_with_count(path)
    if head.startswith(_BOM):  # Windows editors start UTF-8 text with a byte-order mark
        body = read_bytes(path)[len(_BOM):]
        table = parse_table(path, body, None, "point lines", delimiter="," if b"," in _first_line(body) else None,
                            comments="#")
        if table.size == 0:
            raise InputError(f"{path}: the file holds no data lines (only comments or blank lines)")
        return table
    first = clean_text(head).split(b"\n", 1)[0] if size > len(head) else None
    if first is None:  # small file: clean it all to find the first data line
        body = clean_text(head)
        if not body:
            raise InputError(f"{path}: the file holds no data lines (only comments or blank lines)")
        first = body.split(b"\n", 1)[0]
    delimiter = "," if b"," in first else None
    table = parse_table(path, path, None, "point lines", delimiter=delimiter, comments="#")
    if table.size == 0:
        raise InputError(f"{path}: the file holds no data lines (only comments or blank lines)")
    return table


def _first_line(body: bytes) -> bytes:
    """The first data line of raw text (comments and blank lines skipped)."""
    return clean_text(body[: 1 << 16]).split(b"\n", 1)[0]


def _read_table_with_count(path: Path):
    """PTS: an optional first line with the point count, checked against the lines that follow."""
    data = read_bytes(path)
    body = clean_text(data[len(_BOM):] if data.startswith(_BOM) else data)
    if not body:
        raise InputError(f"{path}: the file holds no data lines (only comments or blank lines)")
    lines = Lines(body)
    first = lines.line(0)
    start = 0
    if len(first.split()) == 1 and lines.count > 1:
        try:
            declared = int(first)
        except ValueError:
            raise InputError(f"{path}: first line {first[:40]!r} is neither a point count nor a point") from None
        check_declared(path, declared, 6, len(body), "points")
        start = 1
        if declared != lines.count - 1:
            raise InputError(
                f"{path}: first line declares {declared:,} points but {lines.count - 1:,} point lines follow"
            )
    delimiter = "," if b"," in lines.line(start) else None
    block = body[lines.start(start):] if start else body
    return parse_table(path, block, None, "point lines", first_line=start + 1, delimiter=delimiter)


def read_text_points(path: str | os.PathLike) -> Payload:
    """Points (and normals, labels, colours by column count) of a text point file.

    Example:
        >>> cloud = read_text_points("abc_00470.xyzc")  # doctest: +SKIP
        >>> cloud.labels.shape  # doctest: +SKIP
        (10000,)
    """
    path = Path(path)
    ext = path.suffix.lower()
    table = read_table(path, skip_count_line=(ext == ".pts"))
    cols = table.shape[1]
    normals = labels = colors = None
    if ext == ".pts":
        layouts = {3: "xyz", 4: "xyz i", 6: "xyz rgb", 7: "xyz i rgb"}
    elif ext == ".xyzc":
        layouts = {4: "xyz label"}
    else:
        layouts = {3: "xyz", 4: "xyz label", 6: "xyz normals", 7: "xyz normals label"}
    layout = layouts.get(cols)
    if layout is None:
        want = ", ".join(str(c) for c in layouts)
        raise InputError(f"{path}: {ext or 'text'} point lines need {want} columns, found {cols}")
    points = np.ascontiguousarray(table[:, :3])
    if "normals" in layout:
        normals = np.ascontiguousarray(table[:, 3:6])
    if "label" in layout:
        labels = integers(path, table[:, -1], "the label column")
    if "rgb" in layout:
        colors = colors_to_uint8(integers(path, table[:, -3:], "the colour columns"))
    return Payload(points, None, normals, colors, labels, info={"format": f"text ({layout})"})


def write_text_points(path, points, faces=None, normals=None, colors=None, labels=None, *,
                      precision: int = 17) -> list[str]:
    """Write a text point file by extension (see the module table); returns attributes left out."""
    path = Path(path)
    ext = path.suffix.lower()
    cols, kinds, left_out = [points[:, 0], points[:, 1], points[:, 2]], "fff", []
    head = b""
    delimiter = "," if ext == ".csv" else " "
    if ext == ".xyzc":
        if labels is None:
            raise OptionError(f"{path}: .xyzc needs a label per point; none were given")
        cols.append(labels)
        kinds += "d"
        left_out = [n for n, v in (("normals", normals), ("colors", colors)) if v is not None]
    elif ext == ".pts":
        head = f"{points.shape[0]}\n".encode()
        if colors is not None:
            cols += [colors[:, 0], colors[:, 1], colors[:, 2]]
            kinds += "ddd"
        left_out = [n for n, v in (("normals", normals), ("labels", labels)) if v is not None]
        if colors is not None and colors.shape[1] == 4:
            left_out.append("alpha")
    else:
        if normals is not None:
            cols += [normals[:, 0], normals[:, 1], normals[:, 2]]
            kinds += "fff"
        if labels is not None:
            cols.append(labels)
            kinds += "d"
        if colors is not None:
            left_out.append("colors")
    with atomic_open(path, "wb") as handle:
        handle.write(head)
        handle.write(format_rows(cols, kinds, precision, delimiter))
    return (["faces"] if faces is not None else []) + left_out
