"""NURBS curves."""

from __future__ import annotations

import torch

from .spline import TensorSpline

Tensor = torch.Tensor


class NURBSCurve(TensorSpline):
    """A rational B-spline curve in any dimension.

    Args:
        control_points: ``(n, dim)``.
        degree: polynomial degree ``p >= 1``.
        knot_vector: ``(n + p + 1,)`` non-decreasing; default clamped uniform on [0, 1].
        weights: ``(n,)`` positive; default ones.

    Convention: ``evaluate`` takes parameters ``(..., M)`` in the knot domain and returns
    ``(..., M, dim)``; ``derivatives(u, order=k)`` returns ``(..., M, k + 1, dim)`` with the
    point itself in slot 0. ``u = u_max`` is the end point.

    Example:
        >>> import torch
        >>> c = NURBSCurve(torch.tensor([[1., 0.], [1., 1.], [0., 1.]]), degree=2,
        ...                weights=torch.tensor([1., 2 ** -0.5, 1.]))
        >>> c.evaluate(torch.tensor([0.5])).norm(dim=-1)  # a quarter circle
        tensor([1.])
    """

    para_dim = 1
    kind = "curve"

    def __init__(self, control_points, degree: int = 3, knot_vector=None, weights=None, *, validate: bool = True):
        super().__init__(
            control_points, (degree,), None if knot_vector is None else [knot_vector], weights, validate=validate
        )

    @property
    def degree(self) -> int:
        return self.degrees[0]

    @property
    def knot_vector(self) -> Tensor:
        return self.knot_vectors[0]

    def tangents(self, params) -> Tensor:
        """Unit tangents ``(..., M, dim)``."""
        d = self.derivatives(params, order=1)[..., 1, :]
        return d / d.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(d.dtype).tiny)
