"""Nearest neighbours between point sets, found without gradient.

Chamfer and Hausdorff distances need, for every point of one cloud, its nearest
point in the other. Finding it is a discrete search (no gradient to carry), so it
runs on detached values: a KD-tree (``scipy.spatial.cKDTree``, all cores) on CPU,
and ``torch.cdist`` over bounded chunks of queries on CUDA. The losses then gather
the neighbours and recompute the distances with autograd (DESIGN.md item 4), which
gives the exact gradient wherever the nearest neighbour is unique.

On CPU no ``N x M`` matrix is ever built: memory is ``O((N + M) * D)``.
:func:`nearest_neighbors_naive` is the plain loop kept as the test oracle.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..errors import NurbskitError

Tensor = torch.Tensor

#: Default budget for one chunk of the distance matrix on CUDA (bytes).
CUDA_CHUNK_BYTES = 256 * 2**20


def _check_pair(query: Tensor, reference: Tensor) -> None:
    if not isinstance(query, Tensor) or not isinstance(reference, Tensor):
        raise NurbskitError(
            f"nearest_neighbors expects tensors, got {type(query).__name__} and {type(reference).__name__}"
        )
    if query.ndim < 2 or reference.ndim < 2:
        raise NurbskitError(
            f"point sets must have shape (..., N, D); got query {tuple(query.shape)} "
            f"and reference {tuple(reference.shape)}"
        )
    if query.shape[-1] != reference.shape[-1]:
        raise NurbskitError(
            f"query and reference must have the same point dimension D; got {query.shape[-1]} "
            f"(query {tuple(query.shape)}) and {reference.shape[-1]} (reference {tuple(reference.shape)})"
        )
    if query.shape[:-2] != reference.shape[:-2]:
        raise NurbskitError(
            f"query and reference must have the same leading batch shape; got "
            f"{tuple(query.shape[:-2])} and {tuple(reference.shape[:-2])}"
        )
    if reference.shape[-2] == 0:
        raise NurbskitError(f"reference point set is empty (shape {tuple(reference.shape)}); need at least one point")
    if query.device != reference.device:
        raise NurbskitError(f"query is on {query.device} but reference is on {reference.device}")
    for name, t in (("query", query), ("reference", reference)):
        if not t.is_floating_point():
            raise NurbskitError(f"{name} must be a floating-point tensor, got {t.dtype}")
        if t.numel() and not torch.isfinite(t.detach()).all():
            raise NurbskitError(f"{name} points contain NaN or infinite values")


def _index_kdtree(query: Tensor, reference: Tensor, workers: int) -> Tensor:
    from scipy.spatial import cKDTree

    ref = reference.detach().cpu().double().numpy()
    q = query.detach().cpu().double().numpy()
    _, index = cKDTree(ref).query(q, k=1, workers=workers)
    return torch.from_numpy(np.asarray(index, dtype=np.int64)).to(query.device)


def _index_cdist(query: Tensor, reference: Tensor, chunk_bytes: int) -> Tensor:
    n, m = query.shape[0], reference.shape[0]
    per_row = max(1, m * query.element_size())
    rows = max(1, int(chunk_bytes // per_row))
    q, r = query.detach(), reference.detach()
    out = torch.empty(n, dtype=torch.int64, device=query.device)
    for start in range(0, n, rows):
        # The direct (non-matmul) kernel: the ||a||^2 - 2ab + ||b||^2 shortcut loses the
        # small distances of dense clouds to cancellation and can pick a wrong neighbour.
        d = torch.cdist(q[start : start + rows], r, compute_mode="donot_use_mm_for_euclid_dist")
        out[start : start + rows] = d.argmin(dim=-1)
    return out


def nearest_neighbors(
    query: Tensor,
    reference: Tensor,
    *,
    workers: int = -1,
    chunk_bytes: int = CUDA_CHUNK_BYTES,
) -> tuple[Tensor, Tensor]:
    """Nearest reference point of every query point, without gradient.

    Shapes: ``query (*, N, D)``, ``reference (*, M, D)`` with the same leading batch
    shape ``*`` -> ``sq_dist (*, N)`` (query dtype), ``index (*, N)`` int64 into the
    reference's point axis. Batches are searched one after another.

    On CPU (and any non-CUDA device) a ``scipy.spatial.cKDTree`` is built on the
    reference and queried with ``workers`` threads (``-1``: all cores). On CUDA the
    distance matrix is computed with ``torch.cdist`` in chunks of query rows holding
    at most ``chunk_bytes`` bytes each, then reduced with ``argmin``.

    Convention: ``sq_dist`` is recomputed in torch as ``((query - reference[index])**2).sum(-1)``
    in the input dtype and carries no gradient; for gradients gather
    ``reference[index]`` yourself (as :func:`nurbskit.losses.chamfer_distance` does).
    Ties are broken by the backend (any of the equally near points). An empty query
    gives empty outputs; an empty reference, NaN or infinity raise ``NurbskitError``.

    Example:
        >>> import torch
        >>> q = torch.tensor([[0.0, 0.0], [2.0, 1.0]])
        >>> r = torch.tensor([[0.0, 1.0], [2.0, 0.0], [0.1, 0.0]])
        >>> sq, idx = nearest_neighbors(q, r)
        >>> idx.tolist(), [round(v, 4) for v in sq.tolist()]
        ([2, 1], [0.01, 1.0])
    """
    _check_pair(query, reference)
    batch = query.shape[:-2]
    n, d = query.shape[-2], query.shape[-1]
    m = reference.shape[-2]
    b = math.prod(batch)
    qf = query.detach().reshape(b, n, d)
    rf = reference.detach().reshape(b, m, d)
    indices = []
    for qb, rb in zip(qf, rf):
        if n == 0:
            indices.append(torch.empty(0, dtype=torch.int64, device=query.device))
        elif query.device.type == "cuda":
            indices.append(_index_cdist(qb, rb, chunk_bytes))
        else:
            indices.append(_index_kdtree(qb, rb, workers))
    index = torch.stack(indices) if indices else torch.empty(qf.shape[:2], dtype=torch.int64, device=query.device)
    with torch.no_grad():
        nearest = torch.gather(rf, 1, index.unsqueeze(-1).expand(-1, -1, d))
        sq_dist = ((qf - nearest) ** 2).sum(-1)
    return sq_dist.reshape(*batch, n), index.reshape(*batch, n)


def nearest_neighbors_naive(query: Tensor, reference: Tensor) -> tuple[Tensor, Tensor]:
    """The brute-force oracle for :func:`nearest_neighbors`: a Python loop over queries.

    Shapes: ``query (N, D)``, ``reference (M, D)`` -> ``sq_dist (N,)``, ``index (N,)``.
    ``O(N * M)`` time; for tests on small inputs only.

    Convention: on ties the lowest reference index wins.

    Example:
        >>> import torch
        >>> nearest_neighbors_naive(torch.zeros(1, 3), torch.eye(3))[1].tolist()
        [0]
    """
    _check_pair(query, reference)
    if query.ndim != 2:
        raise NurbskitError(f"nearest_neighbors_naive takes (N, D) point sets, got {tuple(query.shape)}")
    q, r = query.detach(), reference.detach()
    sq = torch.empty(q.shape[0], dtype=q.dtype, device=q.device)
    idx = torch.empty(q.shape[0], dtype=torch.int64, device=q.device)
    for i in range(q.shape[0]):
        best, best_j = None, -1
        for j in range(r.shape[0]):
            dist = float(((q[i] - r[j]) ** 2).sum())
            if best is None or dist < best:
                best, best_j = dist, j
        sq[i] = best
        idx[i] = best_j
    return sq, idx


__all__ = ["nearest_neighbors", "nearest_neighbors_naive"]
