"""Control points by linear least squares, and the alternating projection fit.

With the parameters ``(u_m, v_m)`` of the data points, the knots and the weights
fixed, a NURBS surface is linear in its control points: ``S(u_m, v_m) = A_m . P``
with ``A[m, (i, j)] = N_i(u_m) N_j(v_m) w_ij / sum_kl N_k(u_m) N_l(v_m) w_kl``. The
best control points solve the regularised normal equations

    (A^T A + lambda D^T D) P = A^T X

where ``D`` takes second differences of the control net along u and v (wrapping
along a closed v). ``lambda`` is given *relative* to the data term
(``smoothness * trace(A^T A) / trace(D^T D)``), so one value suits any number of
points and control points. Every step is a torch operation: the solution is
differentiable in the knots and the weights (used by the supervised SB preset to
eliminate the control points, "variable projection").

Alternating this solve with a projection of every point onto the surface (its foot
point gives new parameters) is the classic fitting loop (Hoschek's parameter
correction); :func:`alternate` runs it.
"""

from __future__ import annotations

from typing import Callable, Sequence

import torch

from ..core import NURBSSurface
from ..core.basis import basis_matrix
from ..core.project import project_points
from .params import Topology, expand

Tensor = torch.Tensor


def _topology(topology) -> Topology:
    return Topology(closed_v=topology) if isinstance(topology, bool) else (topology or Topology())


def design_matrix(
    params: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    sizes: Sequence[int],
    weights: Tensor | None = None,
    topology: Topology | bool | None = None,
) -> tuple[Tensor, Tensor, int]:
    """Rational basis values of every point for every free control point.

    Shapes: ``params (M, 2)`` -> ``(A (M, k), index (n_u * n_v,), k)``: ``k`` free
    unknowns after the ties of ``topology`` (periodic seam, pole rows), ``index`` maps
    each control point (u-major) to its unknown.
    """
    topo = _topology(topology)
    n_u, n_v = sizes
    bu = basis_matrix(knot_vectors[0], degrees[0], n_u, params[:, 0])  # (M, n_u)
    bv = basis_matrix(knot_vectors[1], degrees[1], n_v, params[:, 1])  # (M, n_v)
    a = bu.unsqueeze(2) * bv.unsqueeze(1)  # (M, n_u, n_v)
    if weights is not None:
        a = a * weights
        a = a / a.sum(dim=(1, 2), keepdim=True)
    index, k = topo.index(n_u, n_v, degrees[1], device=params.device)
    a = a.reshape(a.shape[0], -1)
    return a.new_zeros(a.shape[0], k).index_add(1, index, a), index, k


def difference_stencils(n_u: int, n_v: int, closed_v: bool = False, device=None) -> tuple[Tensor, Tensor, Tensor]:
    """The control points ``(a, b, c)`` of every second difference ``P_a - 2 P_b + P_c`` of a
    net (u-major indices, ``(rows,)`` each): along u, then along v (with wrap-around when
    ``closed_v``; ``n_v`` then counts the distinct columns)."""
    rows = []
    idx = torch.arange(n_u * n_v, device=device).reshape(n_u, n_v)
    for i in range(1, n_u - 1):
        rows.append((idx[i - 1], idx[i], idx[i + 1]))
    js = range(n_v) if closed_v else range(1, n_v - 1)
    for j in js:
        rows.append((idx[:, (j - 1) % n_v], idx[:, j], idx[:, (j + 1) % n_v]))
    if not rows:
        empty = torch.zeros(0, dtype=torch.int64, device=device)
        return empty, empty, empty
    return tuple(torch.cat([r[t] for r in rows]) for t in range(3))


def second_differences(n_u: int, n_v: int, closed_v: bool = False, *, dtype=None, device=None) -> Tensor:
    """Second-difference operator of a control net, ``(rows, n_u * n_v)`` (dense; the rows
    of :func:`difference_stencils`)."""
    a, b, c = difference_stencils(n_u, n_v, closed_v, device)
    n = a.numel()
    D = torch.zeros(n, n_u * n_v, dtype=dtype or torch.get_default_dtype(), device=device)
    r = torch.arange(n, device=device)
    D[r, a] += 1.0
    D[r, b] -= 2.0
    D[r, c] += 1.0
    return D


#: A least-squares solve that needs no gradient, on the CPU, runs on sparse matrices
#: (scipy's SuperLU) from this many unknowns, or from this many entries of the dense
#: design matrix ``(M, k)``: a point touches (p + 1)(q + 1) control points, so the design
#: matrix has that many non-zeros a row and the normal matrix is banded. Measured
#: (``benchmarks/bench_lstsq_sparse.py``, two runs on a shared machine): the dense solve
#: of a 16 x 16 net on 20,000 points took 6 to 11 times the sparse one, of a 100 x 100
#: net 110 to 190 times (and 10 GB); below these sizes (a patch's few hundred points)
#: scipy's overhead of about a millisecond a solve can lose.
SPARSE_UNKNOWNS = 256
SPARSE_ENTRIES = 1 << 21


def solves_sparse(points: int, unknowns: int, device) -> bool:
    """Whether :func:`solve_control_points` takes the sparse path for ``points`` x
    ``unknowns`` on ``device`` (when no gradient is wanted)."""
    return torch.device(device).type == "cpu" and (unknowns >= SPARSE_UNKNOWNS or points * unknowns >= SPARSE_ENTRIES)


def _sparse_system(params, points, knot_vectors, degrees, sizes, weights, topo, smoothness):
    """The regularised normal equations of :func:`solve_control_points` as scipy sparse
    matrices (float64): ``(AtA (k, k) CSC, rhs (k, dim), index, k)``."""
    import numpy as np
    from scipy import sparse

    from ..core.basis import basis_functions
    from ..core.knots import find_spans

    n_u, n_v = sizes
    p, q = degrees
    index, k = topo.index(n_u, n_v, q)
    local = []
    for kv, d, n, u in zip(knot_vectors, degrees, sizes, params.unbind(-1)):
        span = find_spans(kv, d, n, u)
        local.append((span.unsqueeze(-1) - d + torch.arange(d + 1), basis_functions(kv, d, span, u)))
    (iu, bu), (iv, bv) = local
    a = bu.unsqueeze(2) * bv.unsqueeze(1)  # (M, p + 1, q + 1): each point's non-zero basis products
    full = iu.unsqueeze(2) * n_v + iv.unsqueeze(1)  # their control points (u-major)
    if weights is not None:
        a = a * weights.reshape(-1)[full]
        a = a / a.sum(dim=(1, 2), keepdim=True)
    m = params.shape[0]
    rows = torch.arange(m).reshape(m, 1, 1).expand_as(full)
    A = sparse.csr_matrix(
        (a.detach().double().reshape(-1).numpy(), (rows.reshape(-1).numpy(), index[full].reshape(-1).numpy())),
        shape=(m, k))  # tied control points (a seam, a pole) add up in their unknown
    AtA = (A.T @ A).tocsc()
    rhs = A.T @ points.detach().double().cpu().numpy()
    trace = AtA.diagonal().sum()
    if smoothness > 0:
        cols = n_v - q if topo.closed_v else n_v
        first = index.reshape(n_u, n_v)[:, :cols].reshape(-1).numpy()
        stencil = [first[t.numpy()] for t in difference_stencils(n_u, cols, topo.closed_v)]
        r = np.arange(len(stencil[0]))
        D = sparse.csr_matrix((np.repeat([1.0, -2.0, 1.0], len(r)), (np.tile(r, 3), np.concatenate(stencil))),
                              shape=(len(r), k))
        DtD = (D.T @ D).tocsc()
        AtA = AtA + (smoothness * trace / max(DtD.diagonal().sum(), 1e-30)) * DtD
    AtA = AtA + (1e-12 * trace / k) * sparse.identity(k, format="csc")
    return AtA.tocsc(), rhs, index, k


def solve_control_points(
    params: Tensor,
    points: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    sizes: Sequence[int],
    weights: Tensor | None = None,
    topology: Topology | bool | None = None,
    smoothness: float = 0.0,
) -> Tensor:
    """Least-squares control points for points at known parameters.

    Shapes: ``params (M, 2)``, ``points (M, dim)`` -> ``(n_u, n_v, dim)`` (the full net,
    respecting the ties of ``topology``; a bool means ``closed_v``). ``smoothness`` is
    relative (see the module docstring); with ``smoothness=0`` and enough well-spread
    points the fit reproduces any surface of the same knots and weights exactly. Large
    systems solved without gradients on the CPU (:func:`solves_sparse`: the alternation,
    the initial fit) go through sparse matrices: the same system, solved in float64.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSSurface
        >>> s = NURBSSurface(torch.rand(5, 5, 3, dtype=torch.float64))
        >>> uv = torch.rand(200, 2, dtype=torch.float64)
        >>> P = solve_control_points(uv, s.evaluate(uv), s.knot_vectors, s.degrees, s.sizes)
        >>> bool(torch.allclose(P, s.control_points))
        True
    """
    topo = _topology(topology)
    n_u, n_v = sizes
    differentiable = torch.is_grad_enabled() and any(
        t is not None and t.requires_grad for t in (params, points, weights, *knot_vectors))
    if not differentiable and solves_sparse(params.shape[0], n_u * n_v, params.device):
        from scipy.sparse.linalg import spsolve

        AtA, rhs, index, k = _sparse_system(params, points, knot_vectors, degrees, sizes, weights, topo, smoothness)
        P = torch.from_numpy(spsolve(AtA, rhs).reshape(k, -1)).to(points.dtype)
        return expand(P, index, n_u, n_v)
    A, index, k = design_matrix(params, knot_vectors, degrees, sizes, weights, topo)
    AtA = A.T @ A
    rhs = A.T @ points
    trace = torch.diagonal(AtA).sum().detach()
    if smoothness > 0:
        m = n_v - degrees[1] if topo.closed_v else n_v
        D = second_differences(n_u, m, topo.closed_v, dtype=A.dtype, device=A.device)
        first = index.reshape(n_u, n_v)[:, :m].reshape(-1)
        D = D.new_zeros(D.shape[0], k).index_add(1, first, D)
        DtD = D.T @ D
        lam = smoothness * trace / torch.diagonal(DtD).sum().clamp_min(1e-30)
        AtA = AtA + lam * DtD
    # A whisper of ridge keeps control points with no data nearby determined.
    AtA = AtA + (1e-12 * trace / k) * torch.eye(k, dtype=A.dtype, device=A.device)
    P = torch.linalg.solve(AtA, rhs)
    return expand(P, index, n_u, n_v)


def alternate(
    surface: NURBSSurface,
    points: Tensor,
    rounds: int,
    topology: Topology | bool | None = None,
    smoothness: float = 1e-3,
    tolerance: float = 1e-7,
    params: Tensor | None = None,
    callback: Callable[[int, float], None] | None = None,
) -> tuple[NURBSSurface, Tensor, list[float]]:
    """Alternate foot-point projection and least-squares control points.

    Shapes: ``points (N, 3)`` -> (surface, foot parameters ``(N, 2)``, mean squared
    distance after each round). Knots and weights stay as they are. Foot points come
    from :func:`nurbskit.core.project.project_points` (a closed v is its periodic
    direction); ``params (N, 2)``, when given, warm-starts the first round's projection too (e.g. the
    foot points of an earlier fit of the same points, to which the surface was just solved), as
    the later rounds are; None: the first round starts from the grid. Stops early when
    a round improves the mean squared distance by less than ``tolerance``.
    """
    topo = _topology(topology)
    periodic = (False, topo.closed_v)
    history: list[float] = []

    def feet(surface, warm):
        # The one projection (core.project): from the grid in the first round (unless warm
        # parameters were given), then warm
        # from the last round's foot points (the least-squares step moves the surface little).
        if warm is None:
            return project_points(surface, points, periodic=periodic).params
        return project_points(surface, points, params=warm, periodic=periodic, iterations=3, second_order=False).params

    with torch.no_grad():
        for k in range(rounds):
            params = feet(surface, params)
            err = float((surface.evaluate(params) - points).square().sum(-1).mean())
            history.append(err)
            if callback is not None:
                callback(k, err)
            if k > 0 and history[-2] - err < tolerance * max(history[0], 1e-30):
                break
            cp = solve_control_points(
                params, points, surface.knot_vectors, surface.degrees, surface.sizes,
                surface.weights, topo, smoothness,
            )
            surface = surface._replace(control_points=cp)
        if rounds > 0:
            params = feet(surface, params)
    return surface, params, history


def equidistributed_knots(grid: Tensor, axis: int, n_ctrl: int, degree: int, floor: float = 0.05) -> Tensor:
    """Clamped knots on [0, 1] that equidistribute ``|D^(p+1) X|^(1/(p+1))`` along one grid axis.

    Shapes: ``grid (R, S, dim)`` sampled on a uniform parametric grid -> ``(n_ctrl + p + 1,)``.
    The ``(p+1)``-th derivative is estimated by finite differences along ``axis``
    (averaged over the other), and the interior knots are placed at equal quantiles
    of its ``1/(p+1)`` power (de Boor's rule for placing knots where the function
    needs them: the error of a degree-p spline on a span of length h scales like
    ``h^(p+1) |D^(p+1) f|``). ``floor`` (a fraction of the mean density) keeps flat
    stretches from losing every knot.

    Example:
        >>> import torch
        >>> t = torch.linspace(0, 1, 64, dtype=torch.float64)
        >>> g = torch.stack(torch.meshgrid(t, t, indexing="ij") + (torch.exp(8 * t)[:, None].expand(64, 64),), -1)
        >>> k = equidistributed_knots(g, 0, 8, 3)
        >>> bool(k[4] > 0.25)  # knots crowd where exp(8 u) bends most
        True
    """
    x = grid if axis == 0 else grid.transpose(0, 1)
    d = x.detach().double()
    for _ in range(degree + 1):
        d = d[1:] - d[:-1]
    extent = float((x.detach().double().reshape(-1, x.shape[-1]).amax(0) - x.detach().double().reshape(-1, x.shape[-1]).amin(0)).norm()) or 1.0
    rel = d.norm(dim=-1).mean(dim=1) / extent
    rel = torch.where(rel < 1e-9, torch.zeros_like(rel), rel)  # rounding noise of a flat direction
    dens = rel ** (1.0 / (degree + 1))
    if not float(dens.sum()) > 0:
        dens = torch.ones_like(dens)
    dens = dens + floor * dens.mean()
    cum = torch.cat([dens.new_zeros(1), torch.cumsum(dens, 0)])
    cum = cum / cum[-1]
    pos = torch.linspace(0, 1, cum.numel(), dtype=cum.dtype)
    q = torch.linspace(0, 1, n_ctrl - degree + 1, dtype=cum.dtype)[1:-1]
    # Invert the cumulative density by linear interpolation.
    j = torch.searchsorted(cum, q).clamp(1, cum.numel() - 1)
    c0, c1 = cum[j - 1], cum[j]
    inner = pos[j - 1] + (q - c0) / (c1 - c0).clamp_min(1e-300) * (pos[j] - pos[j - 1])
    k = torch.cat([torch.zeros(degree + 1, dtype=cum.dtype), inner, torch.ones(degree + 1, dtype=cum.dtype)])
    return k.to(dtype=grid.dtype, device=grid.device)
