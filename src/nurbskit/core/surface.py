"""NURBS surfaces."""

from __future__ import annotations

import torch

from ..errors import NurbskitError
from .spline import TensorSpline

Tensor = torch.Tensor


def limit_normals(Su: Tensor, Sv: Tensor, Suv: Tensor, at_u_max: Tensor, at_v_max: Tensor) -> Tensor:
    """``S_u x S_v``, replaced by its limit from inside the domain where it vanishes.

    Shapes: ``(..., 3)`` derivatives and ``(...)`` booleans (does the point lie in the upper
    half of the domain in u / in v) -> ``(..., 3)``, not normalised. Where ``S_u`` vanishes
    along an edge ``v = v0`` (a pole), ``S_u(u, v) = (v - v0) S_uv + O((v - v0)^2)``, so the
    normal points along ``sign(v - v0) S_uv x S_v``: ``-`` near ``v = v_max`` (in the upper
    half of the domain, so that the band next to the pole, which counts as degenerate
    too, takes the pole's sign), ``+`` elsewhere;
    symmetrically ``sign(u - u0) S_u x S_uv`` where ``S_v`` vanishes. A point counts as
    degenerate when ``|S_u x S_v| <= sqrt(eps) (|S_u|^2 + |S_v|^2)``. Branch-free
    (``torch.where``): no host reads.
    """
    n = torch.linalg.cross(Su, Sv, dim=-1)
    with torch.no_grad():
        su2, sv2 = Su.square().sum(-1), Sv.square().sum(-1)
        degenerate = n.norm(dim=-1) <= torch.finfo(n.dtype).eps ** 0.5 * (su2 + sv2)
        su_small = su2 <= sv2
    one = torch.ones_like(su2)
    sign_v = torch.where(at_v_max, -one, one).unsqueeze(-1)
    sign_u = torch.where(at_u_max, -one, one).unsqueeze(-1)
    limit = torch.where(
        su_small.unsqueeze(-1),
        sign_v * torch.linalg.cross(Suv, Sv, dim=-1),
        sign_u * torch.linalg.cross(Su, Suv, dim=-1),
    )
    return torch.where(degenerate.unsqueeze(-1), limit, n)


def _unit(n: Tensor) -> Tensor:
    return n / n.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(n.dtype).tiny)


class NURBSSurface(TensorSpline):
    """A rational tensor-product B-spline surface, or a batch of them.

    Args:
        control_points: ``(*B, n_u, n_v, dim)``; u runs along the first grid axis after
            the batch axes ``*B`` (none for one surface).
        degrees: ``(p, q)``, one pair for the whole batch.
        knot_vectors: ``[(n_u + p + 1,), (n_v + q + 1,)]``, each shared or ``(*B, m)`` per
            element; default clamped uniform on [0, 1].
        weights: ``(*B, n_u, n_v)`` (or ``(n_u, n_v)``, shared) positive; default ones.
        validate: check everything once here, and parameters against the domain on
            evaluation (see :mod:`nurbskit.core.spline`); ``False`` inside loops.

    Convention: ``evaluate`` takes ``(*P, M, 2)`` parameters ``(u, v)`` (``(M, 2)`` shared
    by a batch, ``(*B, M, 2)`` per element) and returns ``(*broadcast(B, P), M, dim)``;
    ``derivatives(uv, order=k)`` returns ``(..., M, k + 1, k + 1, dim)`` where
    ``[..., a, b, :]`` is the derivative a times in u and b times in v (geomdl's
    layout; entries with ``a + b > k``, which geomdl leaves zero, are filled here too);
    ``sample((R, S))`` and ``evaluate_grid(u, v)`` return ``(*B, R, S, dim)``.

    Example:
        >>> import torch
        >>> s = NURBSSurface(torch.rand(4, 5, 3), degrees=(3, 2))
        >>> s.evaluate_grid(torch.linspace(0, 1, 8), torch.linspace(0, 1, 6)).shape
        torch.Size([8, 6, 3])
        >>> batch = NURBSSurface(torch.rand(64, 16, 16, 3), degrees=(3, 3))
        >>> batch.sample(32).shape, batch.evaluate(torch.rand(64, 100, 2)).shape
        (torch.Size([64, 32, 32, 3]), torch.Size([64, 100, 3]))
    """

    para_dim = 2
    kind = "surface"

    def __init__(self, control_points, degrees=(3, 3), knot_vectors=None, weights=None, *, validate: bool = True):
        super().__init__(control_points, degrees, knot_vectors, weights, validate=validate)

    def _upper_edges(self, u: Tensor, v: Tensor, point_dims: int) -> tuple[Tensor, Tensor]:
        """Whether ``u``, ``v`` lie nearer the upper domain end than the lower one: ``(*, ...)``
        booleans on the device, where the last ``point_dims`` axes of ``u`` and ``v`` index
        points and any before them the batch. (A point counts as degenerate in a band next
        to a pole, not only on it: the side of the domain it lies in picks the pole, and
        with it the sign of the limit normal.)"""
        (ku, kv), (nu, nv), (p, q) = self.knot_vectors, self.sizes, self.degrees

        def upper(k, lo, hi, x):
            mid = (k.detach()[..., lo] + k.detach()[..., hi]) / 2
            return x > mid.reshape(mid.shape + (1,) * point_dims)

        return upper(ku, p, nu, u), upper(kv, q, nv, v)

    def _require_3d(self, op: str) -> None:
        if self.dim != 3:
            raise NurbskitError(f"{op} needs a surface in 3-D, got control points of dimension {self.dim}")

    def normals(self, params, *, extrapolate: bool = False) -> Tensor:
        """Unit normals ``S_u x S_v / |S_u x S_v|`` at ``(..., M, 2)`` -> ``(..., M, 3)``.

        At a pole (where ``S_u`` or ``S_v`` vanishes along an edge) the limit normal from
        inside the domain (see :func:`limit_normals`), as :func:`~nurbskit.core.tessellate.tessellate`.
        """
        self._require_3d("normals")
        t = self._params(params)
        d = self.derivatives(t, order=1, extrapolate=extrapolate)
        at_u, at_v = self._upper_edges(t[..., 0], t[..., 1], 1)
        return _unit(limit_normals(d[..., 1, 0, :], d[..., 0, 1, :], d[..., 1, 1, :], at_u, at_v))

    def normals_grid(self, u, v, *, extrapolate: bool = False) -> Tensor:
        """Unit normals on a grid: ``(*B, R, S, 3)`` (limit normals at poles, as :meth:`normals`)."""
        self._require_3d("normals_grid")
        d = self.evaluate_grid(u, v, order=1, extrapolate=extrapolate)
        u, v = [torch.as_tensor(x, dtype=self.dtype, device=self.device) for x in (u, v)]
        at_u, at_v = self._upper_edges(u.reshape(u.shape[:-1] + (-1, 1)), v.reshape(v.shape[:-1] + (1, -1)), 2)
        return _unit(limit_normals(d[..., 1, 0, :], d[..., 0, 1, :], d[..., 1, 1, :], at_u, at_v))
