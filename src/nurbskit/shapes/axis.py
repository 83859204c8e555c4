"""Axis of revolution and direction of extrusion from normals.

* **Extrusion** (a cylinder surface in the general sense): every normal is orthogonal to
  the extrusion direction ``d``, so ``d`` minimises ``sum_i (n_i . d)^2``: the
  eigenvector of the smallest eigenvalue of the normals' scatter ``sum_i n_i n_i^T``.
* **Revolution**: every normal line of a surface of revolution meets the axis (H.
  Pottmann and J. Wallner, *Computational Line Geometry*, Springer 2001, ch. 3; H.
  Pottmann, M. Peternell, B. Ravani, "An introduction to line geometry with applications",
  CAD 31, 1999). In Pluecker coordinates a normal line is ``(n_i, p_i x n_i)`` and the axis
  ``(c, cbar)`` with ``cbar = o x c``; the two lines meet when
  ``c . (p_i x n_i) + cbar . n_i = 0``. Minimising the sum of squares subject to
  ``|c| = 1`` is a 6 x 6 quadratic form whose minimiser, after eliminating ``cbar`` by its
  normal equations (a pseudo-inverse: for a cylinder the normals span only a plane and
  ``cbar``'s component along ``c``, the complex's pitch, is free and set to zero), is the
  smallest eigenvector of the 3 x 3 Schur complement. The residual of a line is its
  distance to the axis times the sine of the angle between them (times ``|n| |c| = 1``).
  Outliers (normals of noise, of caps that are not part of the revolution) are
  down-weighted by iteratively reweighted least squares with Tukey's biweight on a
  MAD scale (P. J. Huber, *Robust Statistics*, 1981).

Computations run in float64 on points centred and scaled to unit size, so ``p x n`` is
well conditioned.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from ..errors import InputError

Tensor = torch.Tensor

__all__ = ["Axis", "extrusion_direction", "revolution_axis", "axis_angle_degrees"]


class Axis(NamedTuple):
    """A line: ``point (3,)`` and unit ``direction (3,)`` (float64); ``spread``: the
    smallest eigenvalue over the next one (near 0: well determined; near 1: ambiguous,
    e.g. a sphere's axis or a plane's extrusion direction)."""

    point: Tensor
    direction: Tensor
    spread: float


def _f64(x, name: str) -> Tensor:
    t = torch.as_tensor(x).detach().to(torch.float64)
    if t.ndim != 2 or t.shape[1] != 3:
        raise InputError(f"{name} must have shape (N, 3), got {tuple(t.shape)}")
    return t


def axis_angle_degrees(a, b) -> float:
    """Angle in degrees between two lines' directions (sign-free: 0 to 90)."""
    a = torch.as_tensor(a, dtype=torch.float64)
    b = torch.as_tensor(b, dtype=torch.float64)
    c = float((a @ b).abs() / (a.norm() * b.norm()))
    return math.degrees(math.acos(min(1.0, c)))


def extrusion_direction(normals, *, iterations: int = 10) -> tuple[Tensor, float]:
    """The direction most orthogonal to all ``normals (N, 3)`` and its spread.

    Weighted scatter with ``iterations`` IRLS rounds (Tukey weights on ``n_i . d``: normals
    estimated across sharp edges are outliers). Returns ``(d (3,), spread)``:
    ``spread = lambda_min / lambda_mid`` of the (unweighted) scatter.
    """
    n = _f64(normals, "normals")
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    vals, vecs = torch.linalg.eigh(n.T @ n)
    spread = float(vals[0] / vals[1].clamp_min(1e-300))
    d = vecs[:, 0]
    for _ in range(max(0, iterations - 1)):
        w = _tukey(n @ d)
        if float(w.sum()) < 12:
            break
        d = torch.linalg.eigh((n * w[:, None]).T @ n)[1][:, 0]
    return d, spread


def _tukey(residual: Tensor, c: float = 4.685, floor: float = 1e-3) -> Tensor:
    """Tukey biweights; the MAD scale has a ``floor`` (residuals here are sines and unit-scaled
    distances), so clean data, whose residuals are all ~0, keeps its weights."""
    scale = (1.4826 * residual.abs().median()).clamp_min(floor)
    x = residual.abs() / (c * scale)
    return torch.where(x < 1, (1 - x * x) ** 2, torch.zeros_like(x))


def revolution_axis(points, normals, *, iterations: int = 10) -> Axis:
    """The axis that the normal lines of ``points (N, 3)`` with ``normals (N, 3)`` meet best.

    Least-squares line-geometry fit (module docstring) with ``iterations`` IRLS rounds.
    Returns an :class:`Axis` with ``point`` the axis point nearest to the points' centroid.

    Example:
        >>> import torch, math
        >>> t = torch.rand(300, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 2 * math.pi
        >>> p = torch.stack([(2 + torch.cos(t[:, 1])) * torch.cos(t[:, 0]),
        ...                  (2 + torch.cos(t[:, 1])) * torch.sin(t[:, 0]), torch.sin(t[:, 1])], -1)
        >>> n = p - 2 * torch.stack([torch.cos(t[:, 0]), torch.sin(t[:, 0]), 0 * t[:, 0]], -1)
        >>> ax = revolution_axis(p, n)  # a torus about z
        >>> round(abs(float(ax.direction[2])), 9), round(float(ax.point[:2].norm()), 9)
        (1.0, 0.0)
    """
    p = _f64(points, "points")
    n = _f64(normals, "normals")
    if p.shape != n.shape:
        raise InputError(f"points {tuple(p.shape)} and normals {tuple(n.shape)} differ in shape")
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    centre = p.mean(0)
    scale = float((p - centre).norm(dim=-1).max().clamp_min(1e-300))
    q = (p - centre) / scale
    y = torch.cat([torch.linalg.cross(q, n, dim=-1), n], dim=-1)  # (N, 6) Pluecker moments, directions
    w = torch.ones(p.shape[0], dtype=torch.float64)
    c = cbar = None
    spread = 1.0
    for it in range(max(1, iterations)):
        M = (y * w[:, None]).T @ y
        A, B, C = M[:3, :3], M[:3, 3:], M[3:, 3:]
        Cp = torch.linalg.pinv(C, rtol=1e-10, hermitian=True)
        S = A - B @ Cp @ B.T
        vals, vecs = torch.linalg.eigh((S + S.T) / 2)
        c = vecs[:, 0]
        cbar = -Cp @ B.T @ c
        spread = float(vals[0].clamp_min(0) / vals[1].clamp_min(1e-300))
        if it + 1 < iterations:
            w = _tukey(y @ torch.cat([c, cbar]))
            if float(w.sum()) < 12:  # too few inliers left: keep the last fit
                break
    # the axis of the linear complex (c, cbar): direction c, nearest point c x cbar / |c|^2
    o = torch.linalg.cross(c, cbar, dim=-1) / (c @ c)
    return Axis(centre + scale * o, c / c.norm(), spread)
