"""PLY (Stanford polygon format): ASCII, binary little and big endian.

Reads any property order and extra properties, ``float`` or ``double`` coordinates,
faces of any size (fan-triangulated) and triangle strips (``tristrips`` with restart
index -1, which Open3D drops). Binary bodies are read with numpy structured dtypes in
one ``np.frombuffer`` per element; lists of one length (the usual triangles) are a fixed
field, other lists fall back to a record walk.

Reference: Greg Turk, "The PLY Polygon File Format" (1994).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ..errors import OptionError
from ._base import (
    InputError, Lines, Payload, check_declared, check_faces, check_fits, clean_text,
    colors_to_uint8, columns_to_float64, fan_triangulate, integers, parse_table, read_bytes,
)

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}

NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
COLOR_NAMES = (("red", "green", "blue", "alpha"), ("r", "g", "b", "a"),
               ("diffuse_red", "diffuse_green", "diffuse_blue", "diffuse_alpha"))
LABEL_NAMES = ("label", "labels", "class", "segment", "segment_id", "scalar_label", "instance")


class _Element:
    def __init__(self, name: str, count: int):
        self.name = name
        self.count = count
        self.props: list[tuple] = []  # (name, type) or (name, "list", count_type, item_type)

    @property
    def has_list(self) -> bool:
        return any(len(p) == 4 for p in self.props)


def _parse_header(path: Path, data: bytes) -> tuple[str, list[_Element], int]:
    end = data.find(b"end_header")
    if end < 0:
        raise InputError(f"{path}: PLY header has no 'end_header' line")
    nl = data.find(b"\n", end)
    body_start = len(data) if nl < 0 else nl + 1
    try:
        header = data[:end].decode("ascii")
    except UnicodeDecodeError:
        raise InputError(f"{path}: PLY header is not ASCII text") from None
    fmt = None
    elements: list[_Element] = []
    for lineno, raw in enumerate(header.splitlines(), start=1):
        words = raw.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        where = f"{path}: PLY header line {lineno} ({raw.strip()!r})"
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _FORMATS:
                raise InputError(f"{where}: format must be one of {sorted(_FORMATS)}")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3:
                raise InputError(f"{where}: expected 'element NAME COUNT'")
            try:
                count = int(words[2])
            except ValueError:
                raise InputError(f"{where}: element count is not an integer") from None
            if count < 0:
                raise InputError(f"{where}: element count is negative")
            elements.append(_Element(words[1], count))
        elif words[0] == "property":
            if not elements:
                raise InputError(f"{where}: property before any element")
            if len(words) == 5 and words[1] == "list":
                if words[2] not in _TYPES or words[3] not in _TYPES:
                    raise InputError(f"{where}: unknown list types {words[2]!r}, {words[3]!r}")
                if _TYPES[words[2]][0] == "f":
                    raise InputError(f"{where}: a list's count type must be an integer type, not {words[2]}")
                prop = (words[4], "list", _TYPES[words[2]], _TYPES[words[3]])
            elif len(words) == 3 and words[1] in _TYPES:
                prop = (words[2], _TYPES[words[1]])
            else:
                raise InputError(f"{where}: expected 'property TYPE NAME' or 'property list CTYPE ITYPE NAME'")
            if any(p[0] == prop[0] for p in elements[-1].props):
                raise InputError(f"{where}: property {prop[0]!r} is declared twice in element {elements[-1].name!r}")
            elements[-1].props.append(prop)
        else:
            raise InputError(f"{where}: unknown header keyword {words[0]!r}")
    if fmt is None:
        raise InputError(f"{path}: PLY header has no 'format' line")
    return fmt, elements, body_start


# ---- binary ------------------------------------------------------------------------

def _read_binary_element(path, data, pos, el: _Element, order: str):
    """Returns (structured array or dict of lists, new position)."""
    remaining = len(data) - pos
    if not el.has_list:
        dtype = np.dtype([(n, order + t) for n, t in el.props]) if el.props else np.dtype([])
        check_declared(path, el.count, dtype.itemsize, remaining, f"'{el.name}' records")
        arr = np.frombuffer(data, dtype=dtype, count=el.count, offset=pos) if dtype.itemsize else np.zeros(el.count, dtype)
        return arr, pos + el.count * dtype.itemsize
    if el.count == 0:
        return {}, pos
    # Guess every list has the length of the first record's, read in one go, verify.
    fields, off, fixed_ok = [], pos, True
    for prop in el.props:
        if len(prop) == 2:
            fields.append((prop[0], order + prop[1]))
            off += np.dtype(prop[1]).itemsize
        else:
            ctype, itype = np.dtype(order + prop[2]), np.dtype(order + prop[3])
            if off + ctype.itemsize > len(data):
                raise InputError(f"{path}: binary PLY is truncated inside the first '{el.name}' record")
            n = int(np.frombuffer(data, ctype, 1, off)[0])
            if n < 0 or off + ctype.itemsize + n * itype.itemsize > len(data):
                fixed_ok = False  # a bad count: the record walk below says where
                break
            fields.append(("__count_" + prop[0], ctype))
            fields.append((prop[0], itype, (n,)) if n else (prop[0], itype, (0,)))
            off += ctype.itemsize + n * itype.itemsize
    # A lower bound for the whole element: every list has at least its count field.
    min_item = sum(np.dtype(order + (p[1] if len(p) == 2 else p[2])).itemsize for p in el.props)
    check_declared(path, el.count, min_item, remaining, f"'{el.name}' records")
    dtype = np.dtype(fields) if fixed_ok else None
    if fixed_ok and el.count * dtype.itemsize <= remaining:
        arr = np.frombuffer(data, dtype=dtype, count=el.count, offset=pos)
        for prop in el.props:
            if len(prop) == 4 and not np.all(arr["__count_" + prop[0]] == arr.dtype[prop[0]].shape[0]):
                fixed_ok = False
                break
        if fixed_ok:
            out = {}
            for prop in el.props:
                out[prop[0]] = arr[prop[0]] if len(prop) == 2 else np.asarray(arr[prop[0]])
            return out, pos + el.count * dtype.itemsize
    return _walk_records(path, data, pos, el, order)


def _walk_records(path, data, pos, el: _Element, order: str):
    """Variable-length lists: read record by record (struct, no per-byte work)."""
    out: dict = {p[0]: [] for p in el.props}
    plan = []
    for prop in el.props:
        if len(prop) == 2:
            plan.append((prop[0], None, struct.Struct(order + _STRUCT[prop[1]])))
        else:
            plan.append((prop[0], np.dtype(order + prop[2]), np.dtype(order + prop[3])))
    n_data = len(data)
    try:
        for _ in range(el.count):
            for name, ctype, itype in plan:
                if ctype is None:
                    out[name].append(itype.unpack_from(data, pos)[0])
                    pos += itype.size
                else:
                    n = int(np.frombuffer(data, ctype, 1, pos)[0])
                    if n < 0:
                        raise InputError(f"{path}: a '{el.name}' record has a list of {n} items")
                    pos += ctype.itemsize
                    end = pos + n * itype.itemsize
                    if end > n_data:
                        raise ValueError
                    out[name].append(np.frombuffer(data, itype, n, pos))
                    pos = end
    except (ValueError, struct.error):
        raise InputError(
            f"{path}: binary PLY is truncated: the header declares {el.count:,} '{el.name}' records "
            f"but the data ends before them"
        ) from None
    for prop in el.props:
        if len(prop) == 2:
            out[prop[0]] = np.asarray(out[prop[0]])
    return out, pos


# ---- ascii --------------------------------------------------------------------------

def _read_ascii_elements(path, body: bytes, elements: list[_Element]):
    body = clean_text(body, comments=False)
    lines = Lines(body)
    declared = sum(el.count for el in elements)
    check_declared(path, declared, 2, len(body), "records (all elements)")
    if lines.count < declared:
        raise InputError(
            f"{path}: header declares {declared:,} records but the body has only {lines.count:,} lines"
        )
    if lines.count > declared:
        raise InputError(
            f"{path}: header declares {declared:,} records but the body has {lines.count:,} lines"
        )
    results = []
    row = 0
    for el in elements:
        block = lines.block(row, el.count)
        if not el.has_list:
            table = parse_table(path, block, el.count, f"'{el.name}' records", first_line=row + 1)
            if el.count and table.shape[1] != len(el.props):
                raise InputError(
                    f"{path}: '{el.name}' records have {table.shape[1]} values, the header declares {len(el.props)}"
                )
            results.append({p[0]: table[:, i] for i, p in enumerate(el.props)} if el.count else
                           {p[0]: np.zeros(0) for p in el.props})
        else:
            results.append(_ascii_lists(path, block, el, row))
        row += el.count
    return results


def _ascii_lists(path, block: bytes, el: _Element, row0: int):
    if el.count == 0:
        return {}
    try:
        table = parse_table(path, block, el.count, f"'{el.name}' records", first_line=row0 + 1)
        uniform = True
    except InputError:
        table, uniform = None, False
    out: dict = {}
    if uniform:
        col = 0
        for prop in el.props:
            if len(prop) == 2:
                out[prop[0]] = table[:, col]
                col += 1
            else:
                if col >= table.shape[1]:
                    uniform = False
                    break
                n = integers(path, table[:, col], f"the list sizes of '{el.name}' records")
                k = int(n[0])
                if k < 0 or not np.all(n == k) or col + 1 + k > table.shape[1]:
                    uniform = False
                    break
                out[prop[0]] = integers(path, table[:, col + 1: col + 1 + k], f"the '{prop[0]}' lists")
                col += 1 + k
        if uniform and col != table.shape[1]:
            uniform = False
    if uniform:
        return out
    out = {p[0]: [] for p in el.props}
    for i, raw in enumerate(block.split(b"\n")[: el.count]):
        words = raw.split()
        j = 0
        try:
            for prop in el.props:
                if len(prop) == 2:
                    out[prop[0]].append(float(words[j]))
                    j += 1
                else:
                    n = int(words[j])
                    if n < 0:
                        raise IndexError
                    items = np.array(words[j + 1: j + 1 + n], dtype=np.float64)
                    if len(items) != n:
                        raise IndexError
                    out[prop[0]].append(integers(path, items, f"the '{prop[0]}' lists"))
                    j += 1 + n
        except (IndexError, ValueError):
            raise InputError(
                f"{path}: '{el.name}' record at body line {row0 + i + 1} does not match the header "
                f"({raw.decode(errors='replace')[:60]!r})"
            ) from None
    return out


# ---- assembling ---------------------------------------------------------------------

def strips_to_triangles(strips) -> np.ndarray:
    """Triangles ``(T, 3)`` from triangle strips; -1 restarts a strip; orientation alternates.

    Degenerate triangles (a repeated index, used to join strips) are dropped.

    Example:
        >>> strips_to_triangles([np.array([0, 1, 2, 3, -1, 4, 5, 6])]).tolist()
        [[0, 1, 2], [2, 1, 3], [4, 5, 6]]
    """
    parts = []
    for s in strips:
        parts.append(np.asarray(s, dtype=np.int64).ravel())
        parts.append(np.array([-1], dtype=np.int64))
    if not parts:
        return np.zeros((0, 3), np.int64)
    seq = np.concatenate(parts)
    if seq.size < 3:
        return np.zeros((0, 3), np.int64)
    i = np.arange(seq.size - 2)
    a, b, c = seq[i], seq[i + 1], seq[i + 2]
    last_restart = np.maximum.accumulate(np.where(seq < 0, np.arange(seq.size), -1))[i]
    odd = ((i - (last_restart + 1)) % 2).astype(bool)
    tri = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    keep = (a >= 0) & (b >= 0) & (c >= 0) & (a != b) & (b != c) & (a != c)
    return tri[keep]


def _pick(fields: dict, names) -> list[str] | None:
    for group in names:
        present = [n for n in group if n in fields]
        if len(present) >= 3 and all(n in fields for n in group[:3]):
            return present
    return None


def _faces_from(path, fields: dict, strips: bool) -> np.ndarray:
    if not fields:
        return np.zeros((0, 3), np.int64)
    name = next((n for n in ("vertex_indices", "vertex_index") if n in fields), None)
    if name is None:
        name = next((n for n, v in fields.items() if isinstance(v, list) or getattr(v, "ndim", 1) == 2), None)
    if name is None:
        raise InputError(f"{path}: the face element has no list of vertex indices")
    value = fields[name]
    if strips:
        rows = value if isinstance(value, list) else list(value)
        return strips_to_triangles([integers(path, r, "triangle strip indices") for r in rows])
    if isinstance(value, list):
        counts = np.array([len(v) for v in value], dtype=np.int64)
        flat = integers(path, np.concatenate(value), "face indices") if value else np.zeros(0, np.int64)
        return fan_triangulate(counts, flat)
    value = integers(path, value, "face indices")
    if value.ndim != 2:
        raise InputError(f"{path}: the face element's '{name}' must be a list property")
    if value.shape[1] == 3:
        return np.ascontiguousarray(value)
    return fan_triangulate(np.full(value.shape[0], value.shape[1]), value.ravel())


def read_ply(path: str | os.PathLike) -> Payload:
    """Vertices with their attributes, and triangles (faces and strips) of a PLY file.

    Example:
        >>> payload = read_ply("bunny.ply")  # doctest: +SKIP
        >>> payload.points.shape, payload.faces.shape  # doctest: +SKIP
        ((35947, 3), (69451, 3))
    """
    path = Path(path)
    data = read_bytes(path)
    if not data.startswith(b"ply"):
        raise InputError(f"{path}: not a PLY file (it does not start with 'ply')")
    fmt, elements, pos = _parse_header(path, data)
    order = _FORMATS[fmt]
    by_name = {}
    if order is None:
        results = _read_ascii_elements(path, data[pos:], elements)
        for el, res in zip(elements, results):
            by_name.setdefault(el.name, res)
    else:
        for el in elements:
            res, pos = _read_binary_element(path, data, pos, el, order)
            if not isinstance(res, dict):
                res = {n: res[n] for n in res.dtype.names or ()}
            by_name.setdefault(el.name, res)
        if pos != len(data) and len(data) - pos > 2:
            raise InputError(
                f"{path}: {len(data) - pos:,} bytes follow the last element the header declares; "
                "the header's counts do not match the data"
            )
    vertex = by_name.get("vertex")
    if vertex is None:
        raise InputError(f"{path}: PLY file has no 'vertex' element")
    declared = next(el for el in elements if el.name == "vertex")
    scalar_names = {"x", "y", "z", *LABEL_NAMES, *(n for g in NORMAL_NAMES + COLOR_NAMES for n in g)}
    for prop in declared.props:
        if len(prop) == 4 and prop[0] in scalar_names:
            raise InputError(f"{path}: the vertex property {prop[0]!r} is declared as a list; expected a scalar")
    for axis in "xyz":
        if axis not in vertex:
            raise InputError(f"{path}: PLY vertex element has no '{axis}' property")
    count = len(vertex["x"])
    check_fits(path, count * 8 * 10, "the vertices")
    points = columns_to_float64(vertex[a] for a in "xyz")
    normals = colors = labels = None
    names = _pick(vertex, NORMAL_NAMES)
    if names:
        normals = columns_to_float64(vertex[n] for n in names[:3])
    names = _pick(vertex, COLOR_NAMES)
    if names:
        colors = colors_to_uint8(np.stack([np.asarray(vertex[n]) for n in names], axis=1), path)
    label = next((n for n in LABEL_NAMES if n in vertex), None)
    if label:
        labels = integers(path, vertex[label], f"the '{label}' values")
    faces = [ _faces_from(path, by_name[n], strips=False) for n in ("face",) if n in by_name ]
    strips = [ _faces_from(path, by_name[n], strips=True) for n in ("tristrips", "tristrip") if n in by_name ]
    all_faces = faces + strips
    tri = np.concatenate(all_faces) if all_faces else None
    if tri is not None:
        check_faces(path, tri, count)
    return Payload(points, tri, normals, colors, labels,
                   info={"format": f"ply {fmt}", "elements": {el.name: el.count for el in elements}})


# ---- writing ------------------------------------------------------------------------

def write_ply(path, points, faces=None, normals=None, colors=None, labels=None, *, binary: bool = True) -> list[str]:
    """Write a PLY file (binary little endian by default, ``binary=False`` for ASCII), atomically.

    ``points (N, 3)`` as double, ``normals (N, 3)`` as nx ny nz (double), ``colors (N, 3|4)`` as
    uchar red green blue [alpha], ``labels (N,)`` as int label, ``faces (F, 3)`` as a uchar/int list.
    PLY's widest integer is 32 bits: labels or vertex indices beyond it are refused, not wrapped.
    """
    n = points.shape[0]
    if labels is not None and labels.size and (labels.min() < -(2**31) or labels.max() >= 2**31):
        bad = int(labels.min()) if labels.min() < -(2**31) else int(labels.max())
        raise OptionError(f"{path}: label {bad} does not fit PLY's 32-bit int; PLY has no wider integer type")
    if faces is not None and n > 2**31 - 1:
        raise OptionError(f"{path}: {n:,} vertices cannot be indexed by PLY's 32-bit int faces")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f8"), ("ny", "<f8"), ("nz", "<f8")]
    if colors is not None:
        fields += [(c, "u1") for c in ("red", "green", "blue", "alpha")[: colors.shape[1]]]
    if labels is not None:
        fields += [("label", "<i4")]
    names = {"<f8": "double", "u1": "uchar", "<i4": "int"}
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment written by nurbskit",
              f"element vertex {n}"]
    header += [f"property {names[t]} {name}" for name, t in fields]
    nf = 0 if faces is None else faces.shape[0]
    if faces is not None:
        header += [f"element face {nf}", "property list uchar int vertex_indices"]
    header.append("end_header")
    head = ("\n".join(header) + "\n").encode("ascii")
    rec = np.empty(n, dtype=np.dtype(fields))
    rec["x"], rec["y"], rec["z"] = points[:, 0], points[:, 1], points[:, 2]
    if normals is not None:
        rec["nx"], rec["ny"], rec["nz"] = normals[:, 0], normals[:, 1], normals[:, 2]
    if colors is not None:
        for i, c in enumerate(("red", "green", "blue", "alpha")[: colors.shape[1]]):
            rec[c] = colors[:, i]
    if labels is not None:
        rec["label"] = labels
    with atomic_open(path, "wb") as handle:
        handle.write(head)
        if binary:
            handle.write(memoryview(rec).cast("B"))
            if faces is not None:
                frec = np.empty(nf, dtype=[("n", "u1"), ("v", "<i4", (3,))])
                frec["n"] = 3
                frec["v"] = faces
                handle.write(frec.tobytes())
        else:
            from .text import format_rows

            cols = [rec[name].astype(np.float64) if t == "<f8" else rec[name].astype(np.int64) for name, t in fields]
            kinds = ["f" if t == "<f8" else "d" for _, t in fields]
            handle.write(format_rows(cols, kinds))
            if faces is not None:
                handle.write(format_rows([np.full(nf, 3), faces[:, 0], faces[:, 1], faces[:, 2]], "dddd"))
    return []
