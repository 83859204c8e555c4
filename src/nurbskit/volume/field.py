"""A scalar NURBS volume and its Laplacian on a grid, as mode products with basis matrices.

The paper evaluates ``f(u, v, w) = sum V B B B W / sum B B B W`` point by point. On a
tensor grid the two sums are three mode products of the homogeneous control array
``(V W, W)`` with the core's dense basis matrices ``B_u (R, n_u)``, ``B_v (S, n_v)``,
``B_w (T, n_w)`` (``nurbskit.core.basis.basis_matrix``): a handful of GEMMs instead
of ``R S T n_u n_v n_w`` multiply-adds.

The Laplacian needs ``f_uu + f_vv + f_ww`` of the *rational* field. With ``A = sum V B W``
and ``W = sum B W`` (both polynomial, so their derivatives are mode products with the
derivative basis matrices), the quotient rule gives, per direction ``a``::

    f    = A / W
    f_a  = (A_a - W_a f) / W
    f_aa = (A_aa - 2 W_a f_a - W_aa f) / W

Only the seven products with at most one differentiated direction are formed (not all
27 of ``evaluate_grid(order=2)``), sharing the first stages.
"""

from __future__ import annotations

from typing import Sequence

import torch

from ..core.basis import basis_matrix
from ..errors import OptionError

Tensor = torch.Tensor


def _product(X: Tensor, B: Tensor, axis: int) -> Tensor:
    """Mode product of ``X (C, n_0, n_1, n_2)`` with ``B (R, n_axis)`` along spatial ``axis``.

    Written as one (batched) GEMM on a reshaped view for each axis.
    """
    C, n0, n1, n2 = X.shape
    if axis == 0:
        return torch.matmul(B, X.reshape(C, n0, n1 * n2)).reshape(C, B.shape[0], n1, n2)
    if axis == 1:
        return torch.matmul(B, X.reshape(C * n0, n1, n2)).reshape(C, n0, B.shape[0], n2)
    return (X.reshape(-1, n2) @ B.transpose(0, 1)).reshape(C, n0, n1, B.shape[0])


class GridField:
    """Basis matrices of a scalar NURBS volume on a fixed grid, built once per fit.

    Args:
        knot_vectors: three 1-D knot vectors.
        degrees: ``(p, q, r)``.
        sizes: control values per direction ``(n_u, n_v, n_w)``.
        axes: grid parameters per direction, ``(R,)``, ``(S,)``, ``(T,)``.
        second_derivatives: also build the derivative matrices the Laplacian needs.

    ``evaluate(values, weights)`` -> ``(R, S, T)``; ``evaluate_with_laplacian`` also
    returns ``(R, S, T)`` Laplacians. Tensors follow the dtype and device of ``axes``.

    Example:
        >>> import torch
        >>> from nurbskit.core.knots import clamped_uniform
        >>> kv = [clamped_uniform(6, 2)] * 3
        >>> g = GridField(kv, (2, 2, 2), (6, 6, 6), [torch.linspace(0, 1, 8)] * 3)
        >>> g.evaluate(torch.rand(6, 6, 6), torch.ones(6, 6, 6)).shape
        torch.Size([8, 8, 8])
    """

    def __init__(
        self,
        knot_vectors: Sequence[Tensor],
        degrees: Sequence[int],
        sizes: Sequence[int],
        axes: Sequence[Tensor],
        *,
        second_derivatives: bool = True,
    ):
        if len(knot_vectors) != 3 or len(degrees) != 3 or len(sizes) != 3 or len(axes) != 3:
            raise OptionError("GridField needs three knot vectors, degrees, sizes and axes")
        self.sizes = tuple(int(n) for n in sizes)
        self.degrees = tuple(int(p) for p in degrees)
        self.shape = tuple(len(a) for a in axes)
        order = 2 if second_derivatives else 0
        mats = []
        for kv, p, n, ax in zip(knot_vectors, self.degrees, self.sizes, axes):
            m = basis_matrix(kv.to(ax), p, n, ax, order)
            mats.append(m if order else m.unsqueeze(0))  # (order + 1, R, n)
        self.matrices = mats
        self.second_derivatives = second_derivatives

    def _homogeneous(self, values: Tensor, weights: Tensor) -> Tensor:
        if tuple(values.shape) != self.sizes or tuple(weights.shape) != self.sizes:
            raise OptionError(
                f"control values and weights must have shape {self.sizes}, "
                f"got {tuple(values.shape)} and {tuple(weights.shape)}"
            )
        return torch.stack([values * weights, weights])  # (2, n_u, n_v, n_w)

    def evaluate(self, values: Tensor, weights: Tensor) -> Tensor:
        """The field ``(R, S, T)`` from control values and weights ``(n_u, n_v, n_w)``."""
        X = self._homogeneous(values, weights)
        for axis in range(3):
            X = _product(X, self.matrices[axis][0], axis)
        A, W = X.unbind(0)  # unbind, not indexing: its backward is one stack, not two zero-filled copies
        return A / W

    def evaluate_with_laplacian(
        self, values: Tensor, weights: Tensor, scale: Sequence[float] = (1.0, 1.0, 1.0)
    ) -> tuple[Tensor, Tensor]:
        """The field and ``sum_a scale_a^2 d^2 f / d a^2`` on the grid, both ``(R, S, T)``.

        ``scale`` measures each direction in other units (``scale = 1``: parameter units).
        """
        if not self.second_derivatives:
            raise OptionError("this GridField was built without second derivatives")
        Bu, Bv, Bw = self.matrices
        X = self._homogeneous(values, weights)
        # One product per derivative order (no slicing of stacked results: the backward
        # of a slice fills a zero tensor the size of the whole stack).
        U = [_product(X, Bu[o], 0) for o in range(3)]  # (2, R, n_v, n_w) each
        V00 = _product(U[0], Bv[0], 1)
        V = {  # (u-order, v-order) -> (2, R, S, n_w)
            (0, 0): V00,
            (0, 1): _product(U[0], Bv[1], 1),
            (0, 2): _product(U[0], Bv[2], 1),
            (1, 0): _product(U[1], Bv[0], 1),
            (2, 0): _product(U[2], Bv[0], 1),
        }
        H = {(a, b, 0): _product(x, Bw[0], 2) for (a, b), x in V.items()}
        H[(0, 0, 1)] = _product(V00, Bw[1], 2)
        H[(0, 0, 2)] = _product(V00, Bw[2], 2)
        A, Wt = H[(0, 0, 0)].unbind(0)
        f = A / Wt
        inv = 1.0 / Wt

        def second(first_order, second_order):
            a1, w1 = H[first_order].unbind(0)
            a2, w2 = H[second_order].unbind(0)
            fa = (a1 - w1 * f) * inv
            return (a2 - 2 * w1 * fa - w2 * f) * inv

        f_uu = second((1, 0, 0), (2, 0, 0))
        f_vv = second((0, 1, 0), (0, 2, 0))
        f_ww = second((0, 0, 1), (0, 0, 2))
        su, sv, sw = (float(s) ** 2 for s in scale)
        return f, su * f_uu + sv * f_vv + sw * f_ww
