"""Normals of a point cloud by local PCA (Hoppe et al., "Surface reconstruction from
unorganized points", SIGGRAPH 1992): the normal at a point is the eigenvector of the
smallest eigenvalue of its k nearest neighbours' covariance.

Neighbours come from the one neighbour kernel, :func:`nurbskit.core.neighbors.k_nearest`.
Orientation is not made consistent: the shape estimators here use normal *lines*, whose
sign does not matter.
"""

from __future__ import annotations

import torch

from ..core.neighbors import k_nearest
from ..errors import InputError

Tensor = torch.Tensor

__all__ = ["estimate_normals"]


def estimate_normals(points, k: int = 16) -> Tensor:
    """Unit normals ``(N, 3)`` of ``points (N, 3)`` from the PCA of ``k`` nearest neighbours.

    Returned in the points' dtype (float64 for arrays). Signs are arbitrary.

    Example:
        >>> import torch
        >>> g = torch.rand(200, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
        >>> n = estimate_normals(torch.cat([g, torch.zeros(200, 1, dtype=torch.float64)], 1))
        >>> bool((n[:, 2].abs() > 1 - 1e-9).all())
        True
    """
    p = torch.as_tensor(points)
    if not p.is_floating_point():
        p = p.to(torch.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {tuple(p.shape)}")
    if p.shape[0] < 4:
        raise InputError(f"need at least 4 points to estimate normals, got {p.shape[0]}")
    k = max(3, min(int(k), p.shape[0]))
    idx = k_nearest(p, p, k)  # (N, k)
    nb = p[idx]  # (N, k, 3)
    centred = nb - nb.mean(1, keepdim=True)
    cov = centred.transpose(1, 2) @ centred  # (N, 3, 3)
    _, vecs = torch.linalg.eigh(cov)
    return vecs[..., :, 0]
