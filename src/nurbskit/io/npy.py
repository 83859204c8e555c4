"""NumPy files: ``.npy`` holding ``(N, 3)`` points (or ``(N, 6)`` points and normals), and
``.npz`` archives with arrays named ``points`` (or ``vertices``), and optionally
``normals``, ``colors``, ``labels``, ``faces``.

Pickled object arrays are refused (``allow_pickle=False``): a data file must not run code.
"""

from __future__ import annotations

import math
import os
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .._fs import atomic_path
from ._base import InputError, Payload, check_fits, colors_to_uint8, integers


def _header_shape(path: Path):
    """Shape and dtype from the .npy header, checked against the file size before loading."""
    with open(path, "rb") as handle:
        try:
            version = np.lib.format.read_magic(handle)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
        except (ValueError, TypeError, SyntaxError, tokenize.TokenError, RecursionError, MemoryError) as exc:
            # numpy parses the header with ast.literal_eval: a damaged one raises any of these
            raise InputError(f"{path}: not a valid .npy file ({type(exc).__name__}: {_first_line(exc)})") from None
        offset = handle.tell()
    return shape, dtype, offset


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0][:200] if text else type(exc).__name__


def _load_npy(path: Path) -> np.ndarray:
    shape, dtype, offset = _header_shape(path)
    if dtype.hasobject:
        raise InputError(f"{path}: .npy holds Python objects; only numeric arrays are read")
    nbytes = math.prod(shape) * dtype.itemsize  # Python integers: a 2^63 dimension must not wrap around
    size = path.stat().st_size - offset
    if nbytes > size:
        raise InputError(
            f"{path}: .npy header declares shape {shape} ({nbytes:,} bytes) but only {size:,} bytes follow; "
            "the file is truncated"
        )
    check_fits(path, nbytes, "the array")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, TypeError, SyntaxError, tokenize.TokenError) as exc:
        raise InputError(f"{path}: cannot read .npy ({_first_line(exc)})") from None


def _table(path: Path, arr: np.ndarray, what: str, cols: tuple[int, ...]) -> np.ndarray:
    if arr.ndim != 2 or arr.shape[1] not in cols:
        want = " or ".join(f"(N, {c})" for c in cols)
        raise InputError(f"{path}: {what} must have shape {want}, got {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise InputError(f"{path}: {what} must be numeric, got dtype {arr.dtype}")
    return arr


def read_npy(path: str | os.PathLike) -> Payload:
    """Points (and normals for ``(N, 6)``) of a ``.npy`` file."""
    path = Path(path)
    arr = _table(path, _load_npy(path), "the array", (3, 6))
    points = np.ascontiguousarray(arr[:, :3], dtype=np.float64)
    normals = np.ascontiguousarray(arr[:, 3:6], dtype=np.float64) if arr.shape[1] == 6 else None
    return Payload(points, None, normals, info={"format": "npy", "dtype": str(arr.dtype)})


def read_npz(path: str | os.PathLike) -> Payload:
    """Points, faces and attributes of a ``.npz`` archive (see the module docstring for names)."""
    path = Path(path)
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise InputError(f"{path}: not a readable .npz archive ({exc})") from None
    with archive:
        names = set(archive.files)
        key = "points" if "points" in names else "vertices" if "vertices" in names else None
        if key is None:
            raise InputError(f"{path}: .npz has no 'points' or 'vertices' array (it has {sorted(names)})")
        # the members' uncompressed sizes, as the archive declares them, must fit before any is read
        check_fits(path, sum(info.file_size for info in archive.zip.infolist()), "the arrays")
        try:
            arrays = {name: archive[name] for name in names}
        except (ValueError, OSError, EOFError, KeyError, TypeError, SyntaxError, tokenize.TokenError,
                RecursionError, zipfile.BadZipFile, zlib.error) as exc:
            raise InputError(f"{path}: a .npz array cannot be read ({type(exc).__name__}: {_first_line(exc)})") from None
    points = np.ascontiguousarray(_table(path, arrays[key], key, (3,)), dtype=np.float64)
    n = points.shape[0]
    normals = colors = labels = faces = None
    if "normals" in arrays:
        normals = np.ascontiguousarray(_table(path, arrays["normals"], "normals", (3,)), dtype=np.float64)
    if "colors" in arrays:
        colors = colors_to_uint8(_table(path, arrays["colors"], "colors", (3, 4)), path)
    if "labels" in arrays:
        labels = integers(path, np.asarray(arrays["labels"]).reshape(-1), "labels")
    if "faces" in arrays:
        f = _table(path, arrays["faces"], "faces", (3,))
        if f.dtype.kind not in "iu":
            raise InputError(f"{path}: faces must be integers, got dtype {f.dtype}")
        faces = integers(path, f, "faces")
    for name, value in (("normals", normals), ("colors", colors), ("labels", labels)):
        if value is not None and value.shape[0] != n:
            raise InputError(f"{path}: '{name}' has {value.shape[0]} rows but there are {n} points")
    return Payload(points, faces, normals, colors, labels, info={"format": "npz", "arrays": sorted(names)})


def write_npy(path, points, faces=None, normals=None, colors=None, labels=None) -> list[str]:
    """Write ``(N, 3)`` (or ``(N, 6)`` with normals) float64 to ``.npy``, atomically."""
    arr = points if normals is None else np.concatenate([points, normals], axis=1)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, arr)
    return [n for n, v in (("faces", faces), ("colors", colors), ("labels", labels)) if v is not None]


def write_npz(path, points, faces=None, normals=None, colors=None, labels=None) -> list[str]:
    """Write every given array into a compressed ``.npz``, atomically."""
    arrays = {"points": points}
    for name, value in (("faces", faces), ("normals", normals), ("colors", colors), ("labels", labels)):
        if value is not None:
            arrays[name] = value
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)
    return []
