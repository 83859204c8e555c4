"""Tensor-product rational B-splines of any parametric dimension: one mechanism for
curves (k = 1), surfaces (k = 2) and volumes (k = 3).

Convention: control points ``(n_1, ..., n_k, dim)`` with the first parametric
direction on the first grid axis; weights ``(n_1, ..., n_k)``. Internally the
evaluation works on homogeneous points ``(w * P, w)`` and divides once at the end.

Two ways in:

* scattered parameters ``(..., M, k)``: spans by ``searchsorted``, the ``p + 1``
  non-zero basis values per direction, a gather of the local control block and one
  contraction (cost ``M * prod(p_a + 1)``);
* grids: dense basis matrices ``B_a (R_a, n_a)`` and ``k`` successive matrix products
  (``B_u @ Pw @ B_v^T`` for a surface), which is what BLAS and GPUs are built for.

Derivatives of the rational map use the generalised quotient rule
(The NURBS Book, eq. 4.8 / A4.4 for surfaces): for a multi-index ``alpha``,
``S^(alpha) = (A^(alpha) - sum_{0 != beta <= alpha} C(alpha, beta) w^(beta) S^(alpha - beta)) / w``.
"""

from __future__ import annotations

import itertools
import math
from math import comb
from typing import Sequence

import torch

from .basis import basis_function_derivatives, basis_functions, basis_matrix
from .knots import find_spans

Tensor = torch.Tensor


def homogeneous(control_points: Tensor, weights: Tensor) -> Tensor:
    """``(w * P, w)``: shapes ``(..., dim)``, ``(...)`` -> ``(..., dim + 1)``."""
    w = weights.unsqueeze(-1)
    return torch.cat([control_points * w, w], dim=-1)


def _gather_blocks(Pw: Tensor, spans: Sequence[Tensor], degrees: Sequence[int]) -> Tensor:
    """Local control blocks ``(..., M, p_1 + 1, ..., p_k + 1, D)`` for each point.

    One ``index_select`` on the flattened control net with a flat index built from the
    spans (advanced indexing with k index tensors is far slower on CPU).
    """
    k = len(degrees)
    sizes = Pw.shape[:k]
    flat = None
    stride = 1
    for a in reversed(range(k)):
        idx = spans[a].unsqueeze(-1) - degrees[a] + torch.arange(degrees[a] + 1, device=spans[a].device)
        shape = list(idx.shape[:-1]) + [1] * k
        shape[idx.ndim - 1 + a] = degrees[a] + 1
        term = idx.reshape(shape) * stride
        flat = term if flat is None else flat + term
        stride *= sizes[a]
    D = Pw.shape[-1]
    rows = Pw.reshape(-1, D).index_select(0, flat.reshape(-1))
    return rows.reshape(flat.shape + (D,))


def _contract(block: Tensor, bases: Sequence[Tensor]) -> Tensor:
    """Contract local blocks with per-direction basis values, one direction at a time.

    Shapes: ``block (M, s_1, ..., s_k, D)``, ``bases[a] (M, o + 1, s_a)`` ->
    ``(M, o + 1, ..., o + 1, D)``. Each step is one batched matrix product
    ``(M, 1, o + 1, s_a) @ (M, O, s_a, rest)``; on these tiny per-point blocks that beats
    both a many-operand ``einsum`` and broadcast multiply-and-sum.
    """
    M = block.shape[0]
    orders = [B.shape[-2] for B in bases]
    X = block
    done = 1  # product of the order axes produced so far
    for a, B in enumerate(bases):
        s_a = B.shape[-1]
        rest = math.prod(block.shape[a + 2 :])  # explicit: M may be 0
        X = torch.matmul(B.unsqueeze(1), X.reshape(M, done, s_a, rest))  # (M, done, o + 1, rest)
        done *= B.shape[-2]
    return X.reshape((M, *orders, block.shape[-1]))


def _local(Pw: Tensor, knot_vectors: Sequence[Tensor], degrees: Sequence[int], params: Tensor, order: int | None) -> Tensor:
    """Homogeneous values (``order`` None) or derivatives at ``params (..., M, k)``."""
    k = len(degrees)
    lead = params.shape[:-1]
    flat = params.reshape(-1, k)
    sizes = Pw.shape[:k]
    spans, bases = [], []
    for a in range(k):
        u = flat[:, a]
        s = find_spans(knot_vectors[a], degrees[a], sizes[a], u)
        spans.append(s)
        if order is None:
            bases.append(basis_functions(knot_vectors[a], degrees[a], s, u).unsqueeze(-2))
        else:
            bases.append(basis_function_derivatives(knot_vectors[a], degrees[a], s, u, order))
    h = _contract(_gather_blocks(Pw, spans, degrees), bases)
    if order is None:
        h = h.reshape(h.shape[0], h.shape[-1])
    return h.reshape(lead + h.shape[1:])


def homogeneous_derivatives_to_points(hders: Tensor, k: int) -> Tensor:
    """Quotient rule on homogeneous derivatives.

    Shapes: ``hders (..., o + 1, ... (k times), D)`` holding derivatives of ``(w P, w)``
    -> ``(..., o + 1, ..., D - 1)`` derivatives of ``P``.
    """
    order = hders.shape[-2] - 1
    A, w = hders[..., :-1], hders[..., -1:]
    S: dict[tuple, Tensor] = {}

    def at(t: Tensor, alpha: tuple) -> Tensor:
        return t[(Ellipsis,) + alpha + (slice(None),)]

    w0 = at(w, (0,) * k)
    for alpha in itertools.product(range(order + 1), repeat=k):
        value = at(A, alpha)
        for beta in itertools.product(*(range(a + 1) for a in alpha)):
            if not any(beta):
                continue
            coef = 1
            for a, b in zip(alpha, beta):
                coef *= comb(a, b)
            rest = tuple(a - b for a, b in zip(alpha, beta))
            value = value - coef * at(w, beta) * S[rest]
        S[alpha] = value / w0
    stacked = torch.stack([S[alpha] for alpha in itertools.product(range(order + 1), repeat=k)], dim=-2)
    return stacked.reshape(stacked.shape[:-2] + (order + 1,) * k + stacked.shape[-1:])


def evaluate(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    params: Tensor,
) -> Tensor:
    """Points of a rational tensor-product spline at scattered parameters.

    Shapes: ``control_points (n_1, ..., n_k, dim)``, ``weights (n_1, ..., n_k)``,
    ``params (..., M, k)`` -> ``(..., M, dim)``.
    """
    h = _local(homogeneous(control_points, weights), knot_vectors, degrees, params, None)
    return h[..., :-1] / h[..., -1:]


def derivatives(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    params: Tensor,
    order: int,
) -> Tensor:
    """All mixed partial derivatives up to ``order`` in each direction.

    Shapes: ``params (..., M, k)`` -> ``(..., M, order + 1, ... (k times), dim)``;
    entry ``[..., a, b, :]`` of a surface is the derivative ``a`` times in u and ``b``
    times in v; ``[..., 0, 0, :]`` is the point itself.
    """
    return homogeneous_derivatives_to_points(
        _local(homogeneous(control_points, weights), knot_vectors, degrees, params, order), len(degrees)
    )


def derivatives_from_homogeneous(
    Pw: Tensor, knot_vectors: Sequence[Tensor], degrees: Sequence[int], params: Tensor, order: int
) -> Tensor:
    """:func:`derivatives` from homogeneous control points ``Pw (n_1..n_k, dim + 1)``
    formed once by the caller (iterative solvers evaluate the same spline many times)."""
    return homogeneous_derivatives_to_points(_local(Pw, knot_vectors, degrees, params, order), len(degrees))


def _mode_products(Pw: Tensor, matrices: Sequence[Tensor]) -> Tensor:
    """``Pw (n_1..n_k, D)`` times ``matrices[a] (R_a, n_a)`` along each axis -> ``(D, R_1..R_k)``.

    The homogeneous channel goes first so that every product is one large GEMM on a
    reshaped view: each leading axis as a left product batched over what precedes it,
    the last axis as a single right product ``X @ B_k^T``. The result stays
    channel-first; callers divide and move the channel last (a free view).
    """
    X = torch.movedim(Pw, -1, 0)  # (D, n_1, ..., n_k)
    lead = [Pw.shape[-1]]
    batch = Pw.shape[-1]
    for B in matrices[:-1]:
        X = torch.matmul(B, X.reshape(batch, B.shape[1], -1))  # (batch, R_a, rest)
        lead.append(B.shape[0])
        batch *= B.shape[0]
    B = matrices[-1]
    X = X.reshape(-1, B.shape[1]) @ B.transpose(0, 1)
    return X.reshape(tuple(lead) + (B.shape[0],))


def evaluate_grid(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    axes: Sequence[Tensor],
    order: int = 0,
) -> Tensor:
    """Points (or derivatives) on the tensor grid ``axes[0] x axes[1] x ...``.

    Shapes: ``axes[a] (R_a,)`` -> ``(R_1, ..., R_k, dim)``; with ``order > 0``,
    ``(R_1, ..., R_k, order + 1, ... (k times), dim)`` laid out as :func:`derivatives`.
    """
    k = len(degrees)
    Pw = homogeneous(control_points, weights)
    sizes = control_points.shape[:k]
    if order == 0:
        matrices = [basis_matrix(knot_vectors[a], degrees[a], sizes[a], axes[a]) for a in range(k)]
        h = _mode_products(Pw, matrices)
        return torch.movedim(h[:-1] / h[-1:], 0, -1)
    # Stack the derivative orders into the rows: B_a ((o+1) * R_a, n_a).
    mats = [basis_matrix(knot_vectors[a], degrees[a], sizes[a], axes[a], order) for a in range(k)]
    h = _mode_products(Pw, [m.reshape(-1, m.shape[-1]) for m in mats])
    lengths = [len(ax) for ax in axes]
    h = h.reshape([Pw.shape[-1]] + sum(([order + 1, r] for r in lengths), []))
    # (D, o, R_1, o, R_2, ...) -> (R_1, ..., R_k, o, ..., o, D)
    perm = [2 * a + 2 for a in range(k)] + [2 * a + 1 for a in range(k)] + [0]
    return homogeneous_derivatives_to_points(h.permute(perm), k)
