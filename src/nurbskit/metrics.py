"""What is reported: the thesis's evaluation columns and scale-free surface distances.

Every function here returns plain Python floats (or a dict of them), computed without
gradient in float64, ready for ``json.dump``. The definitions are those of
:mod:`nurbskit.losses`:

* ``chamfer``: mean squared nearest distance, x to y plus y to x (thesis eq. 2.7, averaged);
* ``hausdorff``: symmetric Hausdorff distance, Euclidean, not squared (eq. 2.8);
* ``laplacian``: mean squared umbrella Laplacian of a sampled grid (eq. 2.9, unsupervised);
* ``combined_metric``: ``chamfer + hausdorff + 0.1 * laplacian`` (thesis, Table 6.3).

The raw thesis numbers depend on the scale of the data. :func:`surface_distances` adds
scale-free ones: true point-to-surface distances (projection) and the surface's overshoot
beyond the data, both divided by the diagonal of the input's bounding box.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from . import losses
from .errors import NurbskitError
from .core.neighbors import nearest_neighbors

Tensor = torch.Tensor

#: Output grid used when none is given (the thesis's output resolution, 64 x 64).
DEFAULT_RESOLUTION = (64, 64)

#: Newton starts per point for reported point-to-surface distances (``project_points``'
#: ``starts``). One start follows the basin of the nearest grid sample, and where a surface
#: folds back or passes through itself that sample can lie on the other sheet: on the
#: thesis duck fitted exactly (SC), 10 of 4,096 of its own points came out up to 0.031 from
#: the surface (diagonal 5.7) with one start, at every default or finer grid up to 384^2,
#: and none with four. Not always enough: near the poles of make demo's fit
#: (``tests/data/pole_seam_fit.json``) 2 of its 4,096 grid points stay up to 0.0055 off
#: with four (62 with one, none with eight, at twice the cost of four).
REPORT_STARTS = 4


def _cloud(points, name: str = "points", like: Tensor | None = None) -> Tensor:
    t = points if isinstance(points, Tensor) else torch.as_tensor(np.asarray(points, dtype=np.float64))
    device = like.device if like is not None else t.device
    t = t.detach().to(dtype=torch.float64, device=device)
    if t.ndim < 2:
        raise NurbskitError(f"{name} must have shape (N, D), got {tuple(t.shape)}")
    if t.shape[-2] == 0:
        raise NurbskitError(f"{name} is empty (shape {tuple(t.shape)}); need at least one point")
    return t


def chamfer(x, y) -> float:
    """Chamfer distance as a float: :func:`nurbskit.losses.chamfer_distance`, ``reduction="mean"``.

    Shapes: ``x (N, D)``, ``y (M, D)`` (tensors or arrays) -> float.

    Example:
        >>> round(chamfer([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [1.0, 1.0], [3.0, 0.0]]), 6)
        2.166667
    """
    with torch.no_grad():
        return float(losses.chamfer_distance(_cloud(x, "x"), _cloud(y, "y")))


def hausdorff(x, y) -> float:
    """Symmetric Hausdorff distance (Euclidean, not squared) as a float.

    Shapes: ``x (N, D)``, ``y (M, D)`` -> float.

    Example:
        >>> hausdorff([[0.0, 0.0]], [[3.0, 4.0]])
        5.0
    """
    with torch.no_grad():
        return float(losses.hausdorff_distance(_cloud(x, "x"), _cloud(y, "y")))


def _strip_seam(grid: Tensor, axis: int, max_repeat: int) -> Tensor:
    """Drop trailing rows along ``axis`` that repeat the leading ones (a closed seam)."""
    n = grid.shape[axis]
    scale = float(grid.abs().max()) if grid.numel() else 0.0
    for k in range(min(max_repeat, n - 1), 0, -1):
        if torch.allclose(grid.narrow(axis, n - k, k), grid.narrow(axis, 0, k), rtol=0, atol=1e-7 * (scale or 1.0)):
            return grid.narrow(axis, 0, n - k)
    return grid


def _closed_grid(grid: Tensor, closed_u: bool, closed_v: bool, repeat: tuple[int, int] = (1, 1)) -> Tensor:
    if closed_u:
        grid = _strip_seam(grid, -3, repeat[0])
    if closed_v:
        grid = _strip_seam(grid, -2, repeat[1])
    return grid


def laplacian(
    grid,
    resolution: int | Sequence[int] | None = None,
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
) -> float:
    """Mean squared umbrella Laplacian of a grid of points, as a float.

    ``grid`` is either points ``(R, S, D)`` or a ``NURBSSurface``, which is sampled on a
    uniform ``resolution`` grid first (default 64 x 64, the thesis's output grid).

    Convention: this is :func:`nurbskit.losses.laplacian_grid` (mean over nodes, boundary
    rule ``boundary``). With ``closed_u`` / ``closed_v`` the direction wraps, and a last
    row (column) that repeats the first, as a sampled closed surface has, is dropped
    first. The per-node value scales like ``h^4`` with the grid spacing, so compare it
    only at equal resolution.

    Example:
        >>> import torch
        >>> laplacian(torch.zeros(8, 8, 3))
        0.0
    """
    with torch.no_grad():
        if hasattr(grid, "sample"):
            grid = grid.detach().sample(DEFAULT_RESOLUTION if resolution is None else resolution)
        g = grid if isinstance(grid, Tensor) else torch.as_tensor(np.asarray(grid, dtype=np.float64))
        g = _closed_grid(g.detach().to(torch.float64), closed_u, closed_v)
        return float(losses.laplacian_grid(g, closed_u=closed_u, closed_v=closed_v, boundary=boundary))


def combined_metric(chamfer: float, hausdorff: float, laplacian: float) -> float:
    """The thesis's combined evaluation metric: ``chamfer + hausdorff + 0.1 * laplacian``.

    Example:
        >>> combined_metric(0.5, 1.0, 2.0)
        1.7
    """
    return float(chamfer) + float(hausdorff) + 0.1 * float(laplacian)


def bbox_diagonal(points) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points (*, N, D)``.

    All leading dimensions are pooled. Example:
        >>> bbox_diagonal([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [1.0, 1.0, 0.0]])
        5.0
    """
    p = _cloud(points)
    p = p.reshape(-1, p.shape[-1])
    return float((p.amax(0) - p.amin(0)).norm())


def _summary(values: Tensor, scale: float, prefix: str) -> dict:
    v = values.detach().cpu().double().numpy() / scale
    return {
        f"{prefix}_mean": float(v.mean()),
        f"{prefix}_p95": float(np.percentile(v, 95)),
        f"{prefix}_max": float(v.max()),
    }


def _check_surface(surface, points: Tensor) -> None:
    if getattr(surface, "para_dim", None) != 2:
        raise NurbskitError(f"expected a NURBSSurface, got {type(surface).__name__}")
    if points.ndim != 2:
        raise NurbskitError(f"points must have shape (N, D), got {tuple(points.shape)}")
    if points.shape[-1] != surface.dim:
        raise NurbskitError(
            f"points have dimension {points.shape[-1]} but the surface has dimension {surface.dim}"
        )


def point_distances(surface, points, **project_options) -> Tensor:
    """Distance ``(N,)`` from each of ``points (N, D)`` to ``surface``, by true projection
    (:func:`nurbskit.core.project.project_points`, float64, no gradient), with
    :data:`REPORT_STARTS` starts per point unless ``starts`` is given; extra keyword
    arguments go to ``project_points``. What every report's input-to-surface numbers and
    error maps are made of.

    Example:
        >>> import torch, nurbskit
        >>> g = torch.linspace(0, 1, 4, dtype=torch.float64)
        >>> u, v = torch.meshgrid(g, g, indexing="ij")
        >>> plane = nurbskit.NURBSSurface(torch.stack([u, v, 0 * u], -1), degrees=(3, 3))
        >>> point_distances(plane, [[0.5, 0.5, 2.0], [0.25, 0.0, -1.0]])
        tensor([2., 1.], dtype=torch.float64)
    """
    from .core.project import project_points

    with torch.no_grad():
        s64 = surface.detach().to(torch.float64)
        pts = _cloud(points, like=s64.control_points)
        _check_surface(surface, pts)
        project_options.setdefault("starts", REPORT_STARTS)
        _, closest, _ = project_points(s64, pts, **project_options)
        return ((pts - closest) ** 2).sum(-1).sqrt()


def surface_distances(
    surface,
    points,
    resolution: int | Sequence[int] = DEFAULT_RESOLUTION,
    *,
    samples: Tensor | None = None,
    to_surface: Tensor | None = None,
    **project_options,
) -> dict:
    """Scale-free distances between a surface and the points it should fit.

    * ``to_surface_*``: distance from each input point to the surface, by true projection
      (:func:`point_distances`); says how well the data is covered.
    * ``overshoot_*``: distance from each sample of the surface on a uniform
      ``resolution`` grid to the nearest input point; says where the surface runs
      beyond the data (flaps, bulges between points).

    Each comes as ``_mean``, ``_p95`` (95th percentile, linear interpolation) and ``_max``,
    divided by ``diagonal``, the bounding-box diagonal of ``points``, also returned
    (unnormalised). All values are floats.

    Shapes: ``points (N, D)`` with ``D == surface.dim``. ``samples (R, S, D)`` may pass
    a grid already evaluated at ``resolution``, and ``to_surface (N,)`` the distances of
    :func:`point_distances` already computed (a report that needs them per point too).
    Extra keyword arguments go to ``project_points`` (through :func:`point_distances`).

    Convention: computed in float64 without gradient. Points that span no extent
    (diagonal 0) raise ``NurbskitError``: there is no scale to normalise by.

    Example:
        >>> import torch, nurbskit
        >>> g = torch.linspace(0, 1, 4, dtype=torch.float64)
        >>> u, v = torch.meshgrid(g, g, indexing="ij")
        >>> plane = nurbskit.NURBSSurface(torch.stack([u, v, 0 * u], -1), degrees=(3, 3))
        >>> d = surface_distances(plane, plane.sample((10, 10)).reshape(-1, 3), (10, 10))
        >>> round(d["diagonal"], 6), d["to_surface_max"] < 1e-9, d["overshoot_max"] < 1e-9
        (1.414214, True, True)
    """
    with torch.no_grad():
        s64 = surface.detach().to(torch.float64)
        pts = _cloud(points, like=s64.control_points)
        _check_surface(surface, pts)
        diag = bbox_diagonal(pts)
        if not diag > 0:
            raise NurbskitError(
                f"the {pts.shape[0]} input points span no extent (bounding-box diagonal {diag}); "
                "normalised distances are undefined"
            )
        if to_surface is None:
            to_surface = point_distances(s64, pts, **project_options)
        else:
            to_surface = to_surface.detach().to(pts).reshape(-1)
            if to_surface.shape[0] != pts.shape[0]:
                raise NurbskitError(f"to_surface must hold one distance per point ({pts.shape[0]}), "
                                    f"got {to_surface.shape[0]}")
        grid = s64.sample(resolution) if samples is None else samples.detach().to(pts)
        sq, _ = nearest_neighbors(grid.reshape(-1, pts.shape[-1]), pts)
        overshoot = sq.sqrt()
    out = {"diagonal": diag}
    out.update(_summary(to_surface, diag, "to_surface"))
    out.update(_summary(overshoot, diag, "overshoot"))
    return out


def evaluate_fit(
    surface,
    points,
    resolution: int | Sequence[int] = DEFAULT_RESOLUTION,
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
    to_surface: Tensor | None = None,
    **project_options,
) -> dict:
    """All reported numbers for a fitted surface against its input points.

    The surface is sampled on a uniform ``resolution`` grid ``(R, S)`` (default 64 x 64,
    as in the thesis). Returns a dict of floats:

    * ``chamfer``, ``hausdorff``: between the ``R * S`` samples and ``points``;
    * ``laplacian``: of the sample grid (:func:`laplacian`; ``closed_*``, ``boundary``);
    * ``combined``: ``chamfer + hausdorff + 0.1 * laplacian`` (thesis, Table 6.3);
    * ``laplacian_control``: the same energy on the control net (the thesis's variant;
      for a closed direction the control rows repeated at the seam are dropped first);
    * ``diagonal``, ``to_surface_{mean,p95,max}``, ``overshoot_{mean,p95,max}`` from
      :func:`surface_distances` (``to_surface``: the per-point distances, if already computed).

    Shapes: ``points (N, D)`` with ``D == surface.dim``.

    Example:
        >>> import json, torch, nurbskit
        >>> s = nurbskit.NURBSSurface(torch.rand(5, 5, 3, dtype=torch.float64), degrees=(3, 3))
        >>> report = evaluate_fit(s, s.sample((20, 20)).reshape(-1, 3), (20, 20))
        >>> report["chamfer"] < 1e-12 and len(json.dumps(report)) > 0
        True
    """
    if isinstance(resolution, int):
        resolution = (resolution, resolution)
    with torch.no_grad():
        s64 = surface.detach().to(torch.float64)
        pts = _cloud(points, like=s64.control_points)
        _check_surface(surface, pts)
        grid = s64.sample(tuple(resolution))
        flat = grid.reshape(-1, pts.shape[-1])
        opts = dict(closed_u=closed_u, closed_v=closed_v, boundary=boundary)
        out = {
            "chamfer": chamfer(flat, pts),
            "hausdorff": hausdorff(flat, pts),
            "laplacian": laplacian(grid, **opts),
        }
        out["combined"] = combined_metric(out["chamfer"], out["hausdorff"], out["laplacian"])
        # a closed net repeats 1 (clamped) to p (periodic) rows at the seam: drop them
        net = _closed_grid(s64.control_points, closed_u, closed_v, s64.degrees)
        out["laplacian_control"] = float(losses.laplacian_control(net, **opts))
        out.update(surface_distances(s64, pts, resolution, samples=grid, to_surface=to_surface, **project_options))
    return out


__all__ = [
    "chamfer", "hausdorff", "laplacian", "combined_metric", "bbox_diagonal",
    "point_distances", "surface_distances", "evaluate_fit", "DEFAULT_RESOLUTION", "REPORT_STARTS",
]
