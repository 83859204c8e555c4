"""Trivariate NURBS volumes (geometry, or scalar fields with dim 1)."""

from __future__ import annotations

from .spline import TensorSpline


class NURBSVolume(TensorSpline):
    """A rational trivariate B-spline, or a batch of them.

    Args:
        control_points: ``(*B, n_u, n_v, n_w, dim)``; ``dim = 1`` for a scalar field.
        degrees: ``(p, q, r)``.
        knot_vectors: three knot vectors, each ``(m,)`` shared or ``(*B, m)`` per element;
            default clamped uniform on [0, 1].
        weights: ``(*B, n_u, n_v, n_w)`` positive; default ones.

    Convention: ``evaluate`` takes ``(*P, M, 3)`` and returns ``(*broadcast(B, P), M, dim)``;
    ``evaluate_grid(u, v, w)`` returns ``(*B, R, S, T, dim)`` by three mode products.

    Example:
        >>> import torch
        >>> field = NURBSVolume(torch.rand(6, 6, 6, 1), degrees=(2, 2, 2))
        >>> field.sample(10).shape
        torch.Size([10, 10, 10, 1])
    """

    para_dim = 3
    kind = "volume"

    def __init__(self, control_points, degrees=(3, 3, 3), knot_vectors=None, weights=None, *, validate: bool = True):
        super().__init__(control_points, degrees, knot_vectors, weights, validate=validate)
