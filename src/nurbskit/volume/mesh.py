"""Isosurfaces of a sampled field and their projections.

Meshes are written by :func:`nurbskit.io.write_mesh` (``write_mesh(path, mesh.vertices, mesh.faces)``).

Convention: meshes are in unit-cube coordinates (see :mod:`nurbskit.volume.views`),
vertices ``(V, 3)`` float64 as ``(x, y, z)``, faces ``(F, 3)`` int64, counter-clockwise
seen from outside (outward normals by the right-hand rule).
"""

from __future__ import annotations

import numpy as np
import torch

from ..errors import NurbskitError
from ..io._base import Mesh  # the one mesh type of the package
from .views import View, points_to_pixels

Tensor = torch.Tensor


def isosurface(grid: Tensor | np.ndarray, isovalue: float) -> Mesh:
    """Marching cubes (scikit-image) of a field sampled on ``[0, 1]^3``: ``(R, S, T)`` -> Mesh.

    Grid point ``[i, j, k]`` sits at ``(i / (R - 1), j / (S - 1), k / (T - 1))``. The grid
    is padded with one layer below the isovalue so that solids touching the cube's
    faces are closed there (the caps lie on the faces); the mesh is watertight.
    Returns an empty mesh when no sample exceeds the isovalue.

    Example:
        >>> import torch
        >>> g = torch.linspace(-1, 1, 9)
        >>> r = (g[:, None, None] ** 2 + g[None, :, None] ** 2 + g[None, None, :] ** 2).sqrt()
        >>> isosurface(1 - r, 0.5).vertices.shape[1]
        3
    """
    from skimage.measure import marching_cubes

    values = grid.detach().cpu().double().numpy() if isinstance(grid, Tensor) else np.asarray(grid, np.float64)
    if values.ndim != 3 or min(values.shape) < 2:
        raise NurbskitError(f"isosurface needs a 3-D grid with at least 2 samples per axis, got shape {values.shape}")
    if not np.isfinite(values).all():
        raise NurbskitError("isosurface: the field contains NaN or infinite values")
    if not (values > isovalue).any():
        return Mesh.empty()
    # A pad far below the isovalue puts the cap vertices (interpolated between the
    # face sample and the pad) on the face itself, to rounding; clipping removes the rest.
    span = float(values.max() - values.min()) + 1.0
    padded = np.pad(values, 1, mode="constant", constant_values=isovalue - 1e6 * span)
    spacing = tuple(1.0 / (n - 1) for n in values.shape)
    verts, faces, _, _ = marching_cubes(padded, level=isovalue, spacing=spacing, allow_degenerate=False)
    verts = np.clip(verts - np.asarray(spacing), 0.0, 1.0)
    # skimage orders faces clockwise seen from the high side; flip to outward normals.
    return Mesh(verts.astype(np.float64), faces[:, ::-1].astype(np.int64).copy())


def rasterize_projection(mesh: Mesh, view: View, height: int, width: int) -> np.ndarray:
    """The mesh's silhouette in one view, as a bool image ``(height, width)``.

    A pixel is set when its centre lies in the orthographic projection of any triangle
    (edges included, to a small tolerance, so that adjacent triangles leave no cracks).
    For a closed mesh that is exactly the projection of the solid it bounds.
    """
    image = np.zeros((height, width), dtype=bool)
    if mesh.is_empty:
        return image
    pix = points_to_pixels(torch.from_numpy(mesh.vertices), view, height, width).numpy()
    tri = pix[mesh.faces]  # (F, 3, 2) as (row, col)
    lo = np.maximum(np.ceil(tri.min(axis=1) - 1e-9), 0).astype(np.int64)
    hi = np.minimum(np.floor(tri.max(axis=1) + 1e-9), [height - 1, width - 1]).astype(np.int64)
    nr, nc = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    keep = (nr > 0) & (nc > 0)
    tri, lo, nr, nc = tri[keep], lo[keep], nr[keep], nc[keep]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    good = np.abs(area) > 1e-12  # edge-on triangles cover nothing their neighbours miss
    tri, lo, nr, nc, area = tri[good], lo[good], nr[good], nc[good], area[good]
    counts = nr * nc
    chunk = 4_000_000  # candidate pixels per batch, bounding memory
    start = 0
    bounds = np.concatenate([[0], np.cumsum(counts)])
    while start < len(tri):
        stop = int(np.searchsorted(bounds, bounds[start] + chunk, side="right")) - 1
        stop = max(stop, start + 1)
        sl = slice(start, stop)
        cnt = counts[sl]
        owner = np.repeat(np.arange(start, stop), cnt)
        offset = np.arange(int(cnt.sum())) - np.repeat(bounds[start:stop] - bounds[start], cnt)
        rows = lo[owner, 0] + offset // nc[owner]
        cols = lo[owner, 1] + offset % nc[owner]
        t = tri[owner]
        s = np.sign(area[owner])
        eps = 1e-7 * np.abs(area[owner]) + 1e-9

        def edge(p, q):
            return ((q[:, 0] - p[:, 0]) * (cols - p[:, 1]) - (q[:, 1] - p[:, 1]) * (rows - p[:, 0])) * s

        inside = (edge(t[:, 0], t[:, 1]) >= -eps) & (edge(t[:, 1], t[:, 2]) >= -eps) & (edge(t[:, 2], t[:, 0]) >= -eps)
        image[rows[inside], cols[inside]] = True
        start = stop
    return image


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two bool images of the same shape (1.0 when both are empty)."""
    a = np.asarray(a, bool)
    b = np.asarray(b, bool)
    union = np.logical_or(a, b).sum()
    return 1.0 if union == 0 else float(np.logical_and(a, b).sum() / union)
