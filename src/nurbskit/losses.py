"""What is minimised: L2, Chamfer, Hausdorff, Laplacian and point-to-surface losses.

Each loss is a function on tensors plus a thin ``nn.Module`` that only stores its
settings (kornia's layout). Definitions follow the thesis this project grew from
(section 2.8, equations 2.6-2.9, and section 5.1 for the three uses of the Laplacian):

* L2 (eq. 2.6): ``1/N sum_i ||x_i - y_i||^2`` for two clouds in the same order.
* Chamfer (eq. 2.7): squared nearest distances in both directions; eq. 2.7 sums them,
  ``reduction="mean"`` (the default here and the scale of the thesis's tables) averages
  each direction before adding the two.
* Hausdorff (eq. 2.8): the larger of the two directed maxima of the (not squared)
  Euclidean nearest distance.
* Laplacian (eq. 2.9): ``1/N sum_i ||L(x_i) - L(y_i)||^2`` with the umbrella operator
  ``L`` on a grid; supervised (predicted against true control grid, as in SplineNet),
  on the output grid, or on the control grid (the thesis's "variant").
* Point-to-surface: true distance by projection (:func:`nurbskit.core.project.project_points`).

Nearest neighbours are found without gradient (:mod:`nurbskit.core.neighbors`)
and the distances recomputed by gathering, so gradients are exact wherever each
nearest neighbour is unique, and memory stays ``O(N + M)`` on CPU.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .errors import NurbskitError
from .core.neighbors import NeighborIndex, nearest_neighbors

Tensor = torch.Tensor

_REDUCTIONS = ("mean", "sum", "none")
_BOUNDARIES = ("edge", "interior", "zeros")


# ---- helpers -----------------------------------------------------------------------

def _check_reduction(reduction: str, allowed=_REDUCTIONS) -> None:
    if reduction not in allowed:
        raise NurbskitError(f"reduction must be one of {list(allowed)}, got {reduction!r}")


def _reduce(values: Tensor, reduction: str, dims) -> Tensor:
    if reduction == "mean":
        return values.mean(dim=dims)
    if reduction == "sum":
        return values.sum(dim=dims)
    return values


def _check_cloud(name: str, t, min_dim: int = 2) -> None:
    if not isinstance(t, Tensor):
        raise NurbskitError(f"{name} must be a tensor, got {type(t).__name__}")
    if t.ndim < min_dim:
        shape = "(*, N, D)" if min_dim == 2 else "(*, R, S, D)"
        raise NurbskitError(f"{name} must have shape {shape}, got {tuple(t.shape)}")
    if not t.is_floating_point():
        raise NurbskitError(f"{name} must be a floating-point tensor, got {t.dtype}")


def _gathered_sq_dist(query: Tensor, reference: Tensor, index: Tensor) -> Tensor:
    """``||query_i - reference[index_i]||^2`` with autograd: ``(*, N, D)`` -> ``(*, N)``."""
    d = query.shape[-1]
    nearest = torch.gather(reference, -2, index.unsqueeze(-1).expand(*index.shape, d))
    return ((query - nearest) ** 2).sum(-1)


def _directed_sq_dists(x: Tensor, y: Tensor, y_index: NeighborIndex | None = None) -> tuple[Tensor, Tensor]:
    _check_cloud("x", x)
    _check_cloud("y", y)
    if x.shape[-2] == 0 or y.shape[-2] == 0:
        raise NurbskitError(
            f"both point clouds need at least one point; got x {tuple(x.shape)} and y {tuple(y.shape)}"
        )
    if y_index is not None:
        ref = y_index.reference  # y detached: the same storage
        if x.ndim != 2 or ref.shape != y.shape or ref.data_ptr() != y.data_ptr():
            raise NurbskitError(
                f"y_index must be a NeighborIndex built on y itself, and x one (N, D) cloud; got x "
                f"{tuple(x.shape)}, y {tuple(y.shape)}, an index on {tuple(y_index.reference.shape)}"
            )
        ix = y_index.indices(x)
        _, iy = nearest_neighbors(y, x)
        return _gathered_sq_dist(x, y, ix), _gathered_sq_dist(y, x, iy)
    try:
        batch = np.broadcast_shapes(x.shape[:-2], y.shape[:-2])  # torch's imports sympy (0.3 s)
    except ValueError:
        raise NurbskitError(
            f"the batch shapes of x {tuple(x.shape)} and y {tuple(y.shape)} do not broadcast"
        ) from None
    x = x.expand(*batch, *x.shape[-2:])
    y = y.expand(*batch, *y.shape[-2:])
    _, ix = nearest_neighbors(x, y)
    _, iy = nearest_neighbors(y, x)
    return _gathered_sq_dist(x, y, ix), _gathered_sq_dist(y, x, iy)


def _safe_sqrt(t: Tensor) -> Tensor:
    # sqrt with a zero (sub)gradient at 0 instead of inf/NaN.
    tiny = torch.finfo(t.dtype).tiny
    return torch.where(t > 0, t.clamp_min(tiny).sqrt(), torch.zeros_like(t))


# ---- L2 -------------------------------------------------------------------------------

def l2_loss(pred: Tensor, target: Tensor, reduction: str = "mean") -> Tensor:
    """Mean squared point distance between two clouds in the same order (thesis eq. 2.6).

    ``L2(X, Y) = 1/N sum_i ||x_i - y_i||_2^2``.

    Shapes: ``pred (*, N, D)``, ``target (*, N, D)`` (broadcastable) -> ``(*)`` for
    ``"mean"`` and ``"sum"``, ``(*, N)`` squared distances for ``"none"``.

    Convention: the squared Euclidean distance is summed over the D coordinates and
    averaged over the N points only. This is D times ``torch.nn.functional.mse_loss``,
    which also averages over coordinates. Grids ``(*, R, S, D)`` count as ``(*, R*S, D)``
    after ``flatten(-3, -2)``; the point order is the correspondence.

    Example:
        >>> import torch
        >>> l2_loss(torch.zeros(2, 3), torch.tensor([[1., 0., 0.], [1., 1., 1.]]))
        tensor(2.)
    """
    _check_cloud("pred", pred)
    _check_cloud("target", target)
    _check_reduction(reduction)
    try:
        diff = pred - target
    except RuntimeError:
        raise NurbskitError(
            f"pred {tuple(pred.shape)} and target {tuple(target.shape)} must have the same shape (*, N, D)"
        ) from None
    if pred.shape[-2:] != target.shape[-2:]:
        raise NurbskitError(
            f"L2 needs clouds of the same size and order; got pred {tuple(pred.shape)} and target "
            f"{tuple(target.shape)} (use chamfer_distance for unordered clouds)"
        )
    return _reduce((diff**2).sum(-1), reduction, -1)


# ---- Chamfer --------------------------------------------------------------------------

def chamfer_distance(
    x: Tensor,
    y: Tensor,
    reduction: str = "mean",
    return_parts: bool = False,
    y_index: NeighborIndex | None = None,
) -> Tensor | tuple[Tensor, Tensor, Tensor]:
    """Symmetric Chamfer distance of squared nearest distances (thesis eq. 2.7).

    ``CD(X, Y) = A(min_y ||x - y||^2 over x in X) + A(min_x ||x - y||^2 over y in Y)``
    where ``A`` is the mean (``reduction="mean"``) or the sum (``"sum"``, exactly eq. 2.7).

    Shapes: ``x (*, N, D)``, ``y (*, M, D)`` with batch shapes that broadcast (one cloud
    against a batch of clouds); N and M may differ -> ``(*)``. With ``return_parts=True`` returns ``(total, x_to_y, y_to_x)``,
    each ``(*)``. ``y_index``: a :class:`~nurbskit.core.neighbors.NeighborIndex` built on
    ``y`` (one ``(M, D)`` cloud, against one ``(N, D)`` cloud ``x``), for a ``y`` that stays
    fixed over many calls (a fitting target): its KD-tree is built once, not per call;
    the result is the same.

    Convention: nearest neighbours are found without gradient (KD-tree on CPU, chunked
    cdist on CUDA) and the squared distances recomputed by gathering, so the gradient
    with respect to both clouds is exact wherever each nearest neighbour is unique.
    Memory is ``O(N + M)`` on CPU. Both clouds must be non-empty. Nothing is read back
    to the host as a torch operation (the KD-tree works on the CPU copy it searches;
    on CUDA the tiled search stays on the device).

    Example:
        >>> import torch
        >>> x = torch.tensor([[0., 0.], [1., 0.]])
        >>> y = torch.tensor([[0., 0.], [1., 1.], [3., 0.]])
        >>> chamfer_distance(x, y)  # (0 + 1)/2 + (0 + 1 + 4)/3
        tensor(2.1667)
    """
    _check_reduction(reduction, ("mean", "sum"))
    dx, dy = _directed_sq_dists(x, y, y_index)
    px, py = _reduce(dx, reduction, -1), _reduce(dy, reduction, -1)
    total = px + py
    return (total, px, py) if return_parts else total


def chamfer_distance_naive(x: Tensor, y: Tensor, reduction: str = "mean") -> Tensor:
    """Brute-force oracle for :func:`chamfer_distance`: an N x M Python loop, ``(N, D)``, ``(M, D)`` -> ``()``.

    Example:
        >>> import torch
        >>> chamfer_distance_naive(torch.zeros(1, 2), torch.ones(1, 2))
        tensor(4.)
    """

    def directed(a, b):
        best = []
        for i in range(a.shape[0]):
            best.append(torch.stack([((a[i] - b[j]) ** 2).sum() for j in range(b.shape[0])]).min())
        return torch.stack(best)

    dx, dy = directed(x, y), directed(y, x)
    agg = torch.mean if reduction == "mean" else torch.sum
    return agg(dx) + agg(dy)


# ---- Hausdorff ------------------------------------------------------------------------

def hausdorff_distance(
    x: Tensor,
    y: Tensor,
    squared: bool = False,
    return_parts: bool = False,
    y_index: NeighborIndex | None = None,
) -> Tensor | tuple[Tensor, Tensor, Tensor]:
    """Symmetric Hausdorff distance (thesis eq. 2.8), not squared by default.

    ``HD(X, Y) = max(max_x min_y ||x - y||, max_y min_x ||x - y||)``.

    Shapes: ``x (*, N, D)``, ``y (*, M, D)`` -> ``(*)``. With ``return_parts=True``
    returns ``(total, x_to_y, y_to_x)`` with the two directed distances. ``y_index`` as
    for :func:`chamfer_distance`.

    Convention: the thesis uses the Euclidean distance (``squared=False``); with
    ``squared=True`` every value is the square of that. The gradient reaches the
    point(s) realising the maximum and their gathered neighbours (``amax`` shares it
    evenly between tied maxima); at distance 0 the gradient is 0, not NaN.

    Example:
        >>> import torch
        >>> x = torch.tensor([[0., 0.], [1., 0.]])
        >>> y = torch.tensor([[0., 0.], [1., 1.], [3., 0.]])
        >>> hausdorff_distance(x, y)
        tensor(2.)
    """
    dx, dy = _directed_sq_dists(x, y, y_index)
    hx, hy = dx.amax(-1), dy.amax(-1)
    if not squared:
        hx, hy = _safe_sqrt(hx), _safe_sqrt(hy)
    total = torch.maximum(hx, hy)
    return (total, hx, hy) if return_parts else total


def hausdorff_distance_naive(x: Tensor, y: Tensor, squared: bool = False) -> Tensor:
    """Brute-force oracle for :func:`hausdorff_distance` on ``(N, D)``, ``(M, D)`` -> ``()``.

    Example:
        >>> import torch
        >>> hausdorff_distance_naive(torch.zeros(1, 2), torch.tensor([[3., 4.]]))
        tensor(5.)
    """
    best = 0.0
    for a, b in ((x.detach(), y.detach()), (y.detach(), x.detach())):
        for i in range(a.shape[0]):
            nearest = min(float(((a[i] - b[j]) ** 2).sum()) for j in range(b.shape[0]))
            best = max(best, nearest)
    value = best if squared else best**0.5
    return torch.tensor(value, dtype=x.dtype)


# ---- Laplacian ------------------------------------------------------------------------

def _second_difference(points: Tensor, axis: int, closed: bool) -> Tensor:
    """``(prev + next)/2 - x`` along ``axis`` (-3: u, -2: v); open axes lose both end nodes."""
    if closed:
        return 0.5 * (points.roll(1, axis) + points.roll(-1, axis)) - points
    n = points.shape[axis]
    prev = points.narrow(axis, 0, n - 2)
    here = points.narrow(axis, 1, n - 2)
    nxt = points.narrow(axis, 2, n - 2)
    return 0.5 * (prev + nxt) - here


def grid_laplacian(
    points: Tensor,
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
) -> Tensor:
    """Discrete umbrella Laplacian of a grid of points.

    ``L(x_ij) = (x_{i-1,j} + x_{i+1,j} + x_{i,j-1} + x_{i,j+1}) / 4 - x_ij``: the
    mean of the four grid neighbours minus the point (SplineNet's 3 x 3 filter, up to
    its sign). On a regular grid of spacing ``(h_u, h_v)`` it approximates
    ``(h_u^2 x_uu + h_v^2 x_vv) / 4``; it is zero on any affine (e.g. planar, regularly
    spaced) grid and equals ``(a h_u^2 + b h_v^2) / 2`` on ``z = a u^2 + b v^2``.

    Shapes: ``points (*, R, S, D)`` (u along R) -> ``(*, R, S, D)`` for ``"edge"`` and
    ``"zeros"``, ``(*, R', S', D)`` for ``"interior"`` with ``R' = R - 2`` (``R`` if
    closed in u) and likewise ``S'``.

    Convention (boundary rule, for open directions):

    * ``"edge"`` (default): ``L = ((x_prev + x_next)/2 - x)_u / 2 + (...)_v / 2`` where a
      direction contributes only if the node has both neighbours in it. Interior nodes
      get the umbrella; edge nodes the second difference along the edge, halved;
      corners 0. Translation invariant, zero on affine grids everywhere, and it does
      not pull the boundary inward.
    * ``"interior"``: only nodes with all four neighbours are returned.
    * ``"zeros"``: the missing neighbours are zero vectors (SplineNet / the thesis's
      ``conv2d(..., padding=1)``). Not translation invariant: boundary nodes are pulled
      towards the origin. Kept to reproduce those numbers.

    ``closed_u`` / ``closed_v`` wrap the seam: row ``R - 1`` neighbours row 0. A grid
    that repeats the seam (first row equal to the last, as ``surface.sample`` gives
    for a clamped closed surface) should be passed without its last row.

    Example:
        >>> import torch
        >>> u, v = torch.meshgrid(torch.linspace(0, 1, 5), torch.linspace(0, 2, 4), indexing="ij")
        >>> plane = torch.stack([u, v, 3 * u - v + 1], dim=-1)
        >>> grid_laplacian(plane).abs().max() < 1e-6
        tensor(True)
    """
    _check_cloud("points", points, min_dim=3)
    if boundary not in _BOUNDARIES:
        raise NurbskitError(f"boundary must be one of {list(_BOUNDARIES)}, got {boundary!r}")
    r, s = points.shape[-3], points.shape[-2]
    need_u, need_v = (1 if closed_u else 3), (1 if closed_v else 3)
    if boundary == "interior" and (r < need_u or s < need_v):
        raise NurbskitError(
            f"an interior Laplacian needs at least {need_u} x {need_v} grid nodes, got {r} x {s} "
            f"(points {tuple(points.shape)})"
        )
    if r < 1 or s < 1:
        raise NurbskitError(f"grid must have at least one node, got {r} x {s}")

    if boundary == "zeros":
        pad = points
        if not closed_u:
            z = pad.new_zeros(pad.shape[:-3] + (1,) + pad.shape[-2:])
            pad = torch.cat([z, pad, z], dim=-3)
        if not closed_v:
            z = pad.new_zeros(pad.shape[:-2] + (1, pad.shape[-1]))
            pad = torch.cat([z, pad, z], dim=-2)
        lu = _second_difference(pad, -3, closed_u)
        lv = _second_difference(pad, -2, closed_v)
        if not closed_u:
            lv = lv[..., 1:-1, :, :]
        if not closed_v:
            lu = lu[..., :, 1:-1, :]
        return 0.5 * (lu + lv)

    lu = _second_difference(points, -3, closed_u) if (closed_u or r >= 3) else None
    lv = _second_difference(points, -2, closed_v) if (closed_v or s >= 3) else None
    if boundary == "interior":
        if not closed_v:
            lu = lu[..., :, 1:-1, :]
        if not closed_u:
            lv = lv[..., 1:-1, :, :]
        return 0.5 * (lu + lv)

    out = torch.zeros_like(points)
    if lu is not None:
        out = out + 0.5 * (lu if closed_u else nn.functional.pad(lu, (0, 0, 0, 0, 1, 1)))
    if lv is not None:
        out = out + 0.5 * (lv if closed_v else nn.functional.pad(lv, (0, 0, 1, 1)))
    return out


def grid_laplacian_naive(points: Tensor, closed_u: bool = False, closed_v: bool = False) -> Tensor:
    """Loop oracle for :func:`grid_laplacian` with ``boundary="edge"``: ``(R, S, D)`` -> ``(R, S, D)``.

    Example:
        >>> import torch
        >>> grid_laplacian_naive(torch.zeros(3, 3, 1))[1, 1]
        tensor([0.])
    """
    r, s, _ = points.shape
    out = torch.zeros_like(points)
    for i in range(r):
        for j in range(s):
            acc = torch.zeros_like(points[i, j])
            if closed_u or 0 < i < r - 1:
                acc = acc + 0.5 * (0.5 * (points[(i - 1) % r, j] + points[(i + 1) % r, j]) - points[i, j])
            if closed_v or 0 < j < s - 1:
                acc = acc + 0.5 * (0.5 * (points[i, (j - 1) % s] + points[i, (j + 1) % s]) - points[i, j])
            out[i, j] = acc
    return out


def _laplacian_energy(lap: Tensor, reduction: str) -> Tensor:
    sq = (lap**2).sum(-1)  # ||L(x_i)||^2 per node
    if reduction == "none":
        return sq
    return _reduce(sq.flatten(-2), reduction, -1)


def laplacian_supervised(
    pred_ctrl: Tensor,
    true_ctrl: Tensor,
    reduction: str = "mean",
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
) -> Tensor:
    """Laplacian matching loss between a predicted and a true grid (thesis eq. 2.9, SplineNet).

    ``1/N sum_i ||L(p_i) - L(t_i)||^2`` over the N grid nodes, with ``L`` the umbrella
    operator of :func:`grid_laplacian` (same ``closed_*`` and ``boundary`` options).

    Shapes: ``pred_ctrl (*, n_u, n_v, D)``, ``true_ctrl (*, n_u, n_v, D)`` -> ``(*)``
    (``"none"``: ``(*, n_u', n_v')`` per node).

    Convention: "mean" averages over the nodes the boundary rule returns and sums over
    the D coordinates (SplineNet sums over channels and averages over nodes).
    Because ``L`` is linear this is the Laplacian energy of ``pred - true``.

    Example:
        >>> import torch
        >>> t = torch.arange(48.0).reshape(4, 4, 3) ** 2
        >>> laplacian_supervised(t + 1.0, t)  # a translation has the same Laplacian
        tensor(0.)
    """
    _check_reduction(reduction)
    _check_cloud("pred_ctrl", pred_ctrl, 3)
    _check_cloud("true_ctrl", true_ctrl, 3)
    if pred_ctrl.shape[-3:] != true_ctrl.shape[-3:]:
        raise NurbskitError(
            f"predicted and true control grids must have the same shape (n_u, n_v, D); got "
            f"{tuple(pred_ctrl.shape)} and {tuple(true_ctrl.shape)}"
        )
    opts = dict(closed_u=closed_u, closed_v=closed_v, boundary=boundary)
    diff = grid_laplacian(pred_ctrl, **opts) - grid_laplacian(true_ctrl, **opts)
    return _laplacian_energy(diff, reduction)


def laplacian_grid(
    points: Tensor,
    reduction: str = "mean",
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
) -> Tensor:
    """Unsupervised Laplacian energy of the output grid (the thesis's "normal" UCDL).

    ``1/N sum_i ||L(x_i)||^2`` over the nodes of an evaluated grid of surface points,
    ``L`` from :func:`grid_laplacian`. Penalises second differences of the sampled
    surface: noise, wiggles and uneven parametric spacing.

    Shapes: ``points (*, R, S, D)`` -> ``(*)`` (``"none"``: ``(*, R', S')``).

    Convention: "mean" averages over nodes (eq. 2.9). The thesis's Listing 5.2 sums
    over nodes instead (``reduction="sum"``). For a smooth surface the per-node value
    scales like ``h^4``: compare values only at equal resolution.

    Example:
        >>> import torch
        >>> g = torch.zeros(5, 5, 3); g[2, 2, 2] = 1.0   # one bump
        >>> laplacian_grid(g, reduction="sum")  # centre 1 + four neighbours (1/4)^2
        tensor(1.2500)
    """
    _check_reduction(reduction)
    return _laplacian_energy(grid_laplacian(points, closed_u=closed_u, closed_v=closed_v, boundary=boundary), reduction)


def laplacian_control(
    control_points,
    reduction: str = "mean",
    *,
    closed_u: bool = False,
    closed_v: bool = False,
    boundary: str = "edge",
) -> Tensor:
    """Unsupervised Laplacian energy of the control grid (the thesis's "variant" UCDL).

    Same as :func:`laplacian_grid` applied to the control net: smooths the control
    polygon itself, which keeps control points close to the surface they shape.

    Shapes: ``control_points (*, n_u, n_v, D)`` or a ``NURBSSurface`` (its
    ``control_points`` are used; weights are ignored) -> ``(*)``.

    Example:
        >>> import torch
        >>> u, v = torch.meshgrid(torch.arange(4.0), torch.arange(5.0), indexing="ij")
        >>> laplacian_control(torch.stack([u, v, 0 * u], -1))  # a flat regular net
        tensor(0.)
    """
    cp = getattr(control_points, "control_points", control_points)
    return laplacian_grid(cp, reduction, closed_u=closed_u, closed_v=closed_v, boundary=boundary)


# ---- point to surface -----------------------------------------------------------------

def point_to_surface_distance(
    surface,
    points: Tensor,
    reduction: str = "mean",
    squared: bool = True,
    **project_options,
) -> Tensor:
    """Distance from points to a NURBS surface by true projection (DESIGN.md item 5).

    Each point is projected with :func:`nurbskit.core.project.project_points` (Newton on
    the foot-point parameters, without gradient); the distance to the foot point is then
    recomputed with autograd at the fixed parameters. By the envelope theorem this is
    the exact gradient of the distance with respect to the surface's control points,
    weights and knots (and to the points), wherever the foot point is unique.

    Shapes: ``points (*, N, D)`` -> ``(*)`` (``"none"``: ``(*, N)``).

    Convention: ``squared=True`` (default) uses ``||p - S(u*, v*)||^2``; ``squared=False``
    the Euclidean distance (zero gradient at distance 0). Extra keyword arguments go to
    ``project_points`` (``grid``, ``iterations``, ``tol``).

    Example:
        >>> import torch, nurbskit
        >>> u, v = torch.meshgrid(torch.linspace(0, 1, 4), torch.linspace(0, 1, 4), indexing="ij")
        >>> plane = nurbskit.NURBSSurface(torch.stack([u, v, 0 * u], -1), degrees=(3, 3))
        >>> point_to_surface_distance(plane, torch.tensor([[0.5, 0.5, 2.0]]))
        tensor(4.)
    """
    from .core.project import project_points

    _check_reduction(reduction)
    _check_cloud("points", points)
    if points.shape[-1] != surface.dim:
        raise NurbskitError(
            f"points have dimension {points.shape[-1]} but the surface has dimension {surface.dim}"
        )
    _, closest, _ = project_points(surface, points, **project_options)
    sq = ((points - closest) ** 2).sum(-1)
    values = sq if squared else _safe_sqrt(sq)
    return _reduce(values, reduction, -1)


# ---- modules --------------------------------------------------------------------------

class L2Loss(nn.Module):
    """Module form of :func:`l2_loss`; ``forward(pred (*, N, D), target (*, N, D))``."""

    def __init__(self, reduction: str = "mean"):
        super().__init__()
        _check_reduction(reduction)
        self.reduction = reduction

    def forward(self, pred: Tensor, target: Tensor) -> Tensor:
        return l2_loss(pred, target, self.reduction)


class ChamferLoss(nn.Module):
    """Module form of :func:`chamfer_distance`; ``forward(x (*, N, D), y (*, M, D))``."""

    def __init__(self, reduction: str = "mean"):
        super().__init__()
        _check_reduction(reduction, ("mean", "sum"))
        self.reduction = reduction

    def forward(self, x: Tensor, y: Tensor) -> Tensor:
        return chamfer_distance(x, y, self.reduction)


class HausdorffLoss(nn.Module):
    """Module form of :func:`hausdorff_distance`; ``forward(x (*, N, D), y (*, M, D))``."""

    def __init__(self, squared: bool = False):
        super().__init__()
        self.squared = bool(squared)

    def forward(self, x: Tensor, y: Tensor) -> Tensor:
        return hausdorff_distance(x, y, squared=self.squared)


class LaplacianLoss(nn.Module):
    """Module form of the three Laplacian losses.

    ``mode="grid"``: :func:`laplacian_grid`, ``forward(points (*, R, S, D))``;
    ``mode="control"``: :func:`laplacian_control`, ``forward(control_points or surface)``;
    ``mode="supervised"``: :func:`laplacian_supervised`, ``forward(pred_ctrl, true_ctrl)``.

    Example:
        >>> import torch
        >>> LaplacianLoss("grid")(torch.zeros(4, 4, 3))
        tensor(0.)
    """

    MODES = ("grid", "control", "supervised")

    def __init__(
        self,
        mode: str = "grid",
        reduction: str = "mean",
        *,
        closed_u: bool = False,
        closed_v: bool = False,
        boundary: str = "edge",
    ):
        super().__init__()
        if mode not in self.MODES:
            raise NurbskitError(f"LaplacianLoss mode must be one of {list(self.MODES)}, got {mode!r}")
        _check_reduction(reduction)
        if boundary not in _BOUNDARIES:
            raise NurbskitError(f"boundary must be one of {list(_BOUNDARIES)}, got {boundary!r}")
        self.mode, self.reduction = mode, reduction
        self.closed_u, self.closed_v, self.boundary = bool(closed_u), bool(closed_v), boundary

    def forward(self, input, target: Tensor | None = None) -> Tensor:
        opts = dict(closed_u=self.closed_u, closed_v=self.closed_v, boundary=self.boundary)
        if self.mode == "supervised":
            if target is None:
                raise NurbskitError("LaplacianLoss(mode='supervised') needs the true control grid as target")
            return laplacian_supervised(input, target, self.reduction, **opts)
        if target is not None:
            raise NurbskitError(f"LaplacianLoss(mode={self.mode!r}) is unsupervised and takes no target")
        if self.mode == "control":
            return laplacian_control(input, self.reduction, **opts)
        return laplacian_grid(input, self.reduction, **opts)


class PointToSurfaceLoss(nn.Module):
    """Module form of :func:`point_to_surface_distance`; ``forward(surface, points (N, D))``.

    Extra keyword arguments are stored and passed to ``project_points``.
    """

    def __init__(self, reduction: str = "mean", squared: bool = True, **project_options):
        super().__init__()
        _check_reduction(reduction)
        self.reduction, self.squared = reduction, bool(squared)
        self.project_options = dict(project_options)

    def forward(self, surface, points: Tensor) -> Tensor:
        return point_to_surface_distance(surface, points, self.reduction, self.squared, **self.project_options)


__all__ = [
    "l2_loss", "chamfer_distance", "hausdorff_distance",
    "grid_laplacian", "laplacian_supervised", "laplacian_grid", "laplacian_control",
    "point_to_surface_distance",
    "L2Loss", "ChamferLoss", "HausdorffLoss", "LaplacianLoss", "PointToSurfaceLoss",
    "chamfer_distance_naive", "hausdorff_distance_naive", "grid_laplacian_naive",
]
