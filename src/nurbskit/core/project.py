"""Closest-point projection of many points onto a NURBS surface or curve at once.

Point inversion after The NURBS Book, section 6.1 (Newton iteration on the parameters
from a good start point), vectorised over all points and made robust for a box domain:

1. **Start** at the nearest sample of a uniform parametric grid (:mod:`.neighbors`: a
   KD-tree on CPU; on accelerators tiled exact distances, or for large inputs a
   coarse-to-fine search of the grid), or at given parameters (a warm start).
2. **Newton** on ``f(t) = |C(t) - x|^2 / 2``: gradient ``g = J r``, Hessian
   ``H = J J^T + sum_d r_d * d^2 C_d`` with ``r = C(t) - x`` and ``J`` the first
   derivatives (rows ``C_u``, ``C_v``): the spline's derivatives up to order 2 (A2.3
   basis derivatives and the rational quotient rule, as ``derivatives(order=2)``).
   Iterations are masked (a converged point is frozen with ``torch.where``), so one
   iteration reads nothing back to the host; convergence is checked every few.
3. **Bounds** (projected Newton with an active set; D. P. Bertsekas, "Projected Newton
   methods for optimization problems with simple constraints", 1982): a parameter that sits on
   the edge of the domain while the gradient or the Newton step points outward is held
   there, and Newton continues on the remaining parameter alone, i.e. on the boundary
   curve. A step that would leave the domain is clamped. A **periodic** direction
   (periodic knot spacing, the last ``p`` control columns repeating the first ``p``) has
   no edge: the step crosses the seam and the parameter wraps into the domain (unless
   it has C0 knots: see :func:`project_points`).
4. **Descent guard**: where ``H`` is not positive definite the step uses the
   Levenberg-Marquardt matrix ``J J^T + mu I`` instead (always a descent direction);
   a step that does not lower ``f`` is rejected and halved on the next iteration.

The iteration runs under ``torch.no_grad`` on detached tensors. The foot point is then
recomputed *with* autograd, ``closest = spline.evaluate(params)``, so by the envelope
theorem (the derivative of a minimum value equals the partial derivative of the objective
at the fixed minimiser) gradients of ``distance`` reach control points, weights and knots
exactly, and reach ``points`` through ``points - closest``.

Convention: ``params`` are in the knot domain, ``(N, 2)`` for a surface and ``(N,)`` for a
curve (the shape :meth:`evaluate` takes); they lie in the closed domain, edges included
(``[start, end)`` along a periodic direction). A batched spline (control points
``(*B, n_1, ..., dim)``) takes points ``(*B, N, dim)``, one cloud per element.
Otherwise leading batch dimensions of ``points`` are kept: ``(..., N, dim)`` -> ``(..., N, 2)``,
``(..., N, dim)``, ``(..., N)``. Where the closest point is not unique (the centre of a
sphere) one of the minimisers is returned. Not handled: the gradient through the domain
ends themselves (a foot point held on the edge ``u = knots[p]`` does not follow that knot).
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np
import torch

from ..errors import NurbskitError
from . import tensor as _tp
from .neighbors import k_nearest

Tensor = torch.Tensor

__all__ = ["Projection", "project_points", "project_points_curve", "nearest_grid_params", "periodic_directions"]


class Projection(NamedTuple):
    """Result of :func:`project_points`; unpacks as ``params, closest, distance``."""

    params: Tensor
    """Foot-point parameters ``(..., N, 2)`` (surfaces) or ``(..., N)`` (curves), detached."""
    closest: Tensor
    """Foot points ``(..., N, dim)``; differentiable w.r.t. the spline's tensors."""
    distance: Tensor
    """``|points - closest|`` ``(..., N)``; differentiable w.r.t. the spline and the points."""


# ----------------------------------------------------------------------------------------
# the local quadratic model
# ----------------------------------------------------------------------------------------
# Rows of the flattened (o + 1)^2 derivative table, taken as views and stacked (an index
# tensor would be copied from the host on every call on an accelerator)
_J_ROWS = {2: (3, 1), 1: (2, 1)}  # S_u, S_v
_H_ROWS = (6, 4, 4, 2)  # S_uu, S_uv; S_uv, S_vv in the 3 x 3 table


def _local_model(spline, Pw: Tensor, t: Tensor, x: Tensor, second_order: bool = True, element: Tensor | None = None):
    """Point, squared distance, gradient and Hessian of ``|C(t) - x|^2 / 2``.

    Shapes: ``t (M, k)``, ``x (M, dim)`` -> ``C (M, dim)``, ``f (M,)`` (the squared
    distance), ``g (M, k)``, ``H (M, k, k)``, ``J (M, k, dim)``. Derivatives come from
    homogeneous points ``Pw`` formed once per projection rather than once per iteration.
    With ``second_order=False`` the Hessian is the Gauss-Newton ``J J^T`` (first
    derivatives only: about a third of the work; exact at zero residual). For a batch,
    ``Pw (Bt, n_u, n_v, D)`` and point ``i`` lies on element ``element[i]``.
    """
    order = 2 if second_order else 1
    D = _tp.derivatives_from_homogeneous(Pw, spline.knot_vectors, spline.degrees, t, order, element)
    m, dim = D.shape[0], D.shape[-1]
    if spline.para_dim == 1:  # (M, o + 1, dim)
        C = D[:, 0]
        J = D[:, 1:2]
        second = D[:, 2:3].unsqueeze(1) if second_order else None  # (M, 1, 1, dim)
    else:  # (M, o + 1, o + 1, dim), [a, b] = d^a/du^a d^b/dv^b, flattened as (o + 1) a + b
        flat = D.reshape(m, (order + 1) ** 2, dim)
        C = flat[:, 0]
        J = torch.stack([flat[:, i] for i in _J_ROWS[order]], 1)  # S_u, S_v
        second = torch.stack([flat[:, i] for i in _H_ROWS], 1).reshape(m, 2, 2, dim) if second_order else None
    r = C - x
    f = (r * r).sum(-1)
    g = _dot(J, r.unsqueeze(1))
    H = _gram(J)
    if second is not None:
        H = H + _dot(second, r[:, None, None, :])
    return C, f, g, H, J


# These per-point products are far too small for a batched GEMM on a GPU (on an H100, ``bmm``
# of 10^6 2 x 3 by 3 x 2 matrices took 1.85 ms, their products summed 0.12 ms), and a
# broadcast product summed over a last axis of 3 is slow on a CPU (0.07 M points: 3.8 ms
# against 0.45 ms by ``bmm``); unrolled over that axis they are fast on both (0.40 ms).
def _dot(a: Tensor, b: Tensor) -> Tensor:
    """``(a * b).sum(-1)`` for a short last axis (``dim``), unrolled over it."""
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out.addcmul_(a[..., i], b[..., i])
    return out


def _gram(J: Tensor) -> Tensor:
    """``J J^T`` per point, ``(M, k, dim) -> (M, k, k)`` (k = 1 or 2): its distinct entries by :func:`_dot`."""
    if J.shape[1] == 1:
        return _dot(J[:, 0], J[:, 0]).reshape(-1, 1, 1)
    a, b, c = _dot(J[:, 0], J[:, 0]), _dot(J[:, 0], J[:, 1]), _dot(J[:, 1], J[:, 1])
    return torch.stack([a, b, b, c], -1).reshape(-1, 2, 2)


def _reduced(A: Tensor, free: Tensor, fill: Tensor) -> list[Tensor]:
    """The entries ``(M,)`` of ``A (M, k, k)`` (k = 1: ``[a]``; k = 2: ``[a, b, c]``, the
    matrix ``[[a, b], [b, c]]``) with a fixed coordinate's row and column replaced by
    ``fill`` on the diagonal and 0 off it: the free block, padded to a full system whose
    solution is 0 on the fixed coordinates (the 1-D Newton along a boundary curve)."""
    entries = A.reshape(A.shape[0], -1).unbind(-1)
    if A.shape[-1] == 1:
        return [torch.where(free[:, 0], entries[0], fill)]
    f0, f1 = free.unbind(-1)
    return [torch.where(f0, entries[0], fill), torch.where(f0 & f1, entries[1], 0.0), torch.where(f1, entries[3], fill)]


def _positive_definite(m: list[Tensor], eps: Tensor) -> Tensor:
    """Whether the reduced matrix ``m`` (see :func:`_reduced`) is safely positive definite
    -> ``(M,)``: eigenvalues below about ``eps`` count as not positive."""
    if len(m) == 1:
        return m[0] > eps
    a, b, c = m
    return (a > eps) & (c > eps) & (a * c - b * b > eps * (a + c))


def _solve(m: list[Tensor], g: Tensor) -> Tensor:
    """``-A^{-1} g`` for the reduced matrix ``m`` and ``g (M, k)`` (0 on fixed coordinates)."""
    if len(m) == 1:
        return -g / m[0].unsqueeze(-1)
    a, b, c = m
    g0, g1 = g.unbind(-1)
    det = a * c - b * b
    return torch.stack([(b * g1 - c * g0) / det, (b * g0 - a * g1) / det], dim=-1)


def _step(g: Tensor, H: Tensor, J: Tensor, t: Tensor, lo: Tensor, hi: Tensor) -> Tensor:
    """One projected (active-set) Newton direction ``(M, k)`` for ``f / 2`` at ``t``.

    Where the free block of ``H`` is not safely positive definite (eigenvalues below
    ``1e-10`` of the trace of ``J J^T``), the Levenberg-Marquardt matrix
    ``J J^T + (1e-3 trace) I`` takes its place: positive definite whenever ``J`` has rank,
    so the step descends. Branch-free (no host read): the direction with the first active
    set and the one with the blocked parameters held as well are both computed, and
    ``torch.where`` picks. The 2 x 2 systems are solved in closed form on their entries;
    the second direction, where at most one parameter is left free, is the 1-D step on
    each diagonal entry (about a third fewer operations than a second 2 x 2 solve).
    """
    JJ = _gram(J)
    trace = JJ.diagonal(dim1=1, dim2=2).sum(-1)
    eps = 1e-10 * trace
    damping = 1e-3 * trace + torch.finfo(t.dtype).tiny
    fill = trace + 1.0  # any positive diagonal for a fixed coordinate: its step is 0
    at_lo, at_hi = t <= lo, t >= hi
    free = ~((at_lo & (g > 0)) | (at_hi & (g < 0)))
    h = _reduced(H, free, fill)
    lm = _reduced(JJ, free, fill)
    lm[0] = lm[0] + damping
    if len(lm) > 1:
        lm[2] = lm[2] + damping
    pd = _positive_definite(h, eps)
    d = _solve([torch.where(pd, x, y) for x, y in zip(h, lm)], torch.where(free, g, 0.0))
    # A Newton step that points out of the domain from an edge is blocked by the clamp and
    # may then not descend: hold that parameter as well and step along the other alone.
    # Blocked parameters are free ones, so at most one of k <= 2 is left: its 1-D Newton
    # step on the diagonal entry of H (of the Levenberg-Marquardt matrix where that entry
    # is not safely positive), and 0 where none is left.
    blocked = free & ((at_lo & (d < 0)) | (at_hi & (d > 0)))
    diag = H.diagonal(dim1=1, dim2=2)
    alone = torch.where(diag > eps.unsqueeze(-1), diag, JJ.diagonal(dim1=1, dim2=2) + damping.unsqueeze(-1))
    held = torch.where(free & ~blocked, -g / alone, 0.0)
    return torch.where(blocked.any(-1, keepdim=True), held, d)


class _Domain(NamedTuple):
    """The parameter box as tensors (no host read): ``lo``, ``hi`` ``(k,)``, or ``(Bt, k)``
    per element of a batch and ``(M, k)`` per point once :meth:`take` has picked each
    point's row; a periodic direction has ``lo = -inf``, ``hi = inf`` for the clamp and
    wraps into ``[start, start + period)`` instead."""

    lo: Tensor
    hi: Tensor
    start: Tensor
    period: Tensor
    periodic: Tensor  # (k,) or (rows, k) bool

    def fold(self, t: Tensor) -> Tensor:
        t = torch.maximum(torch.minimum(t, self.hi), self.lo)
        wrapped = self.start + torch.remainder(t - self.start, self.period)
        return torch.where(self.periodic, wrapped, t)

    def take(self, index: Tensor) -> "_Domain":
        """Rows ``index`` of a per-row domain; a shared ``(k,)`` domain is returned as it is."""
        if self.lo.ndim < 2:
            return self
        return _Domain(*(z.index_select(0, index) for z in self))


def _domain(spline, periodic) -> _Domain:
    """The domain of ``spline``: ``(k,)`` fields, or ``(Bt, k)`` where knots (``(Bt, m)``) or
    ``periodic`` (a ``(Bt, k)`` bool tensor) differ per element of a flat batch."""
    kvs = [kv.detach() for kv in spline.knot_vectors]
    a = torch.stack(torch.broadcast_tensors(*[kv[..., p] for kv, p in zip(kvs, spline.degrees)]), -1)
    b = torch.stack(torch.broadcast_tensors(*[kv[..., n] for kv, n in zip(kvs, spline.sizes)]), -1)
    if isinstance(periodic, Tensor):
        per = periodic.to(device=a.device, dtype=torch.bool)
    else:  # set on the device: a tensor made from the list would be a copy from the host
        per = torch.zeros(len(periodic), dtype=torch.bool, device=a.device)
        for i, wraps in enumerate(periodic):
            if wraps:
                per[i] = True
    a, b, per = torch.broadcast_tensors(a, b, per)
    inf = torch.full_like(a, float("inf"))
    return _Domain(torch.where(per, -inf, a), torch.where(per, inf, b), a, b - a, per)


def _c0_breaks(spline, Pw: Tensor, periodic, elements: int | None = None) -> list[Tensor] | None:
    """Per direction, the knots where the spline turns a corner: interior knots of
    multiplicity ``>= p`` (where it is only C0 in its parameter: a polyline's vertices, a
    crease) across which its tangent along that direction turns (:func:`_turning`; the
    double knots of a rational circle do not), as a table ``(E, L)``: a sorted row per
    element, padded with ``inf`` (``E = 1`` where the rows agree); None when there are
    none. A direction that wraps has its seam (the domain's start) as a break too where
    the seam turns (a closed polygon) or where it has interior ones: :func:`_pieces` then
    cuts it into boxes that do not wrap. The knots are read on the host (a copy per
    direction on an accelerator; nothing on the CPU), and the turns with one read per
    direction that has knots of multiplicity ``>= p``."""
    k = spline.para_dim
    if isinstance(periodic, Tensor):
        wraps = periodic.detach().cpu().numpy().reshape(-1, k)
    else:
        wraps = np.asarray(periodic, dtype=bool).reshape(1, k)
    knots = [kv.detach().cpu().numpy().reshape(-1, kv.shape[-1]) for kv in spline.knot_vectors]  # (1 or Bt, m)
    count = elements or 1
    out, found = [], False
    for a, (p, n) in enumerate(zip(spline.degrees, spline.sizes)):
        sides = []  # (element, parameter before the knot, at the knot, is the seam)
        for e in range(count):
            kk = knots[a][min(e, knots[a].shape[0] - 1)]
            values, counts = np.unique(kk[p + 1 : n], return_counts=True)  # the interior knots
            for v in values[(counts >= p) & (values > kk[p]) & (values < kk[n])]:
                sides.append((e, np.nextafter(v, -np.inf), v, False))
            if wraps[min(e, wraps.shape[0] - 1), a] and np.count_nonzero(kk == kk[p]) >= p:
                sides.append((e, kk[n], kk[p], True))  # the seam: the domain's end meets its start
        turns = _turning(spline, Pw, a, sides, knots, elements) if sides else []
        rows = [[] for _ in range(count)]
        seams = [False] * count
        for (e, _, v, seam), turn in zip(sides, turns):
            if turn and seam:
                seams[e] = True
            elif turn:
                rows[e].append(v)
        for e in range(count):
            kk = knots[a][min(e, knots[a].shape[0] - 1)]
            if wraps[min(e, wraps.shape[0] - 1), a] and (rows[e] or seams[e]):
                rows[e].insert(0, kk[p])  # the seam, the first piece's start
        if all(r == rows[0] for r in rows):
            rows = rows[:1]
        table = np.full((len(rows), max(len(r) for r in rows)), np.inf)
        for e, r in enumerate(rows):
            table[e, : len(r)] = r
        found |= table.shape[1] > 0
        out.append(torch.as_tensor(table, dtype=Pw.dtype, device=Pw.device))
    return out if found else None


def _turning(spline, Pw: Tensor, a: int, sides: list, knots: list, elements: int | None) -> list[bool]:
    """Whether the tangent along direction ``a`` turns across each knot of ``sides``
    (``(element, parameter before, parameter after, seam)``): the first derivatives on either
    side, at 9 parameters spread over each other direction, differ in direction by more
    than rounding (or one vanishes). One evaluation, one host read."""
    k = spline.para_dim
    spread = 9
    before, after, element, side = [], [], [], []
    for i, (e, lo, hi, _) in enumerate(sides):
        other = [np.linspace(kk[p], kk[n], spread) for kk, p, n in
                 ((knots[b][min(e, knots[b].shape[0] - 1)], spline.degrees[b], spline.sizes[b]) for b in range(k))]
        grid = np.stack(np.meshgrid(*[other[b] if b != a else np.zeros(1) for b in range(k)], indexing="ij"), -1)
        grid = grid.reshape(-1, k)
        for t, into in ((lo, before), (hi, after)):
            g = grid.copy()
            g[:, a] = t
            into.append(g)
        element.append(np.full(grid.shape[0], e))
        side.append(np.full(grid.shape[0], i))
    t = torch.as_tensor(np.concatenate(before + after), dtype=Pw.dtype, device=Pw.device)
    rows = np.concatenate(element)
    el = None if elements is None else torch.as_tensor(np.concatenate([rows, rows]), device=Pw.device)
    D = _tp.derivatives_from_homogeneous(Pw, spline.knot_vectors, spline.degrees, t, 1, el)
    d = D[:, 1] if k == 1 else D.reshape(t.shape[0], 2 ** k, -1)[:, 2 ** (k - 1 - a)]  # d/d(direction a)
    d = d / d.norm(dim=-1, keepdim=True)  # a vanishing derivative gives NaN: counted as a turn
    m = d.shape[0] // 2
    bend = 1.0 - (d[:m] * d[m:]).sum(-1)  # 1 - cos of the angle between the two sides' tangents
    smooth = (bend <= 100 * torch.finfo(Pw.dtype).eps).cpu().numpy()  # the one host read
    per = np.ones(len(sides), dtype=bool)
    np.logical_and.at(per, np.concatenate(side), smooth)
    return list(~per)


def _pieces(dom: _Domain, t: Tensor, breaks: list[Tensor], element: Tensor | None = None) -> _Domain:
    """Per start ``t (M, k)``, the box of the smooth piece it lies in: between the C0 knots
    ``breaks`` around it (a start on a knot lies in the piece above it), the upper bound one
    ulp below its knot, so that Newton at that bound evaluates the piece's own span. A
    table of several rows (a batch) gives each start its element's row (``element (M,)``).
    A wrapping direction with breaks (its seam is the first) is cut at them: its pieces
    end at the seam too, and do not wrap (``t`` is folded into ``dom`` already)."""
    M, k = t.shape
    fields = [z.expand(M, k).clone() for z in dom]
    lo, hi, start, period, periodic = fields
    for a, b in enumerate(breaks):
        count = b.shape[-1]
        if count == 0:
            continue
        if b.shape[0] == 1:  # shared: one sorted row
            i = torch.searchsorted(b[0], t[:, a].contiguous(), right=True)  # knots at or below t
            below = b[0].index_select(0, (i - 1).clamp_min(0))
            above = b[0].index_select(0, i.clamp_max(count - 1))
            cut = torch.isfinite(b[0, :1]).expand(M)
        else:  # each start searches its element's row (padded with inf)
            rows = b.index_select(0, element)
            i = torch.searchsorted(rows, t[:, a : a + 1].contiguous(), right=True)
            below = rows.gather(1, (i - 1).clamp_min(0))[:, 0]
            above = rows.gather(1, i.clamp_max(count - 1))[:, 0]
            i = i[:, 0]
            cut = torch.isfinite(rows[:, 0])
        wraps = periodic[:, a] & cut  # a wrapping direction cut at its breaks: its seam ends pieces
        end = torch.where(wraps, start[:, a] + period[:, a], hi[:, a])
        end = torch.where(wraps, torch.nextafter(end, torch.full_like(end, -math.inf)), end)
        lo[:, a] = torch.where(i > 0, below, torch.where(wraps, start[:, a], lo[:, a]))
        hi[:, a] = torch.where((i < count) & torch.isfinite(above),
                               torch.nextafter(above, torch.full_like(above, -math.inf)), end)
        periodic[:, a] = periodic[:, a] & ~cut
    return _Domain(*fields)


def _across_c0_knots(refine, per_start, breaks: list[Tensor], rows: Tensor, starts: Tensor, targets: Tensor,
                     element_of) -> tuple[Tensor, Tensor]:
    """Projected Newton on a spline with C0 knots -> ``(rows, found)`` of every start made.

    Across a C0 knot the squared distance has a kink, where Newton overshoots, halves its
    step and stops short of the knot. So each start is refined within its smooth piece (the
    knots are the edges of its box, where the active set holds a parameter); a result that
    ends on such an edge starts again in the neighbouring piece, from the knot (twice, for a
    corner of pieces). The caller keeps each point's closest result. ``element_of(rows)``
    names each start's element of a batch (None for one spline), ``per_start(element)``
    gives each start's domain, and ``refine(starts, targets, box, element)`` runs Newton."""
    all_rows, all_found = [rows], []
    element = element_of(rows)
    dom = per_start(element)
    starts = dom.fold(starts)  # into the domain: a wrapping direction's pieces do not wrap
    box = _pieces(dom, starts, breaks, element)
    found = refine(starts, targets, box, element)
    all_found.append(found)
    for _ in range(2):
        again = []
        for a, b in enumerate(breaks):
            if b.shape[-1] == 0:
                continue
            at_lo = (found[:, a] <= box.lo[:, a]) & (box.lo[:, a] > dom.lo[..., a])
            at_hi = (found[:, a] >= box.hi[:, a]) & (box.hi[:, a] < dom.hi[..., a])
            for mask, value in ((at_lo, torch.nextafter(box.lo[:, a], torch.full_like(found[:, a], -math.inf))),
                                (at_hi, torch.nextafter(box.hi[:, a], torch.full_like(found[:, a], math.inf)))):
                pick = torch.nonzero(mask).reshape(-1)  # a host read, on splines with C0 knots only
                if pick.numel():
                    t = found.index_select(0, pick).clone()
                    t[:, a] = value.index_select(0, pick)
                    again.append((rows.index_select(0, pick), t, targets.index_select(0, pick)))
        if not again:
            break
        rows, starts, targets = (torch.cat(z) for z in zip(*again))
        element = element_of(rows)
        dom = per_start(element)
        starts = dom.fold(starts)  # across a wrapping direction's seam: into the last or the first piece
        box = _pieces(dom, starts, breaks, element)
        found = refine(starts, targets, box, element)
        all_rows.append(rows)
        all_found.append(found)
    return torch.cat(all_rows), torch.cat(all_found)


#: Points in a Newton state from which an accelerator compacts it at a convergence check.
_COMPACT_MIN = 1 << 16


@torch.no_grad()
def _newton(
    spline, Pw: Tensor, t: Tensor, x: Tensor, dom: _Domain, iterations: int, tol_move: Tensor, noise: Tensor,
    check_every: int, second_order: bool = True, element: Tensor | None = None,
) -> Tensor:
    """Refine start parameters ``t (M, k)`` for points ``x (M, dim)`` -> ``(M, k)``.

    ``noise`` is the rounding error of a computed point (``eps`` times the size of the
    control net): a step is accepted unless it raises ``f = |r|^2`` by more than the
    rounding of ``f``, about ``4 noise (|r| + noise)``. For a batch (``Pw (Bt, ...)``),
    ``element (M,)`` names each point's element, and ``dom`` (``(M, k)`` fields),
    ``tol_move`` and ``noise`` (``(M,)``) may be per point; each point's iterates are
    those it would take on its element alone.

    Masked iterations: every point takes part in every iteration, and a point that has
    converged is frozen by ``torch.where``, so an iteration reads nothing back to the
    host. Every ``check_every`` iterations (0: never) one value is read: the loop stops
    once every point has converged, and once half of the points have converged the state
    is compacted to the points still moving (on the CPU always, where a host read costs
    nothing and the work shrinks; on an accelerator for 65,536 points or more, where the
    work is arithmetic rather than launches: 10^6 points projected in float32 on an H100
    ran the last four of eight iterations on every point).
    """
    t = dom.fold(t)
    out = t.clone()
    _, f, g, H, J = _local_model(spline, Pw, t, x, second_order, element)
    scale = torch.ones_like(f)
    done = torch.zeros_like(f, dtype=torch.bool)
    index = None  # rows of `out` still in the state (None: all, in order)
    min_scale = 2.0 ** -16
    compact = t.device.type == "cpu" or t.shape[0] >= _COMPACT_MIN
    for it in range(iterations):
        d = _step(g, H, J, t, dom.lo, dom.hi) * scale[:, None]
        cand = dom.fold(t + d)
        _, fc, gc, Hc, Jc = _local_model(spline, Pw, cand, x, second_order, element)
        accept = (fc <= f + 4 * noise * (f.sqrt() + noise)) & ~done
        # the step actually taken (a periodic wrap does not count as movement)
        delta = torch.where(dom.periodic, torch.maximum(torch.minimum(d, dom.hi), dom.lo), cand - t)
        moved = (delta.unsqueeze(-1) * J).sum(1).norm(dim=-1)
        a1, a2 = accept[:, None], accept[:, None, None]
        t, f, g = torch.where(a1, cand, t), torch.where(accept, fc, f), torch.where(a1, gc, g)
        H, J = torch.where(a2, Hc, H), torch.where(a2, Jc, J)
        scale = torch.where(accept, torch.ones_like(scale), 0.5 * scale)
        # Converged: the last step moved the foot point by less than tol (Newton is
        # quadratic, so the accepted point is then accurate to about tol^2 / curvature
        # radius); stuck: the step was halved until it no longer matters.
        done = done | (moved <= tol_move) | (~accept & (scale < min_scale))
        if check_every and (it + 1) % check_every == 0 and it + 1 < iterations:
            remaining = int((~done).sum())  # the one host read of this check
            if remaining == 0:
                break
            if compact and remaining <= done.shape[0] // 2:
                rows = torch.arange(done.shape[0], device=t.device) if index is None else index
                fin = torch.nonzero(done).reshape(-1)
                out.index_copy_(0, rows.index_select(0, fin), t.index_select(0, fin))
                keep = torch.nonzero(~done).reshape(-1)
                index = rows.index_select(0, keep)
                t, f, g, H, J, scale, x, done = (z.index_select(0, keep) for z in (t, f, g, H, J, scale, x, done))
                # what a batch holds per point (shared values pass through)
                dom = dom.take(keep)
                tol_move, noise = (z.index_select(0, keep) if z.ndim else z for z in (tol_move, noise))
                element = None if element is None else element.index_select(0, keep)
    if index is None:
        return t
    out.index_copy_(0, index, t)
    return out


# ----------------------------------------------------------------------------------------
# start points
# ----------------------------------------------------------------------------------------
def _as_eval(t: Tensor, k: int) -> Tensor:
    """``(..., M, k)`` -> what ``evaluate`` takes: ``(..., M)`` for curves, ``(..., M, 2)`` for surfaces."""
    return t[..., 0] if k == 1 else t


def _resolution(spline, grid) -> tuple[int, ...]:
    k = spline.para_dim
    if grid is None:
        return tuple(max(4 * n, 32) for n in spline.sizes)
    res = (int(grid),) * k if isinstance(grid, int) else tuple(int(r) for r in grid)
    if len(res) != k or min(res) < 2:
        raise NurbskitError(f"grid must be {k} integer(s) >= 2 (samples per parametric direction), got {grid!r}")
    return res


def _grid_starts(spline, points: Tensor, grid, chunk: int, starts: int = 1,
                 elements: int | None = None) -> tuple[Tensor, Tensor]:
    """Start parameters for Newton: ``rows (E,)`` (indices into the points) and ``t0 (E, k)``.

    Each point starts from its ``starts`` nearest grid samples (for one spline the first
    ``N`` entries are each point's nearest one, in order), found by
    :mod:`nurbskit.core.neighbors`. Samples
    where the map degenerates (the pole of a sphere patch, ``C_u = 0``) are saddles for
    Newton: the gradient along the collapsed direction vanishes there, so Newton cannot
    leave them towards a boundary minimum nearby. When the grid has such samples, every
    point therefore also starts from its nearest regular sample (the degenerate point
    itself may be the true foot point); deciding this per grid, not per point, keeps the
    number of starts independent of the data (no host read per point).

    A flat batch of ``elements`` splines takes ``points (Bt * N, dim)``, element by
    element: the grids of all elements are evaluated in one call, their degenerate
    samples found together (one host read), and the nearest samples searched in one
    call (each element's points in its own grid); ``rows`` index the flat points.
    """
    res = spline._resolution(_resolution(spline, grid), op="project_points' start grid")
    # evenly over the non-empty knot spans, not the parameter: where knots cluster (a fit's
    # knots moved to the detail) a uniform grid left most of the curve to a few samples,
    # and points started in the wrong basin (measured: 293 of 2,000 points off by up to
    # 5.6 on a spiral with knots (i / s)^5); a repeated knot's empty spans get no samples
    # (counting them put a third of a circle's samples on its double knots, and the mean
    # distance of a surface of revolution rose 0.6 %); (R_a,), or (Bt, R_a) per element
    axes = [_tp.span_axis(kv.detach(), p, n, r)
            for kv, p, n, r in zip(spline.knot_vectors, spline.degrees, spline.sizes, res)]
    k, dim = spline.para_dim, spline.dim
    lead = () if elements is None else (elements,)
    D = spline.evaluate_grid(*axes, order=1).reshape(lead + (-1,) + (2,) * k + (dim,))
    if k == 1:
        samples, J = D[..., 0, :], D[..., 1:2, :]
    else:
        samples, J = D[..., 0, 0, :], torch.stack([D[..., 1, 0, :], D[..., 0, 1, :]], dim=-2)
    # the parameters of the samples, in their order (u slowest): (*lead, G, k)
    mesh = [a.reshape(a.shape[:-1] + (1,) * i + (res[i],) + (1,) * (k - 1 - i)).expand(lead + tuple(res))
            for i, a in enumerate(axes)]
    table = torch.stack([m.reshape(lead + (-1,)) for m in mesh], dim=-1)
    JJ = J @ J.transpose(-1, -2)
    gram = JJ[..., 0, 0] if k == 1 else JJ[..., 0, 0] * JJ[..., 1, 1] - JJ[..., 0, 1] * JJ[..., 1, 0]
    regular = gram > 1e-12 * gram.amax(-1, keepdim=True)
    degenerate = (~regular.all(-1) & regular.any(-1)).reshape(-1).tolist()  # per grid: the one host read
    x = points.detach().to(samples.dtype)
    n = x.shape[0] // (elements or 1)
    xs = x if elements is None else x.view(elements, n, dim)
    if starts == 1 and _use_coarse(samples.device, n * samples.shape[-2]):
        idx = (_coarse_to_fine(samples, res, x) if elements is None else
               torch.stack([_coarse_to_fine(samples[e], res, xs[e]) for e in range(elements)]))[..., None]
    else:  # a batch in one call: one KD-tree per element on the CPU, the same tiles on CUDA
        idx = k_nearest(xs, samples, starts).to(table.device)  # (*lead, N, count)
    own = torch.arange(x.shape[0], device=table.device)
    rows, t0 = [], []
    for j in range(idx.shape[-1]):  # the j-th nearest sample of every point
        rows.append(own)
        if elements is None:
            t0.append(table.index_select(0, idx[:, j]))
        else:
            t0.append(torch.gather(table, 1, idx[..., j : j + 1].expand(-1, -1, k)).reshape(-1, k))
    for e, extra in enumerate(degenerate):
        if extra:  # every point of the element also starts from its nearest regular sample
            S, T, R = (samples, table, regular) if elements is None else (samples[e], table[e], regular[e])
            keep = torch.nonzero(R).reshape(-1)
            sub = k_nearest(xs if elements is None else xs[e], S.index_select(0, keep), 1)[:, 0]
            rows.append(own[e * n : (e + 1) * n])
            t0.append(T.index_select(0, keep.index_select(0, sub)))
    # within each element, its starts in the order a single spline gives them
    return torch.cat(rows), torch.cat(t0)


#: Above this many point-sample pairs an accelerator searches the grid coarse to fine.
_COARSE_PAIRS = 1 << 27


def _use_coarse(device: torch.device, pairs: int) -> bool:
    """Coarse-to-fine grid search on accelerators for large inputs; the CPU's KD-tree is
    exact and fast at any size."""
    return device.type != "cpu" and pairs > _COARSE_PAIRS


def _coarse_to_fine(samples: Tensor, res: Sequence[int], x: Tensor, block: int = 1 << 18) -> Tensor:
    """Index ``(N,)`` of a near-nearest sample of a parametric grid, in two levels.

    ``samples (G, dim)`` on the grid ``res`` (u slowest). Level 1: the exact nearest
    sample of a sub-grid of every ``s``-th sample per direction (``s ~ sqrt(r / 2)``, so
    the sub-grid and the window below have about the same size). Level 2: the exact
    nearest sample in the ``(2 s + 1)^k`` window of the full grid around it. It uses the
    grid's structure instead of ``N x G`` distances (1e6 points on 128^2 samples: about
    1e9 pairs instead of 1.6e10); where the surface folds back on itself within a coarse
    cell the start may be a near neighbour rather than the nearest, which only moves
    Newton's start within the same neighbourhood.
    """
    k, dim = len(res), samples.shape[-1]
    dev = samples.device
    strides = [max(2, int(round((r / 2) ** 0.5))) for r in res]
    picks = [sorted(set(range(0, r, st)) | {r - 1}) for r, st in zip(res, strides)]
    pick_t = [torch.tensor(pk, dtype=torch.int64, device=dev) for pk in picks]
    grid = samples.reshape(*res, dim)
    coarse = grid
    for a, pk in enumerate(pick_t):
        coarse = coarse.index_select(a, pk)
    c = k_nearest(x, coarse.reshape(-1, dim), 1)[:, 0]  # (N,) into the coarse grid
    centre = []
    for a in reversed(range(k)):  # unravel, last axis fastest
        centre.append(pick_t[a].index_select(0, c % len(picks[a])))
        c = c // len(picks[a])
    centre = centre[::-1]  # fine index of the coarse sample, per axis (N,)
    offsets = [torch.arange(-st, st + 1, device=dev) for st in strides]
    flat = None
    stride = 1
    for a in reversed(range(k)):
        shape = [1] * (k + 1)
        shape[a + 1] = offsets[a].numel()
        ia = (centre[a][:, None] + offsets[a][None]).clamp(0, res[a] - 1)  # (N, w_a)
        shape[0] = -1
        term = ia.reshape(shape) * stride
        flat = term if flat is None else flat + term
        stride *= res[a]
    flat = flat.reshape(x.shape[0], -1)  # (N, W) fine indices of the window
    out = torch.empty(x.shape[0], dtype=torch.int64, device=dev)
    for i in range(0, x.shape[0], block):
        f = flat[i : i + block]
        cand = samples.index_select(0, f.reshape(-1)).reshape(f.shape[0], f.shape[1], dim)
        d = (cand[..., 0] - x[i : i + block, None, 0]).square()
        for j in range(1, dim):
            d.add_((cand[..., j] - x[i : i + block, None, j]).square())
        out[i : i + block] = f.gather(1, d.argmin(dim=1, keepdim=True))[:, 0]
    return out


def nearest_grid_params(spline, points: Tensor, grid: int | Sequence[int] | None = None, chunk: int = 65536) -> Tensor:
    """Parameters of the nearest sample of a uniform parametric grid (the Newton start).

    Shapes: ``points (N, dim)`` -> ``(N, k)`` (k = ``spline.para_dim``). ``grid`` is the
    number of samples per direction; default ``max(4 * n, 32)`` for ``n`` control points.

    Example:
        >>> import torch
        >>> from nurbskit import NURBSSurface
        >>> s = NURBSSurface(torch.rand(4, 4, 3, dtype=torch.float64))
        >>> nearest_grid_params(s, torch.rand(10, 3, dtype=torch.float64)).shape
        torch.Size([10, 2])
    """
    with torch.no_grad():
        return _grid_starts(spline.detach(), points, grid, chunk)[1][: points.shape[0]]


def periodic_directions(spline, tol: float | None = None) -> tuple[bool, ...]:
    """Which parametric directions close on themselves, so that projection wraps across
    the seam: either periodic (a periodic knot spacing and the last ``p`` control columns
    and weights repeating the first ``p``: continuity ``C^{p-1}`` at the seam, the fit's
    closed v, :func:`nurbskit.fit.params.periodic_knots`) or closed and clamped (end
    knots of multiplicity ``p + 1`` and the last control column and weights equal to the
    first, as a full revolution's nine-point circle: the seam is only ``C^0`` in the
    parameter, but the point at the domain's end is the point at its start, so a Newton
    step may leave at one end and come back in at the other). Equality is up to ``tol`` relative to the size of the
    control net (default ``64 eps``). Reads one value back to the host: pass
    ``periodic=`` to :func:`project_points` inside loops. A batch of splines gets one
    tuple per element (flattened batch order); :func:`project_points` judges each
    element on its own.

    Example:
        >>> import torch
        >>> from nurbskit import NURBSCurve
        >>> P = torch.tensor([[1., 0.], [0., 1.], [-1., 0.], [0., -1.], [1., 0.], [0., 1.]], dtype=torch.float64)
        >>> knots = torch.arange(-2.0, 7.0, dtype=torch.float64) / 4
        >>> periodic_directions(NURBSCurve(P, degree=2, knot_vector=knots))
        (True,)
    """
    mask = _periodic_mask(spline, tol)
    if mask.ndim > 1:
        return tuple(tuple(bool(v) for v in row) for row in mask.reshape(-1, mask.shape[-1]).tolist())
    return tuple(bool(v) for v in mask.tolist())  # the one host read


def _periodic_mask(spline, tol: float | None = None) -> Tensor:
    """:func:`periodic_directions` as a bool tensor ``(k,)``, or ``(Bt, k)`` for a flat batch
    (control points ``(Bt, n_1, ..., dim)``, knots ``(m,)`` or ``(Bt, m)``), each element
    judged on its own; reads nothing back to the host."""
    with torch.no_grad():
        cp, w = spline.control_points.detach(), spline.weights.detach()
        k = spline.para_dim
        lead = tuple(cp.shape[: cp.ndim - k - 1])
        eps = torch.finfo(cp.dtype).eps
        flat = cp.reshape(lead + (-1, cp.shape[-1]))
        size = (flat.amax(-2) - flat.amin(-2)).norm(dim=-1, keepdim=True)  # (*lead, 1)
        size = torch.where(size > 0, size, torch.ones_like(size))
        w_max = w.abs().reshape(lead + (-1,)).amax(-1, keepdim=True)
        rel = (64 * eps) if tol is None else float(tol)

        def within(a, b, scale):  # every entry of a - b (leading batch axes kept) within rel * scale
            return ((a - b).abs().reshape(lead + (-1,)) <= rel * scale).all(-1)

        out = []
        for a, (kv, p, n) in enumerate(zip(spline.knot_vectors, spline.degrees, spline.sizes)):
            kv = kv.detach()
            if p < 1 or n <= p:
                out.append(torch.zeros(lead, dtype=torch.bool, device=cp.device))
                continue
            ax = len(lead) + a
            gaps = kv[..., 1:] - kv[..., :-1]  # n + p gaps; period n - p
            span = (kv[..., n] - kv[..., p]).unsqueeze(-1)
            span = torch.where(span != 0, span, torch.ones_like(span))
            same_gaps = ((gaps[..., : 2 * p] - gaps[..., n - p : n + p]).abs() <= rel * span).all(-1)
            clamped = (gaps[..., :p].abs() <= rel * span).all(-1) & (gaps[..., n:].abs() <= rel * span).all(-1)
            periodic = (same_gaps & within(cp.narrow(ax, 0, p), cp.narrow(ax, n - p, p), size)
                        & within(w.narrow(ax, 0, p), w.narrow(ax, n - p, p), w_max))
            closed = (clamped & within(cp.narrow(ax, 0, 1), cp.narrow(ax, n - 1, 1), size)
                      & within(w.narrow(ax, 0, 1), w.narrow(ax, n - 1, 1), w_max))
            out.append(periodic | closed)
        return torch.stack(torch.broadcast_tensors(*out), -1)


# ----------------------------------------------------------------------------------------
# public entry points
# ----------------------------------------------------------------------------------------
def _batch_shape(spline) -> tuple[int, ...]:
    """Leading batch dimensions of a spline's control points ``(*B, n_1..n_k, dim)``."""
    return tuple(spline.control_points.shape[: spline.control_points.ndim - spline.para_dim - 1])


def project_points(
    spline,
    points,
    *,
    grid: int | Sequence[int] | None = None,
    starts: int = 1,
    iterations: int = 32,
    tol: float | None = None,
    chunk: int | None = None,
    periodic: Sequence[bool] | None = None,
    params: Tensor | None = None,
    restart: bool = False,
    check_every: int = 4,
    validate: bool = True,
    second_order: bool = True,
) -> Projection:
    """Closest points on a NURBS surface (or curve) to many points, differentiably.

    Where a spline turns a corner at a knot (an interior knot of multiplicity ``>= p``
    across which the tangent turns: a polyline's vertices, a crease; in a direction that
    wraps, also a seam that is a corner, as on a closed polygon), the squared distance has
    a kink there, across which Newton would overshoot and stop short: a call that starts
    from the grid refines within the smooth pieces (the corners, and the seam of a wrapping
    direction that has any, are edges of each start's box) and starts again across the
    knot a result ends on; in a batch each element by its own knots and control points. A
    warm call (``params`` without ``restart``) does not, so that it reads nothing back.
    Knots of multiplicity ``>= p`` where the tangent keeps its direction (the double knots
    of a rational circle) are no corners: the distance is smooth across them.

    Args:
        spline: a :class:`NURBSSurface` (or :class:`NURBSCurve`; see
            :func:`project_points_curve`), possibly batched: control points
            ``(*B, n_u, n_v, dim)`` (see Convention).
        points: ``(..., N, dim)`` with ``dim == spline.dim``; converted to the spline's
            dtype and device. For a batched spline ``(*B, N, dim)``.
        grid: samples per parametric direction for the start points (int or one per
            direction); default ``max(4 * n, 32)`` for ``n`` control points.
        starts: refine from this many nearest grid samples per point and keep the closest
            result. Newton finds the local minimum whose basin holds its start; far from a
            curved surface (beyond its radius of curvature) two basins can nearly tie, and
            more starts make picking the wrong one rarer, at ``starts`` times the cost.
        iterations: at most this many Newton iterations (each point stops on its own).
        tol: a point stops once its Newton step moves the foot point by less than
            ``tol`` times the diagonal of the control net's bounding box; default
            ``eps ** 0.75`` of the dtype (about 2e-12 in float64, 6e-6 in float32).
        chunk: points refined together; bounds the memory of one iteration. Default
            65,536 on the CPU (cache-sized), 2^20 on accelerators (fewer launches).
        periodic: one bool per parametric direction: a periodic direction (periodic knot
            spacing, last ``p`` control columns repeating the first ``p``) has no edge;
            Newton steps across its seam and wraps. Default: detected
            (:func:`periodic_directions`, a few host reads).
        params: warm start ``(..., N, 2)`` (``(..., N)`` for curves), e.g. the foot
            points of a previous, nearby surface: Newton starts there instead of at the
            grid (no grid is built).
        restart: with ``params``, also start from the grid and keep the closer result
            per point (a foot point can jump to another part of the surface).
        check_every: read one value back every this many iterations to stop once all
            points have converged; 0 runs all ``iterations`` and reads nothing.
        validate: check the points for NaN and infinity (one host read); loops that
            already checked their input pass False.
        second_order: Newton with the full Hessian (default); False: Gauss-Newton
            (``J J^T``, first derivatives only, about a third of the work per iteration,
            linear convergence where the residual is large): for a few warm iterations
            inside a loop whose surface moves little per step.

    Returns:
        ``Projection(params, closest, distance)``: ``params (..., N, 2)`` (``(..., N)`` for
        curves) detached, ``closest (..., N, dim)`` and ``distance (..., N)`` with gradients
        (envelope theorem: foot-point parameters held fixed).

    Convention: a batched spline (control points ``(*B, n_u, n_v, dim)``, knots shared
    ``(m,)`` or per element ``(*B, m)``) takes points ``(*B, N, dim)`` and projects each
    batch element onto its own surface, in one pass: one grid evaluation for all
    elements, the nearest-sample search per element, then Newton on every element's
    points together (each point evaluates its own element; periodic directions,
    domains and tolerances are each element's). The results are those of projecting
    each element alone (the same iterates point by point), and a warm call's operations
    do not grow with the batch (``benchmarks/bench_projection_batch.py``).

    Example:
        >>> import torch
        >>> from nurbskit import NURBSSurface
        >>> g = torch.linspace(0, 1, 4, dtype=torch.float64)
        >>> cp = torch.stack([*torch.meshgrid(g, g, indexing="ij"), torch.zeros(4, 4, dtype=torch.float64)], -1)
        >>> plane = NURBSSurface(cp, degrees=(3, 3))  # the unit square in z = 0
        >>> params, closest, distance = project_points(plane, torch.tensor([[0.25, 0.5, 2.0]], dtype=torch.float64))
        >>> params, distance
        (tensor([[0.2500, 0.5000]], dtype=torch.float64), tensor([2.], dtype=torch.float64))
    """
    k = getattr(spline, "para_dim", None)
    if k not in (1, 2):
        raise NurbskitError(
            f"project_points takes a NURBSSurface or NURBSCurve, got {type(spline).__name__}"
            + (f" with {k} parametric directions" if k is not None else "")
        )
    x = torch.as_tensor(points) if not isinstance(points, Tensor) else points
    if not x.is_floating_point():
        x = x.to(spline.dtype)
    x = x.to(dtype=spline.dtype, device=spline.device)
    if x.ndim < 2 or x.shape[-1] != spline.dim:
        raise NurbskitError(
            f"project_points: points must have shape (..., N, {spline.dim}) to match the {spline.kind}'s "
            f"dimension, got {tuple(x.shape)}"
        )
    if iterations < 0:
        raise NurbskitError(f"project_points: iterations must be >= 0, got {iterations}")
    if starts < 1:
        raise NurbskitError(f"project_points: starts must be >= 1, got {starts}")
    if tol is not None and not float(tol) > 0:
        raise NurbskitError(f"project_points: tol must be a positive number, got {tol!r}")
    if check_every < 0:
        raise NurbskitError(f"project_points: check_every must be >= 0 (0: never read back), got {check_every}")
    if params is not None:
        params = params if isinstance(params, Tensor) else torch.as_tensor(params, dtype=torch.float64)
        want = tuple(x.shape[:-1]) + ((k,) if k > 1 else ())
        if tuple(params.shape) != want:
            raise NurbskitError(f"project_points: params must have shape {want}, one start per point, "
                                f"got {tuple(params.shape)}")
        if validate and not torch.isfinite(params.detach()).all():
            raise NurbskitError("project_points: params (the warm start) contain NaN or infinite values")
    if chunk is None:
        chunk = 65536 if spline.device.type == "cpu" else 1 << 20
    if chunk < 1:
        raise NurbskitError(f"project_points: chunk must be >= 1, got {chunk}")
    if periodic is not None:
        periodic = tuple(bool(p) for p in periodic)
        if len(periodic) != k:
            raise NurbskitError(f"project_points: periodic needs {k} value(s), one per parametric direction, got {periodic!r}")
    options = dict(grid=grid, starts=starts, iterations=iterations, tol=tol, chunk=chunk, restart=restart,
                   check_every=check_every, validate=validate, second_order=second_order)

    batch_shape = _batch_shape(spline)
    if not batch_shape:
        return _project(spline, x, periodic, params, None, **options)
    if tuple(x.shape[: len(batch_shape)]) != batch_shape or x.ndim != len(batch_shape) + 2:
        raise NurbskitError(
            f"project_points: a spline batch {batch_shape} takes points {batch_shape + ('N', spline.dim)}, "
            f"got {tuple(x.shape)}"
        )
    # A batch: flattened to Bt elements and projected in one pass (see _project).
    count = math.prod(batch_shape)
    flat = spline._replace(
        control_points=spline.control_points.reshape(count, *spline.control_points.shape[len(batch_shape):]),
        weights=spline.weights.reshape(count, *spline.weights.shape[len(batch_shape):]),
        knot_vectors=[kv if kv.ndim == 1 else kv.reshape(count, kv.shape[-1]) for kv in spline.knot_vectors],
        validate=False,
    )
    warm = None if params is None else torch.as_tensor(params).reshape(count, x.shape[-2], k)
    res = _project(flat, x.reshape(count, *x.shape[len(batch_shape):]), periodic, warm, count, **options)
    return Projection(*(z.reshape(batch_shape + z.shape[1:]) for z in res))


def _project(
    spline, x: Tensor, periodic, warm, elements: int | None, *, grid, starts, iterations, tol, chunk, restart,
    check_every, validate, second_order,
):
    """:func:`project_points` on one spline (``elements`` None; points ``(..., N, dim)``) or
    on a flat batch of ``elements`` splines (control points ``(Bt, ...)``, knots ``(m,)``
    or ``(Bt, m)``; points ``(Bt, N, dim)``, warm starts ``(Bt, N, k)``).

    A batch is projected in one pass: the start search runs per element (its KD-tree or
    tiled search reads one element's grid), then the Newton iterations run on the points
    of every element together, each point evaluating its own element (``element`` rows
    into the batch's control points), with each element's domain, periodic directions
    and tolerances, so that every result is the one its element gives alone.
    """
    k, dim = spline.para_dim, spline.dim
    lead = x.shape[:-1]
    flat = x.reshape(-1, dim)
    total = flat.shape[0]
    n = total if elements is None else x.shape[1]  # points per element
    with torch.no_grad():
        xd = flat.detach()
        if validate and not torch.isfinite(xd).all():
            raise NurbskitError("project_points: points contain NaN or infinite values")
        fixed = spline.detach()
        if periodic is None:
            # one bool per direction; for a batch one per element and direction, kept on the device
            periodic = periodic_directions(fixed) if elements is None else _periodic_mask(fixed)
        dom = _domain(fixed, periodic)
        eps = torch.finfo(spline.dtype).eps
        cp = fixed.control_points.reshape(elements or 1, -1, dim)
        size = (cp.amax(1) - cp.amin(1)).norm(dim=-1)  # (1,) or (Bt,): each element's own scale
        size = torch.where(size > 0, size, torch.ones_like(size))  # a tensor: no host read
        if elements is None:
            size = size[0]
        tol_move = (eps ** 0.75 if tol is None else float(tol)) * size
        noise = eps * size
        found = torch.empty(0, k, dtype=spline.dtype, device=spline.device)
        if total:
            rows, starts_t = [], []
            if warm is not None:
                w = torch.as_tensor(warm).to(dtype=spline.dtype, device=spline.device).detach()
                rows.append(torch.arange(total, device=w.device))
                starts_t.append(w.reshape(total, k))
            if warm is None or restart:
                r, t0 = _grid_starts(fixed, xd, grid, chunk, starts, elements)
                rows.append(r)
                starts_t.append(t0)
            rows, starts_t = ((z[0] if len(z) == 1 else torch.cat(z)) for z in (rows, starts_t))
            targets = xd.index_select(0, rows)

            def element_of(rows):  # each start's element of a batch (None: one spline)
                return None if elements is None else torch.div(rows, n, rounding_mode="floor")

            def per_start(element):  # each start's domain (one spline's is shared)
                return dom if element is None else dom.take(element)

            element = element_of(rows)
            Pw = _tp.homogeneous(fixed.control_points, fixed.weights).contiguous()

            def rows_of(z, i):  # a chunk of a per-start value; shared values pass through
                return z if z is None or z.ndim == 0 else z[i : i + chunk]

            def refine(starts_t, targets, box, element):
                # the tolerances of each start's element (one spline's are shared)
                tm, nz = (z if element is None else z.index_select(0, element) for z in (tol_move, noise))
                return torch.cat([
                    _newton(fixed, Pw, starts_t[i : i + chunk], targets[i : i + chunk],
                            box if box.lo.ndim < 2 else _Domain(*(z[i : i + chunk] for z in box)), iterations,
                            rows_of(tm, i), rows_of(nz, i), check_every, second_order, rows_of(element, i))
                    for i in range(0, starts_t.shape[0], chunk)
                ])

            # C0 knots: found on the host, so only where the call reads anyway (a cold start
            # from the grid); a warm call inside a loop reads nothing back
            breaks = _c0_breaks(fixed, Pw, periodic, elements) if warm is None or restart else None
            if breaks is None:
                found = refine(starts_t, targets, per_start(element), element)
            else:  # Newton within the smooth pieces between C0 knots, then across the knots it ends on
                rows, found = _across_c0_knots(refine, per_start, breaks, rows, starts_t, targets, element_of)
                targets = xd.index_select(0, rows)
                element = element_of(rows)
            if rows.numel() > total:
                # several starts for some points: keep the closest result, without a host read
                C = _tp.derivatives_from_homogeneous(Pw, fixed.knot_vectors, fixed.degrees, found, 0, element)
                f = (C.reshape(-1, dim) - targets).square().sum(-1)
                best = torch.full((total,), float("inf"), dtype=f.dtype, device=f.device)
                best = best.scatter_reduce(0, rows, f, reduce="amin")
                order = torch.arange(rows.numel(), device=rows.device)
                # ties: the earliest start wins, deterministically on every device
                candidate = torch.where(f <= best.index_select(0, rows), order, torch.full_like(order, rows.numel()))
                choice = torch.full((total,), rows.numel(), dtype=torch.int64, device=rows.device)
                choice = choice.scatter_reduce(0, rows, candidate, reduce="amin")
                found = found.index_select(0, choice)
    # Foot points with autograd (the envelope theorem; see the module docstring). The
    # params lie in the domain by construction: no domain check (it would read back to the host).
    if elements is None:
        params = _as_eval(found, k)
        closest = spline.evaluate(params, extrapolate=True)
        distance = (flat - closest).norm(dim=-1)
        return Projection(params.reshape(lead + params.shape[1:]), closest.reshape(lead + (dim,)),
                          distance.reshape(lead))
    params = _as_eval(found.reshape(elements, n, k), k)
    closest = spline.evaluate(params, extrapolate=True)  # each element at its own parameters
    return Projection(params, closest, (x - closest).norm(dim=-1))


def project_points_curve(
    curve,
    points,
    *,
    grid: int | None = None,
    starts: int = 1,
    iterations: int = 32,
    tol: float | None = None,
    chunk: int | None = None,
    **options,
) -> Projection:
    """Closest points on a NURBS curve: :func:`project_points` in one parameter.

    Shapes: ``points (..., N, dim)`` -> ``params (..., N)``, ``closest (..., N, dim)``,
    ``distance (..., N)``. The end points are the edges of the domain: a point beyond an
    end projects onto it (unless the curve is periodic). ``options`` are those of
    :func:`project_points` (``periodic``, ``params``, ``restart``, ``check_every``, ``validate``).

    Example:
        >>> import torch
        >>> from nurbskit import NURBSCurve
        >>> quarter = NURBSCurve(torch.tensor([[1., 0.], [1., 1.], [0., 1.]], dtype=torch.float64), degree=2,
        ...                      weights=torch.tensor([1., 2 ** -0.5, 1.], dtype=torch.float64))
        >>> project_points_curve(quarter, torch.tensor([[2., 2.]], dtype=torch.float64)).distance
        tensor([1.8284], dtype=torch.float64)
    """
    if getattr(curve, "para_dim", None) != 1:
        raise NurbskitError(f"project_points_curve takes a NURBSCurve, got {type(curve).__name__}")
    return project_points(curve, points, grid=grid, starts=starts, iterations=iterations, tol=tol, chunk=chunk, **options)
