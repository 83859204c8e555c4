"""Initial surfaces for a fit.

* :func:`random_surface`: control points uniform in the input's bounding box, clamped
  uniform knots, unit weights (the NURBS-Diff / thesis SB start);
* :func:`plane_sheet`: a flat control net on the best-fitting plane, covering the
  points projected onto it (the thesis's "sheet" cage for open surfaces);
* :func:`cylinder_cage`: a cylinder around the principal axis enclosing the points,
  closed in v with a periodic seam (the thesis's cage for closed shapes);
* :func:`least_squares_surface`: control points by least squares from a plane or
  cylinder parametrisation of the points;
* :func:`initial_surface` picks one by name; ``auto`` means least squares, with the
  topology from :func:`looks_closed`.

All functions take ``points (N, 3)`` and return ``(surface, topology)`` (a
:class:`~nurbskit.fit.params.Topology`: seam closed in v, pole rows); dtype and
device follow ``points``. Randomness only comes from the ``generator`` argument.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..core import NURBSSurface
from ..errors import OptionError
from .lstsq import solve_control_points
from .params import Topology, new_surface, periodic_knots

Tensor = torch.Tensor


def principal_frame(points: Tensor) -> tuple[Tensor, Tensor]:
    """Centroid ``(3,)`` and principal axes ``(3, 3)`` (rows, by decreasing variance)."""
    center = points.mean(dim=0)
    _, _, vt = torch.linalg.svd(points - center, full_matrices=False)
    return center, vt


def plane_frame(points: Tensor) -> tuple[Tensor, Tensor]:
    """Centroid and axes of the best-fitting plane, turned in-plane to the smallest bounding rectangle.

    ``axes[2]`` is the plane normal; ``axes[0]`` and ``axes[1]`` are the sides of the
    minimum-area rectangle around the projected points (rotating calipers on their
    convex hull), so that a rectangular patch gets a rectangular parameter domain
    whatever its orientation (PCA alone would turn a square by 45 degrees).
    """
    center, axes = principal_frame(points)
    xy = ((points - center) @ axes[:2].T).detach().cpu().double().numpy()
    try:
        from scipy.spatial import ConvexHull

        hull = xy[ConvexHull(xy).vertices]
    except Exception:  # degenerate (collinear) projections: keep the PCA axes
        return center, axes
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    best, best_area = 0.0, np.inf
    for a in angles:
        c, s_ = np.cos(a), np.sin(a)
        r = hull @ np.array([[c, -s_], [s_, c]])
        area = np.prod(r.max(0) - r.min(0))
        if area < best_area - 1e-12 * abs(best_area if np.isfinite(best_area) else 1.0):
            best, best_area = a, area
    c, s_ = float(np.cos(best)), float(np.sin(best))
    e0 = c * axes[0] + s_ * axes[1]
    e1 = -s_ * axes[0] + c * axes[1]
    # Longer side first, so u follows the larger extent.
    l0 = ((points - center) @ e0).amax() - ((points - center) @ e0).amin()
    l1 = ((points - center) @ e1).amax() - ((points - center) @ e1).amin()
    if l1 > l0:
        e0, e1 = e1, -e0
    return center, torch.stack([e0, e1, torch.linalg.cross(e0, e1)])


def plane_parameters(points: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Parameters in ``[0, 1]^2`` from the projection onto the best-fitting plane.

    Returns ``(params (N, 2), center (3,), axes (3, 3))`` with the axes of
    :func:`plane_frame`; u follows the longer side of the bounding rectangle.
    """
    center, axes = plane_frame(points)
    xy = (points - center) @ axes[:2].T
    lo, hi = xy.min(dim=0).values, xy.max(dim=0).values
    return (xy - lo) / (hi - lo).clamp_min(1e-12), center, axes


def cylinder_frame(points: Tensor) -> tuple[Tensor, Tensor]:
    """Centre and axes of the cylinder: ``axes[0]`` is the cylinder axis (largest spread)."""
    center, axes = principal_frame(points)
    lo = (points - center) @ axes[0]
    center = center + axes[0] * (lo.max() + lo.min()) / 2
    return center, axes


def cylinder_parameters(points: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``u`` = height along the principal axis in [0, 1]; ``v`` = angle / 2 pi in [0, 1).

    Returns ``(params (N, 2), center (3,), axes (3, 3))``. The angle is measured about
    the axis from a centre that is the mean of the points in each of a few height
    slabs, so bent shapes (a horse) keep a sensible angle.
    """
    center, axes = cylinder_frame(points)
    rel = points - center
    h = rel @ axes[0]
    u = (h - h.min()) / (h.max() - h.min()).clamp_min(1e-12)
    # Slab-wise centres of the cross-sections, interpolated along the height.
    slabs = 8
    idx = (u * slabs).long().clamp(max=slabs - 1)
    xy = rel @ axes[1:].T
    centres = torch.zeros(slabs, 2, dtype=points.dtype, device=points.device)
    counts = torch.zeros(slabs, dtype=points.dtype, device=points.device)
    centres.index_add_(0, idx, xy)
    counts.index_add_(0, idx, torch.ones_like(u))
    centres = torch.where(counts[:, None] > 0, centres / counts.clamp_min(1)[:, None], xy.mean(0))
    local = xy - centres[idx]
    v = torch.remainder(torch.atan2(local[:, 1], local[:, 0]) / (2 * math.pi), 1.0)
    return torch.stack([u, v], dim=-1), center, axes


def looks_closed(points: Tensor, neighbours: int = 8, threshold: float = 0.25) -> bool:
    """Whether a cloud wraps around (closed shape) rather than being a sheet.

    Projects the points onto their best-fitting plane and checks whether the points
    that are close in the projection are also close in 3D: on a sheet they are (the
    3D distance exceeds the projected one only through the sheet's slope); on a closed
    surface the front and back sides overlap in projection. Returns True when more
    than ``threshold`` of the projected neighbours are more than 2.5 times (plus 1 %
    of the bounding-box diagonal) farther away in 3D than in the projection.
    """
    from ..core.neighbors import kdtree

    x = points.detach().cpu().double().numpy()
    if len(x) < neighbours + 2:
        return False
    center = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - center, full_matrices=False)
    xy = (x - center) @ vt[:2].T
    diag = float(np.linalg.norm(x.max(0) - x.min(0)))
    d2, idx = kdtree(xy).query(xy, k=neighbours + 1)
    d3 = np.linalg.norm(x[idx[:, 1:]] - x[:, None, :], axis=-1)
    far = d3 > 2.5 * d2[:, 1:] + 0.01 * diag
    return bool(far.mean() > threshold)


def _grid(n: int, dtype, device) -> Tensor:
    return torch.linspace(0.0, 1.0, n, dtype=dtype, device=device)


def random_surface(points: Tensor, ctrl, degree, generator: torch.Generator | None = None) -> tuple[NURBSSurface, Topology]:
    """Control points uniform in the bounding box of ``points``; open, clamped uniform knots."""
    lo, hi = points.min(dim=0).values, points.max(dim=0).values
    r = torch.rand(ctrl[0], ctrl[1], points.shape[-1], generator=generator, dtype=points.dtype, device="cpu")
    cp = lo + (hi - lo) * r.to(points.device)
    return new_surface(cp, degree, closed_v=False), Topology()


def plane_sheet(points: Tensor, ctrl, degree) -> tuple[NURBSSurface, Topology]:
    """A flat control net on the best-fitting plane over the projected points' rectangle."""
    _, center, axes = plane_parameters(points)
    xy = (points - center) @ axes[:2].T
    lo, hi = xy.min(dim=0).values, xy.max(dim=0).values
    a = lo[0] + (hi[0] - lo[0]) * _grid(ctrl[0], points.dtype, points.device)
    b = lo[1] + (hi[1] - lo[1]) * _grid(ctrl[1], points.dtype, points.device)
    cp = center + a[:, None, None] * axes[0] + b[None, :, None] * axes[1]
    return new_surface(cp, degree, closed_v=False), Topology()


def cylinder_cage(points: Tensor, ctrl, degree) -> tuple[NURBSSurface, Topology]:
    """A cylinder around the principal axis enclosing the points, closed in v.

    The control rows span the points' extent along the axis; the radius is the
    largest distance of a point from the axis, so the cage covers the cloud.
    """
    n_u, n_v = ctrl
    q = degree[1]
    if n_v < 2 * q + 1:
        raise OptionError(f"a cylinder cage with degree {q} in v needs at least {2 * q + 1} control points along v, got {n_v}")
    center, axes = cylinder_frame(points)
    rel = points - center
    h = rel @ axes[0]
    radius = (rel - h[:, None] * axes[0]).norm(dim=-1).max()
    heights = h.min() + (h.max() - h.min()) * _grid(n_u, points.dtype, points.device)
    m = n_v - q
    # Control points on a circle of the knot-spacing angles: the periodic spline then
    # sits slightly inside the control polygon, close to the circle of the radius.
    knots = periodic_knots(n_v, q, dtype=points.dtype, device=points.device)
    greville = torch.stack([knots[j + 1 : j + q + 1].mean() for j in range(m)])
    angle = 2 * math.pi * greville
    ring = torch.cos(angle)[:, None] * axes[1] + torch.sin(angle)[:, None] * axes[2]  # (m, 3)
    cp = center + heights[:, None, None] * axes[0] + radius * ring[None]
    cp = torch.cat([cp, cp[:, :q]], dim=1)
    return new_surface(cp, degree, closed_v=True), Topology(closed_v=True)


def closed_ends(points: Tensor, params: Tensor, ratio: float = 0.6, slab: float = 0.05) -> tuple[bool, bool]:
    """Whether a cylinder-parametrised cloud closes at its ends (``u = 0`` and ``u = 1``).

    An end is closed (a pole) when the points in its last ``slab`` of height spread
    less than ``ratio`` times the widest cross-section around the axis.
    """
    center, axes = cylinder_frame(points)
    rel = points - center
    radial = (rel - (rel @ axes[0])[:, None] * axes[0]).norm(dim=-1)
    u = params[:, 0]
    widest = radial.max()
    out = []
    for sel in (u <= slab, u >= 1 - slab):
        if sel.sum() < 3:
            out.append(True)
            continue
        xy = rel[sel] @ axes[1:].T
        spread = (xy - xy.mean(0)).norm(dim=-1).max()
        out.append(bool(spread < ratio * widest))
    return out[0], out[1]


def least_squares_surface(
    points: Tensor, ctrl, degree, closed_v: bool, smoothness: float = 1e-3, poles: bool = True
) -> tuple[NURBSSurface, Topology]:
    """Least-squares surface from a plane (open) or cylinder (closed) parametrisation.

    A closed cloud whose ends close up (:func:`closed_ends`) gets pole rows, so the
    surface closes there instead of flaring out where data is sparse.
    """
    if closed_v:
        params, _, _ = cylinder_parameters(points)
        template, _ = cylinder_cage(points, ctrl, degree)
        start, end = closed_ends(points, params) if poles else (False, False)
        topo = Topology(closed_v=True, pole_start=start, pole_end=end)
    else:
        params, _, _ = plane_parameters(points)
        template, _ = plane_sheet(points, ctrl, degree)
        topo = Topology()
    cp = solve_control_points(
        params, points, template.knot_vectors, template.degrees, template.sizes, None, topo, smoothness
    )
    return template._replace(control_points=cp), topo


def initial_surface(
    points: Tensor,
    kind: str,
    ctrl,
    degree,
    closed: str = "auto",
    smoothness: float = 1e-3,
    generator: torch.Generator | None = None,
) -> tuple[NURBSSurface, Topology]:
    """The initial surface by name (see the module docstring) and its topology.

    Example:
        >>> import torch
        >>> pts = torch.rand(500, 3, dtype=torch.float64) * torch.tensor([1.0, 1.0, 0.05], dtype=torch.float64)
        >>> surface, topology = initial_surface(pts, "auto", (6, 6), (3, 3))
        >>> surface.sizes, topology.closed_v
        ((6, 6), False)
    """
    if closed not in ("auto", "open", "v"):
        raise OptionError(f"closed must be auto, open or v, got {closed!r}")
    is_closed = looks_closed(points) if closed == "auto" else closed == "v"
    if kind in ("cylinder", "cage", "auto", "lstsq") and is_closed and ctrl[1] < 2 * degree[1] + 1:
        is_closed = False  # too few control points along v to close the seam
    if kind == "random":
        return random_surface(points, ctrl, degree, generator)
    if kind == "plane":
        return plane_sheet(points, ctrl, degree)
    if kind == "cylinder":
        return cylinder_cage(points, ctrl, degree)
    if kind == "cage":
        return cylinder_cage(points, ctrl, degree) if is_closed else plane_sheet(points, ctrl, degree)
    if kind in ("auto", "lstsq"):
        return least_squares_surface(points, ctrl, degree, is_closed, smoothness)
    raise OptionError(f"init must be one of auto, random, plane, cylinder, cage, lstsq, got {kind!r}")
