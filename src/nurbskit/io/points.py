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
from .formats import check_options, read_payload, writer_for

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
        A value the format cannot hold is never altered: it is written in a wider type the
        format allows (PCD ``F 8``, ``I 8``) or refused with an OptionError.

    Example:
        >>> write_points("cloud.ply", np.random.rand(100, 3))  # doctest: +SKIP
        []
    """
    path = Path(path)
    ext, row = writer_for(path, format, "points")
    pts = as_points(points)
    n = pts.shape[0]
    nrm = as_attribute(normals, n, "normals", (3,), np.float64)
    col = as_attribute(colors, n, "colors", (3, 4), np.uint8)
    lab = as_attribute(labels, n, "labels", None, np.int64)
    if not np.isfinite(pts).all():
        raise OptionError(f"{path}: points contain NaN or infinite values; refusing to write them")
    check_options(ext, row, options)
    return row.load()(path, pts, None, nrm, col, lab, **options)
