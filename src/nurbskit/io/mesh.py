"""Triangle meshes in and out: ``read_mesh`` and ``write_mesh``, chosen by extension
(and by content where the extension lies).

Reads PLY (faces and triangle strips), OFF/NOFF, OBJ (polygons fan-triangulated,
negative indices), STL (ASCII and binary), NPZ, and through trimesh any other mesh
format it knows (glTF, 3MF, ...).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ._base import InputError, Mesh, as_attribute, as_faces, as_points, check_finite
from .formats import check_options, read_payload, writer_for


def read_mesh(path: str | os.PathLike, *, format: str | None = None) -> Mesh:
    """Read a triangle mesh: ``vertices (V, 3)`` float64, ``faces (F, 3)`` int64, and per-vertex
    ``normals (V, 3)`` / ``colors (V, 3|4)`` when the file has them.

    A file without faces (a point cloud) is an InputError that says so; read it with
    :func:`read_points`.

    Example:
        >>> mesh = read_mesh("cat.off")  # doctest: +SKIP
        >>> mesh.vertices.shape, mesh.faces.shape  # doctest: +SKIP
        ((366, 3), (698, 3))
    """
    path = Path(path)
    payload = read_payload(path, format)
    if payload.points.shape[0] == 0:
        raise InputError(f"{path}: the file holds no points and no faces")
    if payload.faces is None or payload.faces.shape[0] == 0:
        raise InputError(
            f"{path}: has {payload.points.shape[0]:,} points and no faces; expected a triangle mesh, found a "
            "point cloud (`nurbskit fit` turns points into a surface)"
        )
    check_finite(path, payload.points, "vertices")
    return Mesh(np.ascontiguousarray(payload.points, dtype=np.float64), payload.faces.astype(np.int64),
                payload.normals, payload.colors, path)


def write_mesh(path: str | os.PathLike, vertices, faces=None, normals=None, colors=None, *,
               format: str | None = None, **options) -> list[str]:
    """Write a triangle mesh by extension (.ply, .off, .obj, .stl, .npz), atomically.

    Args:
        vertices: ``(V, 3)`` (or a :class:`Mesh`, with ``faces`` left out); faces ``(F, 3)``
            integer indices; normals ``(V, 3)`` and colors ``(V, 3|4)`` per vertex, optional.
        options: ``binary`` for PLY and STL (default True), ``precision`` for text formats.

    Returns:
        The names of the attributes the format cannot store (STL keeps neither normals
        nor colours; it also rounds coordinates to float32, and refuses values beyond
        float32's range).

    Example:
        >>> write_mesh("tri.obj", np.eye(3), np.array([[0, 1, 2]]))  # doctest: +SKIP
        []
    """
    path = Path(path)
    if isinstance(vertices, Mesh):
        if faces is not None:
            raise OptionError("write_mesh: give a Mesh, or vertices and faces, not both")
        mesh = vertices
        vertices, faces = mesh.vertices, mesh.faces
        normals = mesh.normals if normals is None else normals
        colors = mesh.colors if colors is None else colors
    if faces is None:
        raise OptionError("write_mesh needs faces (F, 3); write a point cloud with write_points")
    ext, row = writer_for(path, format, "mesh")
    v = as_points(vertices, "vertices")
    f = as_faces(faces, v.shape[0])
    nrm = as_attribute(normals, v.shape[0], "normals", (3,), np.float64)
    col = as_attribute(colors, v.shape[0], "colors", (3, 4), np.uint8)
    if not np.isfinite(v).all():
        raise OptionError(f"{path}: vertices contain NaN or infinite values; refusing to write them")
    check_options(ext, row, options)
    return row.load()(path, v, f, nrm, col, None, **options)
