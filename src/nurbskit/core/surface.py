"""NURBS surfaces."""

from __future__ import annotations

import torch

from .spline import TensorSpline

Tensor = torch.Tensor


class NURBSSurface(TensorSpline):
    """A rational tensor-product B-spline surface.

    Args:
        control_points: ``(n_u, n_v, dim)``; u runs along the first grid axis.
        degrees: ``(p, q)``.
        knot_vectors: ``[(n_u + p + 1,), (n_v + q + 1,)]``; default clamped uniform on [0, 1].
        weights: ``(n_u, n_v)`` positive; default ones.

    Convention: ``evaluate`` takes ``(..., M, 2)`` parameters ``(u, v)`` and returns
    ``(..., M, dim)``; ``derivatives(uv, order=k)`` returns ``(..., M, k + 1, k + 1, dim)``
    where ``[..., a, b, :]`` is the derivative a times in u and b times in v (geomdl's
    layout; entries with ``a + b > k``, which geomdl leaves zero, are filled here too).

    Example:
        >>> import torch
        >>> s = NURBSSurface(torch.rand(4, 5, 3), degrees=(3, 2))
        >>> s.evaluate_grid(torch.linspace(0, 1, 8), torch.linspace(0, 1, 6)).shape
        torch.Size([8, 6, 3])
    """

    para_dim = 2
    kind = "surface"

    def __init__(self, control_points, degrees=(3, 3), knot_vectors=None, weights=None, *, validate: bool = True):
        super().__init__(control_points, degrees, knot_vectors, weights, validate=validate)

    def normals(self, params) -> Tensor:
        """Unit normals ``S_u x S_v / |S_u x S_v|`` at ``(..., M, 2)`` -> ``(..., M, 3)``."""
        d = self.derivatives(params, order=1)
        n = torch.linalg.cross(d[..., 1, 0, :], d[..., 0, 1, :], dim=-1)
        return n / n.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(n.dtype).tiny)

    def normals_grid(self, u, v) -> Tensor:
        """Unit normals on a grid: ``(R, S, 3)``."""
        d = self.evaluate_grid(u, v, order=1)
        n = torch.linalg.cross(d[..., 1, 0, :], d[..., 0, 1, :], dim=-1)
        return n / n.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(n.dtype).tiny)
