"""Knot operations that leave the geometry unchanged: insertion, refinement, degree
elevation, splitting, Bezier decomposition and reversal, for curves, surfaces and
volumes alike.

One mechanism serves every kind of object. Each operation acts on one parametric
direction (``axis``: 0 = u, 1 = v, 2 = w) and is linear in the homogeneous control
points ``(w * P, w)`` along that direction: a matrix ``T (n_new, n_old)`` that depends
only on the knot vector and the degree. The matrix is built once in float64 from the
detached knots by running the curve algorithm of The NURBS Book (Piegl and Tiller) on
the identity (A5.1 knot insertion, A5.4 knot refinement; degree elevation through the
Bezier form, eq. 5.36), then applied along the axis as one matrix product; the result
is de-homogenised. So the
operations work for any parametric and spatial dimension, and the new control points
and weights are differentiable with respect to the old ones (not with respect to the
knots, whose new values are data built from the detached knots).

Convention:

* ``value`` arguments live in the knot domain ``[a, b] = [knots[p], knots[n]]`` of the
  chosen direction; they are rounded to the knots' dtype before use, so the inserted
  knot is exactly the one the matrix was built for.
* Knots closer than :func:`~nurbskit.core.knots.knot_tolerance` are one knot (as in
  OpenCASCADE): a value within that distance of an existing knot raises that knot's
  multiplicity, and values within it of each other are one value. No operation creates a
  span too short for the basis to divide by (a span of 5e-324 made a curve evaluate to NaN).
* A batch of splines (control points ``(*B, n_1..n_k, dim)``) sharing its knot vectors
  is transformed as a whole: every element gets the same new knots. A batch with one
  knot vector per element is refused (index an element first, ``batch[i]``).
* A knot may reach multiplicity ``p`` (the degree) by insertion, not more: at
  multiplicity ``p`` a control point already lies on the object (C0 there); ``p + 1``
  would cut it in two, which is what :func:`split` is for.
* :func:`elevate_degree` and :func:`decompose_bezier` return clamped knot vectors in
  that direction (an unclamped direction is clamped at its domain first, which keeps
  the geometry on the domain).
* dtype and device of the result follow the input object.

Example:
    >>> import torch
    >>> from nurbskit.core import NURBSCurve
    >>> c = NURBSCurve(torch.rand(5, 3, dtype=torch.float64), degree=3)
    >>> c2 = elevate_degree(insert_knot(c, 0.3, times=2), times=1)
    >>> c2.degree, c2.sizes
    (4, (10,))
"""

from __future__ import annotations

from math import comb
from typing import Sequence

import numpy as np
import torch
from scipy import linalg, sparse

from ..errors import NurbskitError
from .knots import knot_tolerance
from .spline import TensorSpline
from .tensor import homogeneous

Tensor = torch.Tensor
_AXES = ("u", "v", "w")

__all__ = ["insert_knot", "refine_knots", "elevate_degree", "split", "decompose_bezier", "reverse"]


# ---- validation and plumbing ----------------------------------------------------------

def _check_axis(obj: TensorSpline, axis, op: str) -> int:
    if not isinstance(obj, TensorSpline):
        raise NurbskitError(f"{op}: expected a NURBSCurve, NURBSSurface or NURBSVolume, got {type(obj).__name__}")
    if any(kv.ndim > 1 for kv in obj.knot_vectors):
        raise NurbskitError(
            f"{op}: a batch of shape {obj.batch_shape} with one knot vector per element has no common knots "
            f"to change; apply it to each element (batch[i])"
        )
    if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)) or not 0 <= int(axis) < obj.para_dim:
        allowed = "0" if obj.para_dim == 1 else f"0..{obj.para_dim - 1}"
        raise NurbskitError(f"{op}: axis must be an integer in {allowed} for a {obj.kind}, got {axis!r}")
    return int(axis)


def _check_count(count, name: str, op: str) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise NurbskitError(f"{op}: {name} must be a non-negative integer, got {count!r}")
    return int(count)


def _where(obj: TensorSpline, axis: int) -> str:
    return f"the {obj.kind}" if obj.para_dim == 1 else f"direction {_AXES[axis]} of the {obj.kind}"


def _knots64(obj: TensorSpline, axis: int) -> np.ndarray:
    return obj.knot_vectors[axis].detach().cpu().double().numpy().copy()


def _knot_values(obj: TensorSpline, axis: int, values, op: str) -> np.ndarray:
    """``values`` as float64, rounded through the knots' dtype and checked to be finite."""
    kv = obj.knot_vectors[axis]
    try:
        raw = torch.as_tensor(values.detach().cpu() if isinstance(values, Tensor) else values, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise NurbskitError(f"{op}: knot values must be real numbers, got {values!r}") from None
    if raw.ndim > 1:
        raise NurbskitError(f"{op}: knot values must be a number or a 1-D sequence, got shape {tuple(raw.shape)}")
    out = raw.reshape(-1).to(kv.dtype).double().numpy()
    if not np.all(np.isfinite(out)):
        raise NurbskitError(f"{op}: knot values must be finite, got {raw.tolist()!r}")
    return _snap(out, _knots64(obj, axis), knot_tolerance(kv))


def _snap(values: np.ndarray, knots: np.ndarray, tol: float) -> np.ndarray:
    """Values within ``tol`` of an existing knot become that knot; values within ``tol`` of
    each other (and of no knot) become the smallest of their run."""
    out = values.copy()
    if out.size == 0:
        return out
    nearest = np.abs(out[:, None] - knots[None, :])
    close = nearest.min(axis=1) <= tol
    out[close] = knots[nearest.argmin(axis=1)[close]]
    order = np.argsort(out, kind="stable")
    s = out[order]
    for i in range(1, s.size):
        if 0 < s[i] - s[i - 1] <= tol:
            s[i] = s[i - 1]
    out[order] = s
    return out


def _check_in_domain(obj: TensorSpline, axis: int, values: np.ndarray, op: str, *, open_: bool = False) -> None:
    a, b = obj.domain[axis]
    for v in values:
        inside = a < v < b if open_ else a <= v <= b
        if not inside:
            interval = f"({a!r}, {b!r})" if open_ else f"[{a!r}, {b!r}]"
            raise NurbskitError(f"{op}: knot value {float(v)!r} lies outside the domain {interval} of {_where(obj, axis)}")


def _check_multiplicity(obj: TensorSpline, axis: int, knots: np.ndarray, values: np.ndarray, op: str) -> None:
    """Each value may end with multiplicity at most the degree."""
    p = obj.degrees[axis]
    for v in np.unique(values):
        have = int(np.sum(knots == v))
        add = int(np.sum(values == v))
        if have + add > p:
            tol = knot_tolerance(obj.knot_vectors[axis])
            raise NurbskitError(
                f"{op}: knot {float(v)!r} has multiplicity {have} in {_where(obj, axis)} of degree {p}; "
                f"inserting it {add} more time(s) would exceed {p} (at most {max(p - have, 0)} more; "
                f"values within {tol:.1e} of a knot are that knot)"
            )


def _check_interior_multiplicity(obj: TensorSpline, axis: int, knots: np.ndarray, op: str) -> None:
    p = obj.degrees[axis]
    a, b = obj.domain[axis]
    inner = knots[(knots > a) & (knots < b)]
    values, counts = np.unique(inner, return_counts=True)
    if counts.size and counts.max() > p:
        i = int(np.argmax(counts))
        raise NurbskitError(
            f"{op}: interior knot {float(values[i])!r} of {_where(obj, axis)} has multiplicity {int(counts[i])}, "
            f"more than the degree {p} (a break in the object); split it there first"
        )


def _apply(obj: TensorSpline, axis: int, matrix: np.ndarray, knots: np.ndarray, degree: int | None = None):
    """A new object whose homogeneous control points along ``axis`` are ``matrix @ (w P, w)``.

    Shapes: ``matrix (n_new, n_old)`` with ``n_old = obj.sizes[axis]``; ``knots (n_new + degree + 1,)``.
    """
    Pw = homogeneous(obj.control_points, obj.weights)  # (*B, n_1, ..., n_k, dim + 1)
    T = torch.as_tensor(matrix, dtype=Pw.dtype, device=Pw.device)
    # One GEMM on a reshaped view: (n_new, n_old) @ (n_old, everything else).
    where = len(obj.batch_shape) + axis
    front = Pw.movedim(where, 0)
    moved = (T @ front.reshape(front.shape[0], -1)).reshape((T.shape[0],) + front.shape[1:]).movedim(0, where)
    kv_old = obj.knot_vectors[axis]
    kvs = list(obj.knot_vectors)
    kvs[axis] = torch.as_tensor(knots, dtype=torch.float64).to(dtype=kv_old.dtype, device=kv_old.device)
    degrees = list(obj.degrees)
    if degree is not None:
        degrees[axis] = int(degree)
    return obj._replace(
        control_points=(moved[..., :-1] / moved[..., -1:]).contiguous(),
        weights=moved[..., -1].contiguous(),
        knot_vectors=kvs,
        degrees=tuple(degrees),
    )


def _span(knots: np.ndarray, u: float) -> int:
    """The true span ``k`` with ``knots[k] <= u < knots[k + 1]`` (no clamping to the control net).

    At the end of an unclamped domain this is the span past the last control point,
    which is what A5.1 needs there (A5.4 clamps it to FindSpan's last span instead);
    ``u < knots[-1]`` holds for every value the callers let through (the multiplicity
    limit excludes the end of a clamped vector).
    """
    return int(np.searchsorted(knots, u, side="right")) - 1


# ---- the curve algorithms, run on the identity ----------------------------------------

def _insertion_matrix(knots: np.ndarray, p: int, u: float, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Insert ``u`` ``r`` times (The NURBS Book A5.1): ``(T (n + r, n), new knots)``."""
    n = len(knots) - p - 1
    P = np.eye(n)
    k = _span(knots, u)
    s = int(np.sum(knots == u))
    Q = np.zeros((n + r, n))
    Q[: k - p + 1] = P[: k - p + 1]
    Q[k - s + r :] = P[k - s :]
    R = P[k - p : k - s + 1].copy()
    L = k - p
    for j in range(1, r + 1):
        L = k - p + j
        for i in range(p - j - s + 1):
            alpha = (u - knots[L + i]) / (knots[i + k + 1] - knots[L + i])
            R[i] = alpha * R[i + 1] + (1.0 - alpha) * R[i]
        Q[L] = R[0]
        Q[k + r - j - s] = R[p - j - s]
    for i in range(L + 1, k - s):
        Q[i] = R[i - L]
    new_knots = np.concatenate([knots[: k + 1], np.full(r, u), knots[k + 1 :]])
    return Q, new_knots


def _refinement_matrix(knots: np.ndarray, p: int, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert all of the sorted values ``X`` at once (The NURBS Book A5.4).

    Returns ``(T (n + len(X), n), new knots)``.
    """
    U = knots
    n = len(U) - p - 2  # the book's n: index of the last control point
    m = n + p + 1
    r = len(X) - 1
    P = np.eye(n + 1)
    # FindSpan (A2.1) semantics: the last span owns the domain end U[n + 1].
    a = min(_span(U, X[0]), n)
    b = min(_span(U, X[r]), n) + 1
    Q = np.zeros((n + r + 2, n + 1))
    Ubar = np.zeros(m + r + 2)
    Q[: a - p + 1] = P[: a - p + 1]
    for j in range(b - 1, n + 1):
        Q[j + r + 1] = P[j]
    Ubar[: a + 1] = U[: a + 1]
    for j in range(b + p, m + 1):
        Ubar[j + r + 1] = U[j]
    i = b + p - 1
    k = b + p + r
    for j in range(r, -1, -1):
        while X[j] <= U[i] and i > a:
            Q[k - p - 1] = P[i - p - 1]
            Ubar[k] = U[i]
            k -= 1
            i -= 1
        Q[k - p - 1] = Q[k - p]
        for l in range(1, p + 1):
            ind = k - p + l
            alpha = Ubar[k + l] - X[j]
            if alpha == 0.0:
                Q[ind - 1] = Q[ind]
            else:
                alpha = alpha / (Ubar[k + l] - U[i - p + l])
                Q[ind - 1] = alpha * Q[ind - 1] + (1.0 - alpha) * Q[ind]
        Ubar[k] = X[j]
        k -= 1
    return Q, Ubar


def _bezier_matrix(knots: np.ndarray, p: int) -> np.ndarray:
    """Control points to Bezier control points (A5.4 to multiplicity ``p`` at every
    interior break) for a clamped vector: ``(spans * p + 1, n)``."""
    breaks, counts = np.unique(knots, return_counts=True)
    missing = np.repeat(breaks[1:-1], p - counts[1:-1])
    if missing.size == 0:
        return np.eye(len(knots) - p - 1)
    return _refinement_matrix(knots, p, missing)[0]


def _elevation_matrix(knots: np.ndarray, p: int, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Raise the degree by ``t`` through the Bezier form, for a clamped knot vector whose
    interior knots have multiplicity at most ``p``: ``(T (n_new, n), new knots)``.

    Decompose into Bezier segments (A5.4), elevate each (The NURBS Book eq. 5.36), then
    find the control points on the new knot vector (every multiplicity raised by ``t``)
    whose Bezier form is that: ``D T = E B`` with ``D`` the new vector's own Bezier
    matrix. The system is consistent and ``D`` has full column rank, so its solution is
    exact. This solve plays the part of A5.9's knot removal; its conditioning is that of
    the B-spline basis (bounded in terms of the degree alone), whereas A5.9's one-sided
    removal formulas lose digits on short spans at high degree (degree 7 with a span of
    1e-6 of the domain: errors of order 1 from A5.9, 1e-15 here).
    """
    ph = p + t
    breaks, counts = np.unique(knots, return_counts=True)
    spans = breaks.size - 1
    bezalfs = np.zeros((ph + 1, p + 1))
    for i in range(ph + 1):
        for j in range(max(0, i - t), min(p, i) + 1):
            bezalfs[i, j] = comb(p, j) * comb(t, i - j) / comb(ph, i)
    E = sparse.lil_matrix((spans * ph + 1, spans * p + 1))
    for s in range(spans):  # neighbouring segments share their end point (rows 0 and ph of bezalfs)
        E[s * ph : s * ph + ph + 1, s * p : s * p + p + 1] = bezalfs
    new_knots = np.repeat(breaks, counts + t)
    D = _bezier_matrix(new_knots, ph)
    T = _solve_consistent_banded(D, E.tocsr() @ _bezier_matrix(knots, p))
    return T, new_knots


def _solve_consistent_banded(D: np.ndarray, rhs: np.ndarray, refinements: int = 2) -> np.ndarray:
    """``X`` with ``D X = rhs`` for a consistent system whose ``D (m, n)`` is banded with full
    column rank: banded Cholesky of ``D^T D`` (semi-normal equations) plus iterative
    refinement on the residual, O(n * bandwidth^2) instead of a dense QR's O(m * n^2)."""
    Ds = sparse.csr_matrix(D)
    G = (Ds.T @ Ds).tocoo()
    bw = int(np.abs(G.row - G.col).max()) if G.nnz else 0
    n = D.shape[1]
    upper = np.zeros((bw + 1, n))  # LAPACK upper banded storage: upper[bw + i - j, j] = G[i, j]
    keep = G.col >= G.row
    upper[bw + G.row[keep] - G.col[keep], G.col[keep]] = G.data[keep]
    factor = linalg.cholesky_banded(upper)
    X = linalg.cho_solve_banded((factor, False), Ds.T @ rhs)
    for _ in range(refinements):
        X += linalg.cho_solve_banded((factor, False), Ds.T @ (rhs - Ds @ X))
    return X


def _cut_rows(knots: np.ndarray, p: int, v: float) -> tuple[slice, np.ndarray, slice, np.ndarray]:
    """Where to cut a control net whose knot ``v`` has multiplicity ``s >= p``.

    With ``v`` at ``knots[j : j + s]``, the piece before ``v`` keeps control points
    ``[:j]`` and knots ``knots[:j] + [v] * (p + 1)``; the piece after keeps control
    points from ``j + s - p - 1`` and knots ``[v] * (p + 1) + knots[j + s:]``. With
    ``s == p`` the two pieces share the point on the object at ``v``.
    """
    j = int(np.searchsorted(knots, v, side="left"))
    s = int(np.sum(knots == v))
    ends = np.full(p + 1, v)
    return (
        slice(0, j),
        np.concatenate([knots[:j], ends]),
        slice(j + s - p - 1, None),
        np.concatenate([ends, knots[j + s :]]),
    )


def _clamp_matrix(knots: np.ndarray, p: int, domain: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Bring both domain ends to multiplicity ``p + 1`` and drop the control points
    outside: ``(T (n_new, n), clamped knots)``; the identity for a clamped vector."""
    a, b = domain
    T = np.eye(len(knots) - p - 1)
    for end, keep_after in ((a, True), (b, False)):
        r = p - int(np.sum(knots == end))
        if r > 0:
            step, knots = _insertion_matrix(knots, p, end, r)
            T = step @ T
        first, first_knots, second, second_knots = _cut_rows(knots, p, end)
        if keep_after:
            T, knots = T[second], second_knots
        else:
            T, knots = T[first], first_knots
    return T, knots


# ---- public operations ----------------------------------------------------------------

def insert_knot(obj: TensorSpline, value: float, times: int = 1, axis: int = 0) -> TensorSpline:
    """Insert the knot ``value`` ``times`` times in direction ``axis`` (The NURBS Book A5.1).

    Shapes: along ``axis`` the control net grows from ``n`` to ``n + times``; the other
    directions are unchanged (``(n_u, n_v, dim)`` -> ``(n_u + times, n_v, dim)`` for
    ``axis=0`` on a surface). ``value`` must lie in the domain of that direction and end
    with multiplicity at most the degree.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSSurface
        >>> s = NURBSSurface(torch.rand(4, 5, 3, dtype=torch.float64), degrees=(3, 2))
        >>> insert_knot(s, 0.5, times=2, axis=1).sizes
        (4, 7)
    """
    op = "insert_knot"
    axis = _check_axis(obj, axis, op)
    times = _check_count(times, "times", op)
    values = _knot_values(obj, axis, value, op)
    if values.size != 1:
        raise NurbskitError(f"{op}: value must be a single number, got {values.size} values (use refine_knots)")
    if times == 0:
        return obj._replace()
    knots = _knots64(obj, axis)
    _check_in_domain(obj, axis, values, op)
    _check_multiplicity(obj, axis, knots, np.repeat(values, times), op)
    T, new_knots = _insertion_matrix(knots, obj.degrees[axis], float(values[0]), times)
    return _apply(obj, axis, T, new_knots)


def refine_knots(obj: TensorSpline, values: Sequence[float] | Tensor, axis: int = 0) -> TensorSpline:
    """Insert many knots at once in direction ``axis`` (The NURBS Book A5.4).

    ``values (r,)`` in any order, repeats allowed (each value ends with multiplicity at
    most the degree); the control net grows by ``r`` along ``axis``.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSCurve
        >>> c = NURBSCurve(torch.rand(4, 2, dtype=torch.float64), degree=3)
        >>> refine_knots(c, [0.25, 0.5, 0.5, 0.75]).knot_vector.tolist()
        [0.0, 0.0, 0.0, 0.0, 0.25, 0.5, 0.5, 0.75, 1.0, 1.0, 1.0, 1.0]
    """
    op = "refine_knots"
    axis = _check_axis(obj, axis, op)
    X = np.sort(_knot_values(obj, axis, values, op))
    if X.size == 0:
        return obj._replace()
    knots = _knots64(obj, axis)
    _check_in_domain(obj, axis, X, op)
    _check_multiplicity(obj, axis, knots, X, op)
    T, new_knots = _refinement_matrix(knots, obj.degrees[axis], X)
    return _apply(obj, axis, T, new_knots)


def elevate_degree(obj: TensorSpline, times: int = 1, axis: int = 0) -> TensorSpline:
    """Raise the degree in direction ``axis`` by ``times`` (through the Bezier form, The NURBS Book eq. 5.36).

    Every distinct knot gains ``times`` in multiplicity, so continuity is kept; along
    ``axis`` the control net grows from ``n`` to ``n + times * (number of non-empty
    spans)``. The knot vector of that direction comes back clamped (an unclamped one is
    clamped at its domain first). Interior knots of multiplicity above the degree are
    refused: split there first.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSCurve
        >>> c = NURBSCurve(torch.rand(5, 3, dtype=torch.float64), degree=2)
        >>> e = elevate_degree(c, times=2)
        >>> e.degree, e.sizes
        (4, (11,))
    """
    op = "elevate_degree"
    axis = _check_axis(obj, axis, op)
    times = _check_count(times, "times", op)
    if times == 0:
        return obj._replace()
    p = obj.degrees[axis]
    knots = _knots64(obj, axis)
    _check_interior_multiplicity(obj, axis, knots, op)
    C, clamped = _clamp_matrix(knots, p, obj.domain[axis])
    E, new_knots = _elevation_matrix(clamped, p, times)
    return _apply(obj, axis, E @ C, new_knots, degree=p + times)


def split(obj: TensorSpline, value: float, axis: int = 0) -> tuple[TensorSpline, TensorSpline]:
    """Cut the object at ``value`` in direction ``axis`` into two of the same kind.

    The knot is inserted up to multiplicity ``p`` and the control net cut there; the
    first piece covers ``[a, value]`` and the second ``[value, b]`` of that direction,
    each with its original parametrisation (no re-scaling). ``value`` must lie strictly
    inside the domain.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSCurve
        >>> c = NURBSCurve(torch.rand(5, 3, dtype=torch.float64), degree=3)
        >>> left, right = split(c, 0.4)
        >>> left.domain, right.domain
        ([(0.0, 0.4)], [(0.4, 1.0)])
    """
    op = "split"
    axis = _check_axis(obj, axis, op)
    values = _knot_values(obj, axis, value, op)
    if values.size != 1:
        raise NurbskitError(f"{op}: value must be a single number, got {values.size} values")
    _check_in_domain(obj, axis, values, op, open_=True)
    v = float(values[0])
    p = obj.degrees[axis]
    knots = _knots64(obj, axis)
    r = p - int(np.sum(knots == v))
    if r > 0:
        T, knots = _insertion_matrix(knots, p, v, r)
    else:
        T = np.eye(obj.sizes[axis])
    first, first_knots, second, second_knots = _cut_rows(knots, p, v)
    return _apply(obj, axis, T[first], first_knots), _apply(obj, axis, T[second], second_knots)


def decompose_bezier(obj: TensorSpline, axis: int = 0) -> list[TensorSpline]:
    """The Bezier pieces of direction ``axis``, one per non-empty knot span, in order.

    Each piece has ``p + 1`` control points along ``axis`` and knots
    ``[u_i] * (p + 1) + [u_{i+1}] * (p + 1)`` there (the original parameters, not
    re-scaled); the other directions are untouched (decompose them in turn for
    fully Bezier patches).

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSCurve
        >>> c = NURBSCurve(torch.rand(6, 2, dtype=torch.float64), degree=2)
        >>> [piece.domain[0] for piece in decompose_bezier(c)]
        [(0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.0)]
    """
    op = "decompose_bezier"
    axis = _check_axis(obj, axis, op)
    p = obj.degrees[axis]
    knots = _knots64(obj, axis)
    a, b = obj.domain[axis]
    inner, counts = np.unique(knots[(knots > a) & (knots < b)], return_counts=True)
    if counts.size and counts.max() > p:  # a break (multiplicity p + 1): the pieces on each side apart
        left, right = split(obj, float(inner[np.argmax(counts > p)]), axis)
        return decompose_bezier(left, axis) + decompose_bezier(right, axis)
    T, knots = _clamp_matrix(knots, p, obj.domain[axis])
    breaks = np.unique(knots)
    T = _bezier_matrix(knots, p) @ T
    pieces = []
    for i, (lo, hi) in enumerate(zip(breaks[:-1], breaks[1:])):
        piece_knots = np.concatenate([np.full(p + 1, lo), np.full(p + 1, hi)])
        pieces.append(_apply(obj, axis, T[i * p : i * p + p + 1], piece_knots))
    return pieces


def reverse(obj: TensorSpline, axis: int = 0) -> TensorSpline:
    """The same object traversed backwards in direction ``axis``.

    The control points and weights are flipped along ``axis`` and the knot vector is
    mirrored within the domain ``[a, b]`` (``u -> a + b - u``), so the domain stays the
    same and ``reverse(obj)(u) == obj(a + b - u)``.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSCurve
        >>> c = NURBSCurve(torch.tensor([[0., 0.], [1., 2.], [3., 0.]]), degree=2)
        >>> reverse(c).control_points.tolist()
        [[3.0, 0.0], [1.0, 2.0], [0.0, 0.0]]
    """
    op = "reverse"
    axis = _check_axis(obj, axis, op)
    kv = obj.knot_vectors[axis]
    a, b = obj.domain[axis]
    # Computed in float64 and the domain ends snapped, so that the domain is kept exactly.
    k = kv.detach().double().flip(0)
    mirrored = torch.where(k == a, b, torch.where(k == b, a, (a + b) - k))
    kvs = list(obj.knot_vectors)
    kvs[axis] = mirrored.to(kv.dtype)
    # A permutation needs no homogeneous round trip: flipping is exact.
    where = len(obj.batch_shape) + axis
    return obj._replace(
        control_points=obj.control_points.flip(where),
        weights=obj.weights.flip(where),
        knot_vectors=kvs,
    )
