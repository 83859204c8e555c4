"""PCD v0.7 (Point Cloud Library): ``DATA ascii``, ``binary`` and ``binary_compressed``.

Header keywords (in order): VERSION, FIELDS, SIZE, TYPE (F float, I signed, U unsigned),
COUNT, WIDTH, HEIGHT (> 1 for organised clouds), VIEWPOINT, POINTS, DATA.
``binary`` stores one record per point (array of structures); ``binary_compressed``
stores two uint32 (compressed and uncompressed sizes), then an LZF stream that
decompresses to each field's values for all points in turn (structure of arrays).

Fields understood: x y z; normal_x normal_y normal_z; rgb (packed in a float32, PCL's
convention) or rgba (uint32); label. Points whose x, y or z is NaN (the holes of an
organised depth image) are kept here, in grid order; ``read_points`` drops and counts them.

Reference: pointclouds.org, "The PCD (Point Cloud Data) file format".
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from ..errors import OptionError
from ._base import (
    InputError, Lines, Payload, check_declared, check_fits, clean_text, columns_to_float64, integers, parse_table,
    read_bytes,
)
from .lzf import LZFError, compress_literal, decompress
from .text import format_rows

_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_KIND = {"F": "f", "I": "i", "U": "u"}
_MAX_COUNT = 1 << 16  # values per field and point (PCL's largest descriptors have a few hundred)


def _parse_header(path: Path, data: bytes):
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise InputError(f"{path}: PCD header has no DATA line")
        raw = data[pos:nl]
        pos = nl + 1
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise InputError(f"{path}: PCD header is not ASCII text") from None
        if not line or line.startswith("#"):
            continue
        words = line.split()
        key = words[0].upper()
        if key not in _KEYS:
            raise InputError(f"{path}: unknown PCD header keyword {words[0]!r}")
        header[key] = words[1:]
        if key == "DATA":
            break
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "DATA"):
        if key not in header:
            raise InputError(f"{path}: PCD header has no {key} line")
    fields = header["FIELDS"]
    n = len(fields)
    sizes, types = header["SIZE"], header["TYPE"]
    counts = header.get("COUNT", ["1"] * n)
    if not (len(sizes) == len(types) == len(counts) == n):
        raise InputError(
            f"{path}: PCD header lists {n} FIELDS but {len(sizes)} SIZE, {len(types)} TYPE, {len(counts)} COUNT values"
        )
    try:
        width, height = int(header["WIDTH"][0]), int(header["HEIGHT"][0])
        points = int(header["POINTS"][0]) if "POINTS" in header else width * height
        sizes_i = [int(s) for s in sizes]
        counts_i = [int(c) for c in counts]
    except (ValueError, IndexError):
        raise InputError(f"{path}: PCD header has a WIDTH, HEIGHT, POINTS, SIZE or COUNT that is not an integer") from None
    if min(width, height, points) < 0:
        raise InputError(f"{path}: PCD header has a negative WIDTH, HEIGHT or POINTS ({width}, {height}, {points})")
    if points != width * height:
        raise InputError(f"{path}: PCD header says POINTS {points:,} but WIDTH x HEIGHT = {width} x {height} = {width * height:,}")
    dtypes = []
    for name, size, kind, count in zip(fields, sizes_i, types, counts_i):
        if kind.upper() not in _KIND or size not in (1, 2, 4, 8) or (kind.upper() == "F" and size not in (4, 8)):
            raise InputError(f"{path}: PCD field {name!r} has unsupported TYPE {kind} SIZE {size}")
        if not 1 <= count <= _MAX_COUNT:
            raise InputError(f"{path}: PCD field {name!r} has COUNT {count}; expected 1 to {_MAX_COUNT:,}")
        dtypes.append((name, np.dtype(f"<{_KIND[kind.upper()]}{size}"), count))
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode not in ("ascii", "binary", "binary_compressed"):
        raise InputError(f"{path}: PCD DATA must be ascii, binary or binary_compressed, got {mode!r}")
    return dtypes, width, height, points, mode, pos


def _unique_names(dtypes):
    seen, out = {}, []
    for name, dt, count in dtypes:
        key = name if name not in seen and name != "_" else f"_{name}_{len(out)}"
        seen[key] = True
        out.append((key, dt, count))
    return out


def read_pcd(path: str | os.PathLike) -> Payload:
    """Points (NaN holes included, in grid order), normals, colours and labels of a PCD file.

    Example:
        >>> payload = read_pcd("test0.pcd")  # 640 x 480, organised, binary_compressed  # doctest: +SKIP
        >>> payload.points.shape  # doctest: +SKIP
        (307200, 3)
    """
    path = Path(path)
    data = read_bytes(path)
    dtypes, width, height, n, mode, pos = _parse_header(path, data)
    dtypes = _unique_names(dtypes)
    record = np.dtype([(name, dt, (count,)) if count > 1 else (name, dt) for name, dt, count in dtypes])
    remaining = len(data) - pos
    columns: dict[str, np.ndarray] = {}
    if mode == "binary":
        check_declared(path, n, record.itemsize, remaining, "points")
        rec = np.frombuffer(data, record, n, pos)
        columns = {name: rec[name] for name in record.names}
    elif mode == "binary_compressed":
        if remaining < 8:
            raise InputError(f"{path}: binary_compressed PCD is truncated before its size fields")
        csize, usize = (int(v) for v in np.frombuffer(data, "<u4", 2, pos))
        if csize > remaining - 8:
            raise InputError(
                f"{path}: binary_compressed PCD announces {csize:,} compressed bytes but only {remaining - 8:,} follow"
            )
        if usize != n * record.itemsize:
            raise InputError(
                f"{path}: PCD header declares {n:,} points of {record.itemsize} bytes ({n * record.itemsize:,} bytes) "
                f"but the compressed block holds {usize:,} bytes"
            )
        check_fits(path, usize * 3, "the decompressed points")
        try:
            raw = decompress(memoryview(data)[pos + 8: pos + 8 + csize], usize)
        except LZFError as exc:
            raise InputError(f"{path}: the LZF-compressed data is corrupt ({exc})") from None
        off = 0
        for name, dt, count in dtypes:  # structure of arrays: one field after the other
            size = n * count * dt.itemsize
            arr = np.frombuffer(raw, dt, n * count, off)
            columns[name] = arr.reshape(n, count) if count > 1 else arr
            off += size
    else:
        body = clean_text(data[pos:])
        lines = Lines(body)
        check_declared(path, n, 2, len(body), "points")
        if lines.count != n:
            raise InputError(f"{path}: PCD header declares {n:,} points but {lines.count:,} data lines follow")
        width_cols = sum(count for _, _, count in dtypes)
        table = parse_table(path, body, n, "point lines") if n else np.zeros((0, width_cols))
        if n and table.shape[1] != width_cols:
            raise InputError(f"{path}: PCD point lines have {table.shape[1]} values, the FIELDS need {width_cols}")
        col = 0
        for name, dt, count in dtypes:
            vals = table[:, col: col + count]
            if name in ("rgb", "rgba"):
                # ASCII PCD writes packed colours as a float (rgb) or an integer (rgba)
                vals = vals.astype(np.float32).view(np.uint32) if dt.kind == "f" else vals.astype(np.uint32)
            elif dt.kind in "iu":  # the declared integer type, checked: NaN or 1e30 must not wrap around
                vals = integers(path, vals, f"the '{name}' values")
                info = np.iinfo(dt)
                if vals.size and (vals.min() < info.min or vals.max() > info.max):
                    raise InputError(f"{path}: a '{name}' value does not fit the declared TYPE {dt.kind.upper()} "
                                     f"SIZE {dt.itemsize} ({info.min} to {info.max})")
                vals = vals.astype(dt)
            else:  # the declared type: a float32 field printed in decimal reads back as that float32
                with np.errstate(over="ignore"):
                    vals = vals.astype(dt)
            columns[name] = vals[:, 0] if count == 1 else vals
            col += count
    for axis in "xyz":
        if axis not in columns:
            raise InputError(f"{path}: PCD FIELDS has no '{axis}'")
    points = columns_to_float64(columns[a] for a in "xyz")
    normals = colors = labels = None
    if all(k in columns for k in ("normal_x", "normal_y", "normal_z")):
        normals = columns_to_float64(columns[k] for k in ("normal_x", "normal_y", "normal_z"))
    for key in ("rgb", "rgba"):
        if key in columns:
            packed = np.ascontiguousarray(columns[key])
            packed = packed.view(np.uint32) if packed.dtype.itemsize == 4 else packed.astype(np.uint32)
            rgb = [(packed >> 16) & 255, (packed >> 8) & 255, packed & 255]
            if key == "rgba":
                rgb.append((packed >> 24) & 255)
            colors = np.stack(rgb, axis=1).astype(np.uint8)
            break
    if "label" in columns:
        labels = np.asarray(columns["label"]).astype(np.int64)
    # NaN holes stay in: read_points drops them (its default for PCD) and counts them
    dropped = 0
    return Payload(points, None, normals, colors, labels, dropped,
                   info={"format": f"pcd {mode}", "width": width, "height": height,
                         "fields": [d[0] for d in dtypes]})


def write_pcd(path, points, faces=None, normals=None, colors=None, labels=None, *, data: str = "binary",
              coordinate_dtype=None) -> list[str]:
    """Write PCD v0.7 (``data``: 'ascii', 'binary' or 'binary_compressed'), atomically.

    Coordinates are stored as float32 (PCL's usual type) when every coordinate and normal
    fits float32's range, as float64 (``F 8``) otherwise, never as ``inf``;
    ``coordinate_dtype=np.float64`` keeps them exact, ``np.float32`` insists on float32
    (and refuses values beyond its range). Colours go into a packed ``rgb`` float
    (``rgba`` uint32 with alpha), labels into ``label`` (I or U, 4 bytes, 8 when needed).
    The cloud is unorganised (HEIGHT 1).
    """
    if data not in ("ascii", "binary", "binary_compressed"):
        raise OptionError(f"PCD data mode must be ascii, binary or binary_compressed, got {data!r}")
    n = points.shape[0]
    big = max(_largest(points), _largest(normals))
    f32 = float(np.finfo(np.float32).max)
    if coordinate_dtype is None:
        coordinate_dtype = np.float32 if big <= f32 else np.float64
    cdt = np.dtype(coordinate_dtype).newbyteorder("<")
    if cdt.kind != "f" or cdt.itemsize not in (4, 8):
        raise OptionError(f"PCD coordinate_dtype must be float32 or float64, got {np.dtype(coordinate_dtype)}")
    if cdt.itemsize == 4 and big > f32:
        raise OptionError(f"{path}: a coordinate ({big:.3g}) is beyond float32's range; write it with "
                          "coordinate_dtype=float64 (PCD 'F 8')")
    fields = [("x", cdt), ("y", cdt), ("z", cdt)]
    if normals is not None:
        fields += [("normal_x", cdt), ("normal_y", cdt), ("normal_z", cdt)]
    if colors is not None:
        fields += [("rgba", np.dtype("<u4"))] if colors.shape[1] == 4 else [("rgb", np.dtype("<f4"))]
    if labels is not None:
        fields += [("label", _label_dtype(labels))]
    rec = np.empty(n, np.dtype(fields))
    for i, a in enumerate("xyz"):
        rec[a] = points[:, i]
    if normals is not None:
        for i, a in enumerate(("normal_x", "normal_y", "normal_z")):
            rec[a] = normals[:, i]
    if colors is not None:
        c = colors.astype(np.uint32)
        packed = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
        if colors.shape[1] == 4:
            rec["rgba"] = packed | (c[:, 3] << 24)
        else:
            rec["rgb"] = packed.view(np.float32)
    if labels is not None:
        rec["label"] = labels
    types = {"f": "F", "i": "I", "u": "U"}
    header = (
        "# .PCD v0.7 - Point Cloud Data file format (written by nurbskit)\nVERSION 0.7\n"
        f"FIELDS {' '.join(n_ for n_, _ in fields)}\n"
        f"SIZE {' '.join(str(d.itemsize) for _, d in fields)}\n"
        f"TYPE {' '.join(types[d.kind] for _, d in fields)}\n"
        f"COUNT {' '.join('1' for _ in fields)}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    ).encode("ascii")
    with atomic_open(path, "wb") as handle:
        handle.write(header)
        if data == "binary":
            handle.write(memoryview(rec).cast("B"))
        elif data == "binary_compressed":
            soa = b"".join(np.ascontiguousarray(rec[name]).tobytes() for name, _ in fields)
            packed = compress_literal(soa)
            handle.write(np.array([len(packed), len(soa)], "<u4").tobytes() + packed)
        else:
            cols, kinds = [], ""
            for name, d in fields:
                if name == "rgb":  # PCL writes the packed float's value
                    cols.append(rec[name].astype(np.float64))
                    kinds += "f"
                elif d.kind == "f":
                    cols.append(rec[name].astype(np.float64))
                    kinds += "f"
                else:
                    cols.append(rec[name].astype(np.int64))
                    kinds += "d"
            handle.write(format_rows(cols, kinds, 9 if cdt.itemsize == 4 else 17))
    return ["faces"] if faces is not None else []


def _largest(values) -> float:
    return float(np.abs(values).max()) if values is not None and values.size else 0.0


def _label_dtype(labels: np.ndarray) -> np.dtype:
    """The narrowest PCD integer type (4 or 8 bytes, signed when needed) that holds every label."""
    lo, hi = (int(labels.min()), int(labels.max())) if labels.size else (0, 0)
    if lo < 0:
        return np.dtype("<i4") if lo >= -(2**31) and hi < 2**31 else np.dtype("<i8")
    return np.dtype("<u4") if hi < 2**32 else np.dtype("<u8")
