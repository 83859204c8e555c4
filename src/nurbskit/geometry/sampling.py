"""Points on meshes and on NURBS: Poisson-disk (blue noise) and uniform area-weighted
sampling of triangle meshes, and parametric grid sampling of NURBS objects.

Poisson-disk sampling here is dart throwing over a dense set of candidates, the method
of MeshLab's "Poisson-disk sampling" filter (Corsini, Cignoni, Scopigno, "Efficient and
flexible sampling with blue noise properties of triangular meshes", TVCG 2012): draw
``oversample * n`` uniform candidates, visit them in random order and keep one when no
kept point lies within the radius ``r``. The visit is done all at once as a greedy
maximal independent set of the "closer than r" graph (KD-tree pairs, then rounds in
which every candidate whose rank is smallest among its undecided neighbours is kept):
the same set the one-by-one loop keeps, without a Python loop per candidate. The radius
is searched so that at least ``n`` points are kept, and the surplus (a few percent) is
removed closest-pair first, so exactly ``n`` points come back with every pair at least
``r`` apart (Euclidean distance in space, as MeshLab measures it).

Convention: inputs may be numpy arrays or torch tensors; the result has the type, dtype
and device of ``vertices``. With torch vertices the samples are barycentric combinations
of the vertex tensor, so gradients reach the vertices.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import InputError, OptionError

METHODS = ("poisson", "uniform")


def _to_numpy(x, what: str) -> np.ndarray:
    try:
        import torch

        if isinstance(x, torch.Tensor):
            return x.detach().cpu().numpy()
    except ImportError:  # pragma: no cover
        pass
    return np.asarray(x)


def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v = _to_numpy(vertices, "vertices").astype(np.float64)
    f = _to_numpy(faces, "faces")
    if v.ndim != 2 or v.shape[1] != 3:
        raise OptionError(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise OptionError(f"faces must have shape (F, 3), got {f.shape}")
    if f.size == 0:
        raise InputError("the mesh has no faces to sample")
    if f.dtype.kind not in "iu":
        raise OptionError(f"faces must be integer indices, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise OptionError(f"faces index vertices {f.min()}..{f.max()}, but there are {v.shape[0]} vertices")
    if not np.isfinite(v).all():
        raise InputError("vertices contain NaN or infinite values")
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not area.sum() > 0:
        raise InputError("the mesh has zero surface area; nothing to sample")
    return v, f, area


def _uniform(f: np.ndarray, area: np.ndarray, n: int, rng: np.random.Generator):
    """Face indices ``(n,)`` (probability proportional to area) and barycentrics ``(n, 3)``."""
    cdf = np.cumsum(area)
    face = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right")
    face = np.minimum(face, f.shape[0] - 1)
    r1 = np.sqrt(rng.random(n))
    r2 = rng.random(n)
    # Uniform on a triangle: (1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2) (Osada et al. 2002)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    return face, bary


def greedy_independent_set(num: int, pairs: np.ndarray, rank: np.ndarray) -> np.ndarray:
    """Mask of the vertices the sequential greedy pass keeps when it visits them by increasing
    ``rank`` and keeps each vertex none of whose kept neighbours came before.

    Args:
        num: number of vertices.
        pairs: ``(E, 2)`` undirected edges.
        rank: ``(num,)`` distinct visiting order.

    Example:
        >>> greedy_independent_set(3, np.array([[0, 1], [1, 2]]), np.array([1, 0, 2])).tolist()
        [False, True, False]
    """
    state = np.zeros(num, np.int8)  # 0 undecided, 1 kept, -1 removed
    a, b = pairs[:, 0], pairs[:, 1]
    big = np.iinfo(np.int64).max
    rank = rank.astype(np.int64)
    while True:
        undecided = state == 0
        if not undecided.any():
            break
        live = undecided[a] & undecided[b]
        a, b = a[live], b[live]
        # smallest rank among each vertex's undecided neighbours
        low = np.full(num, big, np.int64)
        np.minimum.at(low, a, rank[b])
        np.minimum.at(low, b, rank[a])
        keep = undecided & (rank < low)
        state[keep] = 1
        gone = np.zeros(num, bool)
        gone[a[keep[b]]] = True
        gone[b[keep[a]]] = True
        state[gone & (state == 0)] = -1
    return state == 1


def _poisson(v, f, area, n: int, rng, oversample: int):
    from ..core.neighbors import kdtree

    m = max(int(oversample) * n, n + 16)
    face, bary = _uniform(f, area, m, rng)
    cand = np.einsum("mk,mkd->md", bary, v[f[face]])
    total = float(area.sum())
    # Dart throwing from 5n candidates keeps about n points when n r^2 / A ~ 0.5 (measured
    # on the bunny, fandisk and the thesis meshes): a first guess, then a search on r with
    # the candidate pairs computed once.
    r0 = np.sqrt(0.5 * total / n)
    # an unbalanced tree without node compaction builds about twice as fast and queries as fast
    tree = kdtree(cand, balanced_tree=False, compact_nodes=False)
    r_max = 1.2 * r0
    pairs = tree.query_pairs(r_max, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    dist2 = np.zeros(len(pairs))
    for axis in range(3):  # gathers from contiguous 1-D columns are faster than row gathers
        column = np.ascontiguousarray(cand[:, axis])
        dist2 += (column[a] - column[b]) ** 2
    rank = rng.permutation(m)

    def run(r):
        return greedy_independent_set(m, pairs[dist2 < r * r], rank)

    # Largest r whose kept count is >= n, to within 3 % of n. The count falls as a power
    # of r; its exponent is measured from the last two runs (secant in log-log), and every
    # step stays inside the bracket [lo, hi] with count(lo) >= n > count(hi).
    lo, hi, r = 0.0, r_max, r0
    best, history, target = None, [], 1.015 * n
    for _ in range(30):
        keep = run(r)
        count = int(keep.sum())
        if count >= n:
            lo, best = r, keep
            if count <= 1.03 * n:
                break
        else:
            hi = r
        history.append((np.log(r), np.log(max(count, 1))))
        alpha = 2.0
        if len(history) >= 2 and history[-1][0] != history[-2][0]:
            alpha = -(history[-1][1] - history[-2][1]) / (history[-1][0] - history[-2][0])
            alpha = float(np.clip(alpha, 0.5, 4.0))
        guess = r * (count / target) ** (1.0 / alpha)
        r = guess if lo < guess < hi else 0.5 * (lo + hi)
        if hi - lo < 1e-9 * r0:
            break
    if best is None:  # r -> 0 keeps every candidate
        best = np.ones(m, bool)
    keep, count = best, int(best.sum())
    idx = np.flatnonzero(keep)
    if count > n:
        # drop the surplus closest-first: removing points never brings the others closer
        d, _ = kdtree(cand[idx]).query(cand[idx], k=2)
        idx = idx[np.sort(np.argsort(-d[:, 1], kind="stable")[:n])]
    return face[idx], bary[idx], lo


def sample_mesh(vertices, faces, n: int, method: str = "poisson", seed: int | None = None, *,
                oversample: int = 5, return_faces: bool = False):
    """Sample ``n`` points on a triangle mesh.

    Args:
        vertices: ``(V, 3)`` numpy array or torch tensor.
        faces: ``(F, 3)`` integer indices.
        n: number of points (exactly ``n`` come back with either method).
        method: 'poisson' (blue noise: every pair at least the disc radius apart; the
            smallest nearest-neighbour distance is typically 0.7 of the mean) or
            'uniform' (independent, probability proportional to area).
        seed: for ``numpy.random.default_rng``; None draws fresh entropy.
        oversample: candidates per requested point for 'poisson' (more: closer to maximal).
        return_faces: also return the face index ``(n,)`` of every sample.

    Returns:
        ``points (n, 3)`` of the type, dtype and device of ``vertices``
        (and ``faces (n,)`` int64 with ``return_faces``).

    Example:
        >>> import numpy as np
        >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
        >>> sample_mesh(square, np.array([[0, 1, 2], [0, 2, 3]]), 100, seed=0).shape
        (100, 3)
    """
    if method not in METHODS:
        raise OptionError(f"method must be one of {METHODS}, got {method!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise OptionError(f"n must be a positive integer, got {n!r}")
    if oversample < 2:
        raise OptionError(f"oversample must be at least 2, got {oversample}")
    n = int(n)
    v, f, area = _check_mesh(vertices, faces)
    rng = np.random.default_rng(seed)
    if method == "uniform" or n == 1:
        face, bary = _uniform(f, area, n, rng)
    else:
        face, bary, _ = _poisson(v, f, area, n, rng, oversample)
    points = _combine(vertices, f, face, bary)
    return (points, face) if return_faces else points


def _combine(vertices, f: np.ndarray, face: np.ndarray, bary: np.ndarray):
    try:
        import torch

        if isinstance(vertices, torch.Tensor):
            corners = vertices[torch.as_tensor(f[face], device=vertices.device)]  # (n, 3, 3)
            w = torch.as_tensor(bary, dtype=vertices.dtype, device=vertices.device)
            return (w.unsqueeze(-1) * corners).sum(dim=1)
    except ImportError:  # pragma: no cover
        pass
    v = np.asarray(vertices)
    dtype = v.dtype if v.dtype.kind == "f" else np.float64
    return np.einsum("nk,nkd->nd", bary, v.astype(np.float64)[f[face]]).astype(dtype)


def sample_parametric(obj, resolution: int | Sequence[int]):
    """Points of a NURBS curve, surface or volume on a uniform parametric grid, flattened.

    The thesis's "parametric sampling": ``obj.sample(resolution)`` is the grid
    ``(R, S, dim)``; this returns it as ``(R * S, dim)`` (u slowest), differentiable.

    Example:
        >>> import torch, nurbskit
        >>> s = nurbskit.NURBSSurface(torch.rand(4, 4, 3), degrees=(3, 3))
        >>> sample_parametric(s, (8, 6)).shape
        torch.Size([48, 3])
    """
    grid = obj.sample(resolution)
    return grid.reshape(-1, grid.shape[-1])


def nearest_neighbor_distances(points) -> np.ndarray:
    """Distance from every point to its nearest other point: ``(N, 3)`` -> ``(N,)`` (KD-tree)."""
    from ..core.neighbors import kdtree

    p = _to_numpy(points, "points").astype(np.float64)
    d, _ = kdtree(p).query(p, k=2)
    return d[:, 1]
