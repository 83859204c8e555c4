"""Region adjacency: two regions are neighbours when enough kNN links join their points.

NURBSFit (section 3.2) calls two patches adjacent when at least one pair of their points
is adjacent in the k-nearest-neighbour graph; ``min_links`` raises that to a few links so
that a stray point does not join two far-apart parts.
"""

from __future__ import annotations

import numpy as np


def link_counts(labels: np.ndarray, neighbours: np.ndarray) -> dict[tuple[int, int], int]:
    """``{(a, b): links}`` with ``a < b`` for every pair of regions joined by kNN links.

    Shapes: ``labels (N,)`` (``-1``: in no region), ``neighbours (N, k)`` indices. A link
    is one (point, neighbour) pair of the graph, counted in each direction it appears.

    Example:
        >>> link_counts(np.array([0, 0, 1, -1]), np.array([[1], [2], [1], [2]]))
        {(0, 1): 2}
    """
    a = np.repeat(labels, neighbours.shape[1])
    b = labels[neighbours.reshape(-1)]
    ok = (a >= 0) & (b >= 0) & (a != b)
    if not ok.any():
        return {}
    pairs = np.stack([np.minimum(a[ok], b[ok]), np.maximum(a[ok], b[ok])], axis=1)
    uniq, counts = np.unique(pairs, axis=0, return_counts=True)
    return {(int(p), int(q)): int(c) for (p, q), c in zip(uniq, counts)}


def adjacency(labels: np.ndarray, neighbours: np.ndarray, min_links: int = 1) -> dict[int, dict[int, int]]:
    """Adjacency lists ``{region: {neighbour: links}}`` keeping pairs with ``>= min_links`` links."""
    graph: dict[int, dict[int, int]] = {int(r): {} for r in np.unique(labels[labels >= 0])}
    for (p, q), c in link_counts(labels, neighbours).items():
        if c >= min_links:
            graph[p][q] = c
            graph[q][p] = c
    return graph
