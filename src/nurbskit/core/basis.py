"""B-spline basis functions and their derivatives, vectorised over parameters.

Both routines follow The NURBS Book (Piegl and Tiller): A2.2 for the ``p + 1``
non-zero basis values on a span and A2.3 for their derivatives. They are written
with tensor operations on the knots, so autograd differentiates the piecewise
polynomial basis exactly with respect to the knots and the parameters; only the
span search (piecewise constant) is done on detached values.
"""

from __future__ import annotations

import torch

from .knots import find_spans

Tensor = torch.Tensor


def _take(values: Tensor, index: Tensor) -> Tensor:
    """``values[index]`` for a 1-D ``values`` and any-shaped ``index``.

    ``index_select`` on a flat index: on CPU, advanced indexing (and ``take``) of a
    small tensor costs about 1 ms per 1,000 indices, ``index_select`` a thousandth of that.
    """
    return values.index_select(0, index.reshape(-1)).reshape(index.shape)


def _knot_differences(knots: Tensor, degree: int, spans: Tensor, u: Tensor) -> tuple[list, list]:
    """``left[j] = u - knots[span + 1 - j]`` and ``right[j] = knots[span + j] - u``, j = 1..p."""
    left = [None] + [u - _take(knots, spans + 1 - j) for j in range(1, degree + 1)]
    right = [None] + [_take(knots, spans + j) - u for j in range(1, degree + 1)]
    return left, right


def basis_functions(knots: Tensor, degree: int, spans: Tensor, u: Tensor) -> Tensor:
    """Non-zero basis values ``N[span - p + j, p](u)``, j = 0..p (The NURBS Book A2.2).

    Shapes: ``spans (...)``, ``u (...)`` -> ``(..., p + 1)``.
    """
    left, right = _knot_differences(knots, degree, spans, u)
    values = [torch.ones_like(u)]
    for j in range(1, degree + 1):
        saved = torch.zeros_like(u)
        nxt = []
        for r in range(j):
            temp = values[r] / (right[r + 1] + left[j - r])
            nxt.append(saved + right[r + 1] * temp)
            saved = left[j - r] * temp
        nxt.append(saved)
        values = nxt
    # Stacking on a new leading axis copies contiguous blocks; moving it last is a view.
    return torch.stack(values).movedim(0, -1)


def basis_function_derivatives(knots: Tensor, degree: int, spans: Tensor, u: Tensor, order: int) -> Tensor:
    """Basis values and derivatives up to ``order`` on each span (The NURBS Book A2.3).

    Shapes: ``spans (...)``, ``u (...)`` -> ``(..., order + 1, p + 1)``, where
    ``[..., k, j]`` is the k-th derivative of ``N[span - p + j, p]`` at ``u``.
    Derivatives above the degree are zero.
    """
    p = degree
    left, right = _knot_differences(knots, p, spans, u)
    # ndu[j][r]: basis values (upper triangle, r >= j... stored as ndu[r][j]) and knot differences (lower).
    ndu = [[None] * (p + 1) for _ in range(p + 1)]
    ndu[0][0] = torch.ones_like(u)
    for j in range(1, p + 1):
        saved = torch.zeros_like(u)
        for r in range(j):
            ndu[j][r] = right[r + 1] + left[j - r]
            temp = ndu[r][j - 1] / ndu[j][r]
            ndu[r][j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j][j] = saved

    zero = torch.zeros_like(u)
    top = min(order, p)
    ders = [[zero] * (p + 1) for _ in range(order + 1)]
    for j in range(p + 1):
        ders[0][j] = ndu[j][p]
    for r in range(p + 1):
        a_prev = [torch.ones_like(u)] + [zero] * p
        for k in range(1, top + 1):
            a_next = [zero] * (p + 1)
            d = zero
            rk, pk = r - k, p - k
            if r >= k:
                a_next[0] = a_prev[0] / ndu[pk + 1][rk]
                d = a_next[0] * ndu[rk][pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a_next[j] = (a_prev[j] - a_prev[j - 1]) / ndu[pk + 1][rk + j]
                d = d + a_next[j] * ndu[rk + j][pk]
            if r <= pk:
                a_next[k] = -a_prev[k - 1] / ndu[pk + 1][r]
                d = d + a_next[k] * ndu[r][pk]
            ders[k][r] = d
            a_prev = a_next
    factor = float(p)
    rows = [torch.stack(ders[0])]
    for k in range(1, order + 1):
        rows.append(torch.stack(ders[k]) * factor)
        factor *= p - k
    return torch.stack(rows).movedim((0, 1), (-2, -1))  # (order + 1, p + 1, ...) -> (..., order + 1, p + 1)


def basis_matrix(knots: Tensor, degree: int, n_ctrl: int, u: Tensor, order: int = 0) -> Tensor:
    """Dense basis matrix: ``B[..., i] = N[i, p](u)`` (or its derivatives).

    Shapes: ``u (M,)`` -> ``(M, n_ctrl)`` for ``order == 0``, else
    ``(order + 1, M, n_ctrl)`` with the k-th derivative in slice ``k``.
    A grid of a surface is then ``B_u @ Pw @ B_v^T`` (see ``tensor.evaluate_grid``).
    """
    spans = find_spans(knots, degree, n_ctrl, u)
    columns = spans.unsqueeze(-1) - degree + torch.arange(degree + 1, device=u.device)
    if order == 0:
        values = basis_functions(knots, degree, spans, u)
        return u.new_zeros(u.shape + (n_ctrl,)).scatter(-1, columns, values)
    values = basis_function_derivatives(knots, degree, spans, u, order).movedim(-2, 0)
    columns = columns.unsqueeze(0).expand(order + 1, *columns.shape)
    return u.new_zeros((order + 1,) + u.shape + (n_ctrl,)).scatter(-1, columns, values)
