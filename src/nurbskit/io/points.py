"""Point clouds in and out: ``read_points`` and ``write_points``, chosen by extension
(and by content where the extension lies).

Reads PLY, OFF/NOFF, OBJ, STL (vertices), PCD, XYZ/TXT/CSV/PTS/XYZC, NPY/NPZ and the
vertices of any mesh format trimesh knows. See docs/io.md for the table of formats.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ._base import InputError, PointCloud, as_attribute, as_points, check_finite, nonfinite_rows
from .formats import POINT_WRITE, read_payload

NONFINITE = ("drop", "error", "keep")


def read_points(path: str | os.PathLike, *, nonfinite: str | None = None, format: str | None = None) -> PointCloud:
    """Read a point cloud (or the vertices of a mesh) from ``path``.

    Args:
        path: the file.
        nonfinite: what to do with points holding NaN or infinite coordinates:
            'error' (the default, except for PCD), 'drop' (the default for PCD, whose
            organised clouds mark missing depth with NaN; dropped points are counted in
            ``PointCloud.dropped``), or 'keep'.
        format: force a reader ('ply', 'off', 'obj', 'stl', 'pcd', 'npy', 'npz', 'text').

    Returns:
        PointCloud with ``points (N, 3)`` float64 and, when the file has them,
        ``normals (N, 3)``, ``colors (N, 3|4)`` uint8, ``labels (N,)`` int64.

    Example:
        >>> cloud = read_points("cat.off")  # doctest: +SKIP
        >>> cloud.points.shape, cloud.normals.shape  # doctest: +SKIP
        ((366, 3), (366, 3))
    """
    if nonfinite is not None and nonfinite not in NONFINITE:
        raise OptionError(f"nonfinite must be one of {NONFINITE}, got {nonfinite!r}")
    path = Path(path)
    return cloud_from_payload(path, read_payload(path, format), nonfinite)


def cloud_from_payload(path: Path, payload, nonfinite: str | None = None) -> PointCloud:
    """The PointCloud of a reader's payload, with the NaN policy of :func:`read_points` applied."""
    if nonfinite is None:
        nonfinite = "drop" if payload.info.get("format", "").startswith("pcd") else "error"
    points, normals, colors, labels = payload.points, payload.normals, payload.colors, payload.labels
    dropped = payload.dropped
    if points.shape[0] == 0:
        raise InputError(f"{path}: the file holds no points ({payload.info.get('format', 'its header')} declares none)")
    if nonfinite == "error":
        check_finite(path, points, "points")
    elif nonfinite == "drop":
        keep = ~nonfinite_rows(points)
        if not keep.all():
            dropped += int((~keep).sum())
            points = points[keep]
            normals = None if normals is None else normals[keep]
            colors = None if colors is None else colors[keep]
            labels = None if labels is None else labels[keep]
        if points.shape[0] == 0:
            raise InputError(f"{path}: the file holds no points: all {dropped:,} have NaN coordinates")
    return PointCloud(np.ascontiguousarray(points, dtype=np.float64), normals, colors, labels, dropped, path)


def write_points(path: str | os.PathLike, points, normals=None, colors=None, labels=None, *,
                 format: str | None = None, **options) -> list[str]:
    """Write a point cloud to ``path`` by its extension, atomically (a temporary file renamed
    into place: an interrupted write leaves any previous file untouched).

    Args:
        points: ``(N, 3)``; normals ``(N, 3)``; colors ``(N, 3|4)`` (uint8, or floats in [0, 1]);
            labels ``(N,)`` integers. numpy arrays or torch tensors.
        format: an extension to use instead of the path's ('.ply', '.pcd', ...).
        options: per format: ``binary`` (PLY, default True), ``data`` (PCD: 'binary',
            'ascii', 'binary_compressed'), ``precision`` (text: significant digits, default 17).

    Returns:
        The names of the attributes the format cannot store (e.g. ``['labels']`` for OFF).

    Example:
        >>> write_points("cloud.ply", np.random.rand(100, 3))  # doctest: +SKIP
        []
    """
    path = Path(path)
    ext = (format if format is None or format.startswith(".") else "." + format) or path.suffix
    ext = ext.lower()
    if ext not in POINT_WRITE:
        raise OptionError(f"{path}: cannot write points as {ext or '(no extension)'!r}; writable: {', '.join(POINT_WRITE)}")
    if path.is_dir():
        raise OptionError(f"{path}: is a directory, expected a file name")
    pts = as_points(points)
    n = pts.shape[0]
    nrm = as_attribute(normals, n, "normals", (3,), np.float64)
    col = as_attribute(colors, n, "colors", (3, 4), np.uint8)
    lab = as_attribute(labels, n, "labels", None, np.int64)
    if not np.isfinite(pts).all():
        raise OptionError(f"{path}: points contain NaN or infinite values; refusing to write them")
    _check_options(ext, options)
    if ext == ".ply":
        from .ply import write_ply

        write_ply(path, pts, None, nrm, col, lab, binary=options.get("binary", True))
        return []
    if ext == ".pcd":
        from .pcd import write_pcd

        return write_pcd(path, pts, nrm, col, lab, **options)
    if ext in (".npy",):
        from .npy import write_npy

        return write_npy(path, pts, nrm, col, lab)
    if ext == ".npz":
        from .npy import write_npz

        return write_npz(path, pts, None, nrm, col, lab)
    if ext == ".off":
        from .off import write_off

        write_off(path, pts, None, nrm, col, **options)
        return ["labels"] if lab is not None else []
    if ext == ".obj":
        from .obj import write_obj

        left = write_obj(path, pts, None, nrm, col, **options)
        return left + (["labels"] if lab is not None else [])
    from .text import write_text_points

    return write_text_points(path, pts, nrm, col, lab, **options)


_OPTIONS = {".ply": {"binary"}, ".pcd": {"data", "coordinate_dtype"}, ".off": {"precision"}, ".obj": {"precision"},
            ".stl": {"binary"}}


def _check_options(ext: str, options: dict) -> None:
    allowed = _OPTIONS.get(ext, {"precision"} if ext not in (".npy", ".npz") else set())
    unknown = set(options) - allowed
    if unknown:
        raise OptionError(f"options {sorted(unknown)} do not apply to {ext} files (allowed: {sorted(allowed) or 'none'})")
