"""NURBS curves."""

from __future__ import annotations

import torch

from .spline import TensorSpline

Tensor = torch.Tensor


class NURBSCurve(TensorSpline):
    """A rational B-spline curve in any dimension, or a batch of them.

    Args:
        control_points: ``(*B, n, dim)``; ``*B`` batch axes (none for one curve).
        degree: polynomial degree ``p >= 1`` (one for the whole batch).
        knot_vector: ``(n + p + 1,)`` non-decreasing, shared, or ``(*B, n + p + 1)`` one per
            element; default clamped uniform on [0, 1].
        weights: ``(*B, n)`` (or ``(n,)``, shared) positive; default ones.
        validate: check everything once here, and parameters against the domain on
            evaluation (see :mod:`nurbskit.core.spline`); ``False`` inside loops.

    Convention: ``evaluate`` takes parameters ``(*P, M)`` in the knot domain (``(M,)``
    shared by a batch, ``(*B, M)`` one set per element) and returns
    ``(*broadcast(B, P), M, dim)``; ``derivatives(u, order=k)`` returns
    ``(..., M, k + 1, dim)`` with the point itself in slot 0; ``sample(R)`` returns
    ``(*B, R, dim)``. ``u = u_max`` is the end point.

    Example:
        >>> import torch
        >>> c = NURBSCurve(torch.tensor([[1., 0.], [1., 1.], [0., 1.]]), degree=2,
        ...                weights=torch.tensor([1., 2 ** -0.5, 1.]))
        >>> radius = c.evaluate(torch.linspace(0, 1, 5)).norm(dim=-1)
        >>> bool((radius - 1).abs().max() < 1e-6)  # a quarter circle
        True
        >>> batch = NURBSCurve(torch.rand(8, 4, 3), degree=3)  # eight cubic curves
        >>> batch.evaluate(torch.rand(10)).shape, batch.sample(16).shape
        (torch.Size([8, 10, 3]), torch.Size([8, 16, 3]))
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

    def tangents(self, params, *, extrapolate: bool = False) -> Tensor:
        """Unit tangents ``(..., M, dim)``."""
        d = self.derivatives(params, order=1, extrapolate=extrapolate)[..., 1, :]
        return d / d.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(d.dtype).tiny)
