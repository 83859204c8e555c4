"""Planar profile curves from unordered 2-D points: ordering, then least-squares B-splines.

1. **Order** (after I.-K. Lee, "Curve reconstruction from unorganized points", CAGD 17,
   2000): thin the points to cell centroids, connect them by the Euclidean minimum
   spanning tree of a k-nearest-neighbour graph (the KD-tree of
   :func:`nurbskit.core.neighbors.kdtree`; scipy's ``minimum_spanning_tree``), and take the
   tree's longest path (two sweeps of shortest-path distances) as the curve's polyline:
   side branches made by noise fall off. Each input point takes the arc length of its
   foot point on that polyline (chord-length parameters).
2. **Fit**: least squares on the basis matrix of :func:`nurbskit.core.basis.basis_matrix`
   (The NURBS Book, section 9.4.1), knots at parameter quantiles (every span holds data)
   and a small second-difference penalty (keeps sparse spans well posed); then parameter
   correction: each point's parameter is replaced by its foot point on the fitted curve
   (:func:`nurbskit.core.project.project_points_curve`) and the fit repeated. The number of
   control points is the rung of a ladder with the smallest Bayesian information
   criterion ``N log(mean squared residual) + 2 n log N`` (G. Schwarz, 1978), among the
   rungs whose knot spans are at least ``BAND_SPANS`` times the RMS residual: on noisy
   points, shorter spans let the curve zig-zag through the noise band (the residual then
   falls below the noise, and the refinement tilts the axis to feed the zig-zags).

Convention: points ``(N, 2)`` float64; parameters in [0, 1]. Closed profiles (a torus's
circle, a tube's section) are detected when the ordering's two ends meet
(:func:`is_closed`) and fitted as **periodic** curves: uniform unclamped knots
(:func:`nurbskit.fit.params.periodic_knots`, the core's periodic knot vector: domain
[0, 1], spacing ``1 / (n - p)``) with the last ``p`` control points (and weights) tied
to the first ``p`` (:func:`closing_matrix` with ``wrap=p``), so the curve is closed and
C^{p-1} across the seam (C2 for the cubic): no corner where the ordering happened to
start. The parameters go round the loop by chord length, the gap between the ordering's
ends included (the seam is a span like any other). :func:`nurbskit.io.cad` writes such a
curve as OpenCASCADE's periodic B-spline, and the projection detects it as periodic
(:func:`nurbskit.core.project.periodic_directions`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from ..core.basis import basis_matrix
from ..core.curve import NURBSCurve
from ..core.neighbors import kdtree
from ..core.project import project_points_curve
from ..errors import InputError

Tensor = torch.Tensor

__all__ = ["order_points", "order_polyline", "Ordering", "fit_curve_lsq", "fit_profile", "ProfileFit", "is_closed", "closing_matrix",
           "periodic_profile_knots"]

LADDER = (6, 8, 11, 15, 20, 26, 34)
BAND_SPANS = 6.0
NODE_FRACTION = 0.5
"""At most this many control points per distinct profile position (thinned polyline node):
sparse data (a mesh's rings: many points, few positions) cannot pin more, the curve would
swing between them."""
PATIENCE = 2
"""The ladder stops after this many rungs without a new minimum of the criterion."""
CHECK_EVERY = 2
"""The curve projections check convergence every this many Newton iterations (warm starts
converge in two or three)."""
FAST_CORRECTIONS = True
"""Only the first parameter correction restarts from the grid."""
"""A rung is refused when its knot spans are shorter than this many times the RMS residual."""


def order_points(xy, cells: int = 160) -> np.ndarray:
    """Chord-length parameters ``(N,)`` in [0, 1] of unordered points ``xy (N, 2)`` along
    the curve they sample (module docstring, step 1)."""
    return order_polyline(xy, cells).params


class Ordering(NamedTuple):
    params: np.ndarray
    """Chord-length parameters ``(N,)`` in [0, 1]."""
    polyline: np.ndarray
    """The ordered thinned points ``(L, 2)`` the parameters are measured on (the spanning
    tree's longest path): its consecutive spacings are the sampling's, after thinning."""
    band: float
    """Median distance of the points to the polyline: the half-width of the noise band."""


def order_polyline(xy, cells: int = 160) -> Ordering:
    """:func:`order_points` with the polyline and the noise band it found (:class:`Ordering`)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree

    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[0] < 4:
        raise InputError(f"profile needs at least 4 points, got shape {xy.shape}")
    lo, hi = xy.min(0), xy.max(0)
    h = float(np.linalg.norm(hi - lo)) / cells
    if not h > 0:
        raise InputError("profile points are all the same point")
    keys = np.floor((xy - lo) / h).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    m = int(inverse.max()) + 1
    nodes = np.zeros((m, 2))
    np.add.at(nodes, inverse, xy)
    nodes /= np.bincount(inverse, minlength=m)[:, None]
    if m < 2:
        raise InputError("profile points are all the same point")
    k = min(8, m - 1)
    dist, idx = kdtree(nodes).query(nodes, k + 1)
    rows = np.repeat(np.arange(m), k)
    graph = coo_matrix((dist[:, 1:].reshape(-1) + 1e-15, (rows, idx[:, 1:].reshape(-1))), shape=(m, m)).tocsr()
    graph = graph.maximum(graph.T)
    # the largest connected component carries the curve
    _, comp = connected_components(graph, directed=False)
    main = np.bincount(comp).argmax()
    keep = np.flatnonzero(comp == main)
    tree = minimum_spanning_tree(graph[keep][:, keep])
    tree = tree.maximum(tree.T)
    d0 = dijkstra(tree, directed=False, indices=0)
    a = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
    da, pred = dijkstra(tree, directed=False, indices=a, return_predecessors=True)
    b = int(np.argmax(np.where(np.isfinite(da), da, -1)))
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    poly = nodes[keep][np.array(path[::-1])]  # (L, 2)
    if poly.shape[0] < 2:
        raise InputError("profile points do not form a curve")
    seg = poly[1:] - poly[:-1]
    seg_len = np.linalg.norm(seg, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg_len)])
    # foot point on the nearest of the two segments around the nearest polyline vertex
    _, near = kdtree(poly).query(xy)
    best_t = np.zeros(xy.shape[0])
    best_d = np.full(xy.shape[0], np.inf)
    for offset in (-1, 0):
        s = np.clip(near + offset, 0, seg.shape[0] - 1)
        d = seg[s]
        ll = np.maximum((d * d).sum(1), 1e-300)
        t = np.clip(((xy - poly[s]) * d).sum(1) / ll, 0.0, 1.0)
        foot = poly[s] + t[:, None] * d
        dd = ((xy - foot) ** 2).sum(1)
        better = dd < best_d
        best_d = np.where(better, dd, best_d)
        best_t = np.where(better, arc[s] + t * seg_len[s], best_t)
    return Ordering(best_t / max(arc[-1], 1e-300), poly, float(np.median(np.sqrt(best_d))))


def _quantile_knots(u: Tensor, n_ctrl: int, degree: int) -> Tensor:
    inner = torch.quantile(u, torch.linspace(0, 1, n_ctrl - degree + 1, dtype=u.dtype)[1:-1])
    # strictly increasing interior knots (duplicated data parameters would make them repeat)
    eps = 1e-6
    inner = torch.maximum(inner, torch.arange(1, inner.numel() + 1, dtype=u.dtype) * eps)
    inner = torch.cummax(inner + torch.arange(inner.numel(), dtype=u.dtype) * eps, 0).values.clamp(max=1 - eps)
    zeros, ones = torch.zeros(degree + 1, dtype=u.dtype), torch.ones(degree + 1, dtype=u.dtype)
    return torch.cat([zeros, inner, ones])


def closing_matrix(n_ctrl: int, closed: bool, wrap: int = 1) -> Tensor:
    """``E (n_ctrl, m)``: control points ``E @ free``.

    Open: ``m = n_ctrl``, ``E`` the identity. Closed: ``m = n_ctrl - wrap`` and the last
    ``wrap`` control points repeat the first ``wrap`` (control point ``j`` is free unknown
    ``j mod m``): ``wrap = 1`` is a clamped curve whose ends meet (C0 at the seam),
    ``wrap = degree`` with periodic knots a periodic curve (C^{degree-1} at the seam).

    Example:
        >>> closing_matrix(5, True, wrap=2).argmax(1).tolist()
        [0, 1, 2, 0, 1]
    """
    E = torch.eye(n_ctrl, dtype=torch.float64)
    if not closed:
        return E
    m = n_ctrl - wrap
    if not 0 < wrap < n_ctrl:
        raise InputError(f"a closed curve of {n_ctrl} control points cannot repeat {wrap} of them")
    return E[:, :m][torch.arange(n_ctrl) % m].clone()


def periodic_profile_knots(n_ctrl: int, degree: int) -> Tensor:
    """The periodic knot vector of a closed profile: the core's uniform unclamped knots
    (:func:`nurbskit.fit.params.periodic_knots`, domain [0, 1], the wrapped knots as
    OpenCASCADE computes them) in float64."""
    from ..fit.params import periodic_knots

    return periodic_knots(n_ctrl, degree, dtype=torch.float64)


def fit_curve_lsq(points, params, n_ctrl: int, degree: int = 3, *, knots: Tensor | None = None,
                  smoothing: float = 1e-6, closed: bool = False) -> NURBSCurve:
    """Least-squares B-spline ``NURBSCurve`` through ``points (N, D)`` at ``params (N,)`` in [0, 1].

    ``knots`` default to parameter quantiles (open) or the periodic knots
    (:func:`periodic_profile_knots`, closed); ``smoothing`` weighs the second differences
    of the control points relative to the data term's scale. ``closed``: a periodic curve,
    ``n_ctrl`` counting the ``degree`` control points that repeat the first ones (so
    ``n_ctrl - degree`` are free; module docstring); the second differences run round the
    seam.
    """
    x = torch.as_tensor(points, dtype=torch.float64)
    u = torch.as_tensor(params, dtype=torch.float64).clamp(0, 1)
    if knots is not None:
        kv = knots
    else:
        kv = periodic_profile_knots(n_ctrl, degree) if closed else _quantile_knots(u, n_ctrl, degree)
    E = closing_matrix(n_ctrl, closed, degree)
    B = basis_matrix(kv, degree, n_ctrl, u) @ E  # (N, m)
    # on the wrapped net the consecutive second differences already cross the seam
    D = torch.diff(torch.eye(n_ctrl, dtype=torch.float64), n=2, dim=0) @ E
    BtB = B.T @ B
    lam = smoothing * float(BtB.diagonal().mean())
    m = E.shape[1]
    free = torch.linalg.solve(BtB + lam * D.T @ D + 1e-12 * torch.eye(m, dtype=torch.float64), B.T @ x)
    return NURBSCurve(E @ free, degree=degree, knot_vector=kv)


class ProfileFit(NamedTuple):
    curve: NURBSCurve
    """The fitted curve in the plane, ``(n, 2)`` control points."""
    params: Tensor
    """Each point's parameter on it ``(N,)``."""
    residual_mean: float
    """Mean distance of the points to the curve (after parameter correction)."""
    closed: bool = False
    """The curve is closed and periodic (its last ``degree`` control points repeat its first)."""


CLOSE_SPACINGS = 8.0
"""The ordering's ends meet when their gap is at most this many typical spacings."""
CLOSE_LOOP = 0.3
"""... and at most this fraction of the loop (polyline and gap): on sparse points a few
spacings can be a large part of the curve (a half circle of 8 points is no ring)."""
BAND_SPACING = 4.0
"""On noisy points the typical spacing is at least this many noise half-widths: the
ordering's path wanders across the noise band, and its ends with it."""


def is_closed(xy, params=None, ordering: Ordering | None = None) -> bool:
    """Whether the points ``xy (N, 2)`` sample a closed curve.

    The ends of the ordering's polyline (``ordering``, else :func:`order_polyline` is run;
    ``params`` is kept for compatibility and unused) meet: their gap is at most
    ``CLOSE_SPACINGS`` typical spacings, the typical spacing being the larger of the
    polyline's 90th-percentile consecutive spacing and ``BAND_SPACING`` times the noise
    band's half-width. The test follows the sampling: a sparse ring (a mesh's vertices,
    a few per ring) closes across one of its wide spacings, a dense open arc whose ends
    are a fraction of its length apart does not. Measured on vases, L and wave profiles
    (open: gap over spacing >= 12 up to 2 % noise) and tori, squares and ellipses (closed:
    <= 7), 300 and 2,000 points. The gap must also be at most ``CLOSE_LOOP`` of the loop
    (polyline and gap; open: >= 0.38, closed: <= 0.24 on those clouds, ``1 / count`` for
    a ring of ``count`` points), and the loop long enough to go round (more than twice
    the extent).
    """
    x = np.asarray(xy, dtype=np.float64)
    o = order_polyline(x) if ordering is None else ordering
    poly = o.polyline
    if poly.shape[0] < 3:
        return False
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    spacing = max(float(np.percentile(seg, 90)), BAND_SPACING * o.band)
    gap = float(np.linalg.norm(poly[-1] - poly[0]))
    ext = float(np.linalg.norm(x.max(0) - x.min(0)))
    loop = float(seg.sum()) + gap
    return bool(gap <= CLOSE_SPACINGS * spacing and gap <= CLOSE_LOOP * loop and loop > 2 * ext)


def _loop_share(polyline: np.ndarray) -> float:
    """The polyline's share of its closed loop (the polyline and the gap between its ends):
    a closed curve's chord-length parameters stop short of 1 by the gap's share."""
    length = float(np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum())
    gap = float(np.linalg.norm(polyline[-1] - polyline[0]))
    return length / max(length + gap, 1e-300)


def fit_profile(xy, degree: int = 3, ladder=LADDER, corrections: int = 2, closed: bool | None = None) -> ProfileFit:
    """Order ``xy (N, 2)`` and fit the profile curve (module docstring).

    ``closed``: fit a closed curve (True), an open one (False), or decide by
    :func:`is_closed` (None).
    """
    x = torch.as_tensor(np.asarray(xy), dtype=torch.float64)
    ordering = order_polyline(x.numpy())
    u0 = torch.as_tensor(ordering.params, dtype=torch.float64)
    if closed is None:
        closed = is_closed(x.numpy(), ordering=ordering)
    if closed:
        u0 = u0 * _loop_share(ordering.polyline)
    N = x.shape[0]
    scale = float((x.amax(0) - x.amin(0)).norm()) ** 2
    fits, bic = [], []
    # sparse data (a mesh's rings: many points, few distinct positions along the profile)
    # cannot pin more control points than its distinct positions: the curve would swing
    # between them
    nodes = ordering.polyline.shape[0]
    # a closed curve's rung counts its free control points (n_ctrl = n + degree, the last
    # degree repeating the first): the same unknowns and spans as an open rung of n
    periodic = (True,) if closed else (False,)
    for n in ladder:
        if n > max(degree + 1, min(N // 4, int(NODE_FRACTION * nodes))):
            break
        n_ctrl = n + degree if closed else n
        u = u0
        curve = fit_curve_lsq(x, u, n_ctrl, degree, closed=closed)
        for c in range(corrections):
            # the first correction also restarts from the grid (the chord-length start can
            # sit in the wrong basin); later ones move little, warm starts suffice
            u = project_points_curve(curve, x, params=u, restart=c == 0 or not FAST_CORRECTIONS,
                                     check_every=CHECK_EVERY, periodic=periodic).params
            curve = fit_curve_lsq(x, u, n_ctrl, degree, knots=curve.knot_vector, closed=closed)
        dist = project_points_curve(curve, x, params=u, check_every=CHECK_EVERY, periodic=periodic).distance
        msq = float((dist ** 2).mean())
        # knot spans shorter than a few times the noise band's width let the curve zig-zag
        # through the noise (its residual then falls below the noise): stop the ladder there
        spans = n_ctrl - degree
        length = float(curve.evaluate(torch.linspace(0, 1, 200, dtype=torch.float64)).diff(dim=0).norm(dim=-1).sum())
        if fits and length / spans < BAND_SPANS * msq ** 0.5:
            break
        fits.append(ProfileFit(curve, u, float(dist.mean()), closed))
        # Bayesian information criterion (Schwarz 1978): N log(mean squared residual) + k log N
        # with k = 2 n unknowns (the free control points): more must pay for themselves
        bic.append(N * np.log(max(msq / scale, 1e-30)) + 2 * n * np.log(N))
        # the criterion rises once the residual has reached the noise: stop after
        # PATIENCE rungs without a new minimum (the later rungs cost the most)
        if PATIENCE and len(bic) - 1 - int(np.argmin(bic)) >= PATIENCE:
            break
    if not fits:
        raise InputError(f"too few profile points ({x.shape[0]}) for a degree-{degree} curve")
    return fits[int(np.argmin(bic))]
