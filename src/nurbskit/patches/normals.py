"""Point normals: PCA on k nearest neighbours, oriented consistently over the kNN graph.

Hoppe, DeRose, Duchamp, McDonald and Stuetzle, "Surface reconstruction from unorganized
points" (SIGGRAPH 1992): the normal of a point is the direction of least variance of its
neighbourhood; orientations are made consistent by propagating along a minimum spanning
tree of the neighbour graph weighted by ``1 - |n_i . n_j|`` (nearly parallel normals
first, so a flip never crosses a sharp crease when a smoother path exists).

Convention: ``points (N, 3)`` float64 numpy; returns unit normals ``(N, 3)``. Each
connected component of the graph is oriented so that most of its normals point away
from the component's centroid (outward on closed shapes).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree


def knn_graph(points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Distances and indices ``(N, k)`` of each point's k nearest other points (cKDTree)."""
    k = int(min(k, len(points) - 1))
    d, idx = cKDTree(points).query(points, k=k + 1)
    return d[:, 1:], idx[:, 1:]


def pca_normals(points: np.ndarray, neighbours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented normals ``(N, 3)`` and surface variation ``(N,)`` from ``neighbours (N, k)``.

    Surface variation is ``lambda_0 / (lambda_0 + lambda_1 + lambda_2)`` (Pauly, Gross and
    Kobbelt 2002): 0 on a plane, up to 1/3 on isotropic noise.
    """
    nb = np.concatenate([np.arange(len(points))[:, None], neighbours], axis=1)
    local = points[nb]  # (N, k+1, 3)
    local = local - local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    w, v = np.linalg.eigh(cov)  # ascending eigenvalues
    variation = w[:, 0] / np.maximum(w.sum(axis=1), 1e-300)
    return v[:, :, 0], variation


def orient_normals(points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Flip normals so that neighbours agree, by propagation along a minimum spanning tree.

    Shapes: ``points (N, 3)``, ``normals (N, 3)``, ``neighbours (N, k)`` -> ``(N, 3)``.
    """
    n = len(points)
    rows = np.repeat(np.arange(n), neighbours.shape[1])
    cols = neighbours.reshape(-1)
    weight = 1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols])) + 1e-9
    graph = coo_matrix((weight, (rows, cols)), shape=(n, n)).tocsr()
    graph = graph.maximum(graph.T)
    tree = minimum_spanning_tree(graph)
    tree = tree + tree.T
    out = normals.copy()
    n_comp, comp = connected_components(tree, directed=False)
    for c in range(n_comp):
        members = np.flatnonzero(comp == c)
        root = members[np.argmax(points[members, 2])] if len(members) else 0
        order, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        # Visit in BFS order: each node agrees with its (already oriented) parent.
        for node in order[1:]:
            parent = pred[node]
            if np.dot(out[node], out[parent]) < 0:
                out[node] = -out[node]
        outward = np.einsum("ij,ij->i", out[order], points[order] - points[order].mean(axis=0))
        if np.sum(outward) < 0:
            out[order] = -out[order]
    return out


def estimate_normals(points: np.ndarray, k: int = 12, neighbours: np.ndarray | None = None) -> np.ndarray:
    """Consistently oriented unit normals ``(N, 3)`` of a point cloud ``(N, 3)``.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> xy = rng.random((200, 2))
        >>> n = estimate_normals(np.c_[xy, np.zeros(200)])
        >>> bool(np.all(np.abs(n[:, 2]) > 0.999)), bool(np.all(np.sign(n[:, 2]) == np.sign(n[0, 2])))
        (True, True)
    """
    points = np.asarray(points, dtype=np.float64)
    if neighbours is None:
        _, neighbours = knn_graph(points, k)
    normals, _ = pca_normals(points, neighbours)
    return orient_normals(points, normals, neighbours)
