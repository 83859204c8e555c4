"""B-spline basis functions and their derivatives, vectorised over parameters and degree.

The ``p + 1`` non-zero basis values on a span follow the triangular recurrence of
The NURBS Book (Piegl and Tiller) A2.2, and their derivatives the difference formula
behind A2.3 (eq. 2.9): ``N'_{i,q} = q (N_{i,q-1} / (u_{i+q} - u_i) - N_{i+1,q-1} / (u_{i+q+1} - u_{i+1}))``.
Both are written level by level on whole vectors (``(..., q + 1)`` at level ``q``), so a
degree-``p`` basis is about ``8 p`` tensor operations however many parameters there
are, and autograd differentiates the piecewise polynomial basis exactly with respect
to the knots and the parameters; only the span search (piecewise constant) is done on
detached values.

Convention: knots are ``(m,)`` (shared) or ``(*B, m)`` (one vector per batch element,
with ``spans`` and ``u`` of shape ``(*B, ...)``). On a non-empty span every denominator
``knots[span + 1 + r] - knots[span + 1 + r - q]`` contains the span itself, so it is
positive: nothing is divided by zero, and :func:`nurbskit.core.knots.knot_tolerance`
keeps spans from being too short to divide by.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .knots import find_spans

Tensor = torch.Tensor


def _take(values: Tensor, index: Tensor) -> Tensor:
    """``values[index]`` for a 1-D ``values`` and any-shaped ``index``.

    ``index_select`` on a flat index: on CPU, advanced indexing (and ``take``) of a
    small tensor costs about 1 ms per 1,000 indices, ``index_select`` a thousandth of that.
    """
    return values.index_select(0, index.reshape(-1)).reshape(index.shape)


def knot_window(knots: Tensor, degree: int, spans: Tensor) -> Tensor:
    """``K[..., t] = knots[span - p + 1 + t]`` for ``t = 0 .. 2p - 1``: the knots a span's basis uses.

    Shapes: ``knots (m,)`` with ``spans (...)``, or ``knots (*B, m)`` with ``spans (*B, ...)``
    -> ``(..., 2p)``. ``K[p - 1]`` and ``K[p]`` are the span's own ends.
    """
    p = degree
    index = spans.unsqueeze(-1) + torch.arange(1 - p, p + 1, device=spans.device)
    if knots.ndim == 1:
        return _take(knots, index)
    lead = knots.shape[:-1]
    flat = index.reshape(lead + (-1,))
    return torch.gather(knots, -1, flat).reshape(index.shape)


def _levels(K: Tensor, degree: int, u: Tensor) -> tuple[list[Tensor], list[Tensor]]:
    """Basis values of every degree ``q = 0..p`` on the span, and the level denominators.

    ``values[q] (..., q + 1)`` holds ``N[span - q + r, q](u)``; ``dens[q] (..., q)`` holds
    ``knots[span + 1 + r] - knots[span + 1 + r - q]`` (A2.2's ``right[r+1] + left[q-r]``).
    """
    p = degree
    u = u.unsqueeze(-1)
    left = u - K[..., :p]  # left[t] = u - knots[span - p + 1 + t]
    right = K[..., p:] - u  # right[r] = knots[span + 1 + r] - u
    values = [torch.ones_like(u)]
    dens: list[Tensor] = [u[..., :0]]
    for q in range(1, p + 1):
        R, L = right[..., :q], left[..., p - q :]
        den = R + L
        # (R N) / den, not R (N / den): at a domain end (or a knot of multiplicity p) one of
        # R, L is 0 and the other is den, so the function that survives is x / x = 1
        # exactly, where x (1 / x) can be 1 - 2^-53 (a surface's corner then missed its
        # control point by an ulp)
        N = values[-1]
        values.append(F.pad(R * N / den, (0, 1)) + F.pad(L * N / den, (1, 0)))
        dens.append(den)
    return values, dens


def basis_functions(knots: Tensor, degree: int, spans: Tensor, u: Tensor) -> Tensor:
    """Non-zero basis values ``N[span - p + j, p](u)``, j = 0..p (The NURBS Book A2.2).

    Shapes: ``spans (...)``, ``u (...)`` -> ``(..., p + 1)`` (knots as in the module docstring).
    """
    if degree == 0:
        return torch.ones_like(u).unsqueeze(-1)
    values, _ = _levels(knot_window(knots, degree, spans), degree, u)
    return values[-1]


def basis_function_derivatives(knots: Tensor, degree: int, spans: Tensor, u: Tensor, order: int) -> Tensor:
    """Basis values and derivatives up to ``order`` on each span (The NURBS Book A2.3, eq. 2.9).

    Shapes: ``spans (...)``, ``u (...)`` -> ``(..., order + 1, p + 1)``, where
    ``[..., k, j]`` is the k-th derivative of ``N[span - p + j, p]`` at ``u``.
    Derivatives above the degree are zero.

    The k-th derivative applies the difference operator ``q (E[r-1] - E[r])`` with
    ``E[r] = G[r] / dens[q][r]`` for ``q = p - k + 1 .. p`` to the degree ``p - k`` values.
    """
    return window_basis_derivatives(knot_window(knots, degree, spans), degree, u, order)


def window_basis_derivatives(K: Tensor, degree: int, u: Tensor, order: int) -> Tensor:
    """:func:`basis_function_derivatives` from the knot window ``K (..., 2p)`` of
    :func:`knot_window`: ``u (...)`` -> ``(..., order + 1, p + 1)``.

    The directions of a tensor-product spline with one degree share it: their windows
    and parameters stacked on a leading axis make one pass of the recurrence for all.
    """
    p = degree
    values, dens = _levels(K, p, u)
    rows = [values[p]]
    for k in range(1, order + 1):
        if k > p:
            rows.append(torch.zeros_like(values[p]))
            continue
        G = values[p - k]
        for q in range(p - k + 1, p + 1):
            E = G / dens[q]
            G = (F.pad(E, (1, 0)) - F.pad(E, (0, 1))) * q
        rows.append(G)
    return torch.stack(rows, dim=-2)


def basis_matrix(knots: Tensor, degree: int, n_ctrl: int, u: Tensor, order: int = 0) -> Tensor:
    """Dense basis matrix: ``B[..., i] = N[i, p](u)`` (or its derivatives).

    Shapes: ``u (M,)`` -> ``(M, n_ctrl)`` for ``order == 0``, else
    ``(order + 1, M, n_ctrl)`` with the k-th derivative in slice ``k``. With one knot
    vector per batch element, ``knots (*B, m)`` and ``u (*B, M)`` (or ``(M,)``, shared) ->
    ``(*B, M, n_ctrl)`` or ``(*B, order + 1, M, n_ctrl)``.
    A grid of a surface is then ``B_u @ Pw @ B_v^T`` (see ``tensor.evaluate_grid``).
    """
    if knots.ndim > 1 and u.shape[:-1] != knots.shape[:-1]:
        u = u.expand(knots.shape[:-1] + u.shape[-1:])
    spans = find_spans(knots, degree, n_ctrl, u)
    columns = spans.unsqueeze(-1) - degree + torch.arange(degree + 1, device=u.device)
    if order == 0:
        values = basis_functions(knots, degree, spans, u)
        return u.new_zeros(u.shape + (n_ctrl,)).scatter(-1, columns, values)
    values = basis_function_derivatives(knots, degree, spans, u, order)  # (*, M, o + 1, p + 1)
    dense = u.new_zeros(u.shape + (order + 1, n_ctrl)).scatter(
        -1, columns.unsqueeze(-2).expand(values.shape), values
    )
    return dense.movedim(-2, -3)  # (*, o + 1, M, n_ctrl)


def basis_matrices(knots: list[Tensor], degree: int, n_ctrl: int, us: list[Tensor]) -> Tensor:
    """:func:`basis_matrix` of several directions with one degree and one control count:
    ``knots[a] (m,)``, ``us[a] (M,)`` -> ``(len(us), M, n_ctrl)``, by one pass of the
    recurrence on the stacked knot windows (for trainable knots, where nothing is cached
    and every operation has a backward too)."""
    spans = torch.stack([find_spans(kv, degree, n_ctrl, u) for kv, u in zip(knots, us)])  # (k, M)
    K = torch.stack([knot_window(kv, degree, s) for kv, s in zip(knots, spans)])  # (k, M, 2p)
    u = torch.stack(list(us))
    values, _ = _levels(K, degree, u)
    columns = spans.unsqueeze(-1) - degree + torch.arange(degree + 1, device=u.device)
    return u.new_zeros(u.shape + (n_ctrl,)).scatter(-1, columns, values[degree])
