"""nurbskit objects to OpenCASCADE shapes and back: faces with trimming wires, sewn
shells, triangulated solids, and the nurbskit objects found in any shape.

Convention:
    A :class:`~nurbskit.core.trim.TrimmedSurface` becomes one face on its surface. Each
    trimming loop (a closed polyline in (u, v)) becomes a wire of edges of
    ``EDGE_SEGMENTS`` polyline segments (why: at ``EDGE_SEGMENTS``); an edge's curve on
    the surface is its piece of the polyline (a degree-1 ``Geom2d_BSplineCurve``,
    parameter = cumulative chord length in (u, v) along the loop: the exact trim), and
    its 3-D curve is its piece of a polynomial approximation of the polyline's image
    within the edge's tolerance (:func:`edge_tolerance`: ``CURVE_TOLERANCE`` of the
    surface's size, at most 0.001 mm, which the edge carries; :func:`approximate_trim_curves`).
    The exact image is rational of degree ``p + q`` (:func:`loop_curve_3d`: along a
    straight (u, v) segment the surface point is a polynomial of degree ``p + q`` in
    homogeneous coordinates within a knot span), written where it is smaller or with ``EXACT_CURVES``.
    A :class:`~nurbskit.io.cad.analytic.RevolvedSurface` / ``ExtrudedSurface`` becomes a
    face on OCC's surface of revolution / extrusion over its parameter bounds. The outer loop runs
    counter-clockwise and holes clockwise, as OCC expects for a forward face, so the
    kept region is on the left of every loop. A surface without loops is bounded by its
    parameter domain (its natural boundary).

    Reading, every face gives one TrimmedSurface: a B-spline surface as stored (exact,
    periodic directions unwrapped), any other surface (plane, cylinder, cone, sphere,
    torus, revolution, extrusion, offset) converted to a B-spline by OCC's
    ``BRepBuilderAPI_NurbsConvert`` restricted to that face; its wires as UV polylines
    (line and degree-1 pcurves exactly at their vertices, curved pcurves sampled with
    ``GCPnts_TangentialDeflection``), the outer wire (``BRepTools::OuterWire``) as the
    outer loop and the others as holes.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import torch

from ...core.curve import NURBSCurve
from ...core.spline import TensorSpline
from ...core.trim import TrimLoop, TrimmedSurface
from ...errors import NurbskitError, OptionError
from .occ import as_bspline_surface, curve_from_occ, curve_to_occ, ocp, surface_from_occ, surface_to_occ

#: default modelling tolerance (model units, millimetres): OCC's Precision::Confusion is 1e-7
TOLERANCE = 1e-7
#: tolerance of the edges on trimming loops, relative to the surface's size (the diagonal
#: of its control points, at least 1): their 3-D curves lie within it of the exact image
#: of the pcurve (:func:`approximate_loop_curves_3d`); the pcurves stay exact. 1e-5 of a
#: 15 mm patch is 0.15 um, of a 100 mm patch 1 um, the 0.001 mm CAD systems model to;
#: never coarser than ``CURVE_TOLERANCE_MAX`` nor finer than ``TOLERANCE`` (OCC's
#: Precision::Confusion). Poles per loop of benchmarks/bench_cad.py's patches and what
#: writing and checking them costs, per tolerance and degree: docs/cad.md
CURVE_TOLERANCE = 1e-5
#: the largest edge tolerance of a trimming loop, model units (mm): 0.001 mm
CURVE_TOLERANCE_MAX = 1e-3
#: True: the 3-D curves of trimming loops are the exact rational images (:func:`loop_curves_3d`,
#: degree p + q) instead of approximations within the edge's tolerance
EXACT_CURVES = False
#: reading: curved pcurves become polylines within this (u, v) distance (relative to the
#: face's (u, v) extent) and this turning angle (radians) per segment; a circular hole of
#: radius 3 in a 64 x 64 face then has about 65 points and loses 0.2 % of its area (finer loops
#: make OCC's reading and checking of the file slower: both grow with the points squared)
UV_DEFLECTION = 1e-4
ANGULAR_DEFLECTION = 0.1


@dataclass
class CadModel:
    """The nurbskit objects of a CAD file.

    Attributes:
        faces: one :class:`TrimmedSurface` per face, in the file's order.
        face_types: the surface type of each face as stored (``'BSplineSurface'``,
            ``'Plane'``, ``'CylindricalSurface'``, ...), before conversion.
        curves: free edges (not bounding a face) as NURBS curves.
        reversed: per face, whether the face is reversed (its normal is the opposite of
            the surface's ``S_u x S_v``).
    """

    faces: list[TrimmedSurface] = field(default_factory=list)
    face_types: list[str] = field(default_factory=list)
    curves: list[NURBSCurve] = field(default_factory=list)
    reversed: list[bool] = field(default_factory=list)

    @property
    def surfaces(self):
        return [f.surface for f in self.faces]


# ---- writing: nurbskit -> shapes ----------------------------------------------------------

def _chord_parameters(uv: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(uv, axis=0), axis=1)
    if np.any(seg <= 0):
        raise OptionError("a trimming loop has two equal consecutive (u, v) points")
    return np.concatenate([[0.0], np.cumsum(seg)])


@functools.lru_cache(maxsize=None)
def _bernstein_inverse(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of the Bernstein collocation matrix at ``degree + 1`` Chebyshev-Lobatto nodes."""
    from math import comb

    k = np.arange(degree + 1)
    tau = 0.5 - 0.5 * np.cos(np.pi * k / degree)
    basis = np.array([[comb(degree, j) * t ** j * (1 - t) ** (degree - j) for j in k] for t in tau])
    return tau, np.linalg.inv(basis)


def _homogeneous_net(surface) -> np.ndarray:
    """The surface's control net in homogeneous form ``(x w, y w, z w, w)``: ``(n, m, 4)``."""
    cp = _pad3(surface.control_points.detach().cpu().double()).numpy()
    w = surface.weights.detach().cpu().double().numpy()
    return np.concatenate([cp * w[..., None], w[..., None]], axis=-1)


def _pad3(cp):
    return cp if cp.shape[-1] == 3 else torch.cat([cp, torch.zeros(cp.shape[:-1] + (1,), dtype=cp.dtype)], dim=-1)


def _homogeneous_points(surface, net: np.ndarray, uv: np.ndarray, span_uv: np.ndarray) -> np.ndarray:
    """``S_h(u, v)`` ``(M, 4)`` of the homogeneous surface at ``uv (M, 2)``, each point on the
    knot span of ``span_uv (M, 2)`` (a point of the span it belongs to: a piece's ends on
    a knot line are then evaluated on the piece's own span).

    The tensor-product sum over the ``(p + 1) x (q + 1)`` non-zero basis functions (The
    NURBS Book A3.5), with nurbskit's basis (:func:`nurbskit.core.basis.basis_functions`)
    and the contraction in NumPy: a few dozen array operations per surface, where a
    4-D NURBSSurface's ``evaluate`` spent most of its time setting itself up.
    """
    from ...core.basis import basis_functions
    from ...core.knots import find_spans

    values, index = [], []
    for axis, degree in enumerate(surface.degrees):
        knots = surface.knot_vectors[axis].detach().cpu().double()
        spans = find_spans(knots, degree, net.shape[axis], torch.from_numpy(np.ascontiguousarray(span_uv[:, axis])))
        basis = basis_functions(knots, degree, spans, torch.from_numpy(np.ascontiguousarray(uv[:, axis])))
        values.append(basis.numpy())
        index.append(spans.numpy()[:, None] - degree + np.arange(degree + 1))
    block = net[index[0][:, :, None], index[1][:, None, :]]  # (M, p + 1, q + 1, 4)
    # sum_ij N_i(u) N_j(v) P_ij: the (p + 1)(q + 1) products, then one contraction
    weights = (values[0][:, :, None] * values[1][:, None, :]).reshape(len(uv), -1)
    return np.einsum("mk,mkc->mc", weights, block.reshape(len(uv), -1, block.shape[-1]))


def loop_curve_3d(surface, uv: np.ndarray, params: np.ndarray):
    """The exact 3-D image of a closed (u, v) polyline on ``surface``, as a rational B-spline.

    Along a straight (u, v) segment inside one knot span, ``S(u(t), v(t))`` in homogeneous
    coordinates is a polynomial of degree ``p + q`` in ``t``: each segment is split where
    it crosses a knot line, each piece interpolated at ``p + q + 1`` Chebyshev-Lobatto
    nodes in the Bernstein basis (exact up to rounding), and the pieces joined with C0
    knots. Its parameter is the polyline's (``params``, cumulative chord length), so the
    curve and the (u, v) polyline are the same curve on the surface.

    Args:
        uv: ``(L + 1, 2)`` the loop with its first point repeated at the end.
        params: ``(L + 1,)`` increasing.

    Returns:
        ``(poles (M, 3), weights (M,) or None, flat knots, degree)``.
    """
    return loop_curves_3d(surface, [(uv, params)])[0]


def loop_curves_3d(surface, loops: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple]:
    """:func:`loop_curve_3d` for several ``(uv, params)`` loops on one surface, with one
    evaluation of the surface for all of them (the evaluation's set-up dominates for
    loops of a few dozen points)."""
    d = sum(surface.degrees)
    out = []
    rational = bool(surface.is_rational)
    for s_start, s_end, coeff in _exact_pieces(surface, loops):
        poles_h = np.concatenate([coeff[:1, 0], coeff[:, 1:].reshape(-1, 4)])
        weights = poles_h[:, 3]
        if np.any(weights <= 0):  # pragma: no cover - positive weights give positive Bernstein coefficients
            raise NurbskitError("a trimming loop's 3-D curve has non-positive weights")
        poles = poles_h[:, :3] / weights[:, None]
        flat = np.concatenate([[s_start[0]] * (d + 1), np.repeat(s_start[1:], d), [s_end[-1]] * (d + 1)])
        out.append((poles, (weights if rational else None), flat, d))
    return out


def _exact_pieces(surface, loops: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple]:
    """The exact image of each closed (u, v) polyline on ``surface``, piece by piece:
    per loop ``(s_start (P,), s_end (P,), coeff (P, p + q + 1, 4))``, the homogeneous
    Bernstein coefficients of each piece (between the polyline's points and its crossings
    of the knot lines; see :func:`loop_curve_3d`), neighbouring pieces sharing their end
    coefficient."""
    (p, q) = surface.degrees
    d = p + q
    (u0, u1), (v0, v1) = surface.domain
    inner = []  # distinct knots inside the domain, per direction
    for kv, lo, hi in ((surface.knot_vectors[0], u0, u1), (surface.knot_vectors[1], v0, v1)):
        k = np.unique(kv.detach().cpu().double().numpy())
        inner.append(k[(k > lo) & (k < hi)])
    tau, inverse = _bernstein_inverse(d)
    pieces, all_nodes, all_mids = [], [], []
    for uv, params in loops:
        starts, ends, s_start, s_end = _loop_pieces(uv, params, inner)
        nodes = starts[:, None, :] + tau[None, :, None] * (ends - starts)[:, None, :]  # (P, d + 1, 2)
        nodes[:, 0], nodes[:, -1] = starts, ends
        pieces.append((s_start, s_end))
        all_nodes.append(nodes.reshape(-1, 2))
        all_mids.append(np.repeat(0.5 * (starts + ends), d + 1, axis=0))  # the piece's knot span
    h_all = _homogeneous_points(surface, _homogeneous_net(surface), np.vstack(all_nodes), np.vstack(all_mids))
    out, offset = [], 0
    for (s_start, s_end), nodes in zip(pieces, all_nodes):
        h = h_all[offset:offset + len(nodes)].reshape(-1, d + 1, 4)
        offset += len(nodes)
        coeff = np.einsum("jk,pkc->pjc", inverse, h)
        coeff[:, 0], coeff[:, -1] = h[:, 0], h[:, -1]  # the ends interpolate exactly
        coeff[1:, 0] = coeff[:-1, -1]  # neighbouring pieces share their end pole
        out.append((s_start, s_end, coeff))
    return out


#: degree of the approximated 3-D trimming curves (:func:`approximate_loop_curves_3d`);
#: cubic: 151 poles per loop of the benchmark's patches at 1e-5 against 193 for degree 4
#: (a segment between two of the loop's points needs ``degree`` poles however loose the
#: tolerance), 243 against 220 at 1e-6
APPROX_DEGREE = 3
#: an approximated piece is accepted when its largest deviation at its check points is
#: within this fraction of the edge's tolerance (the rest is margin for the deviation
#: between check points; tests/test_io_cad.py measures it densely)
APPROX_MARGIN = 0.5
#: a piece is halved at most this many times; past that the surface's loops get the
#: exact curves (:func:`loop_curves_3d`)
APPROX_MAX_HALVINGS = 10


def approximate_loop_curves_3d(surface, loops: list[tuple[np.ndarray, np.ndarray]], tolerance: float) -> list[tuple]:
    """3-D images of closed (u, v) polylines on ``surface`` as polynomial (non-rational)
    B-splines of degree :data:`APPROX_DEGREE` within ``tolerance`` (model units) of the
    exact image ``S(u(t), v(t))``: :func:`approximate_trim_curves` for one surface.

    Args:
        loops: ``(uv (L + 1, 2), params (L + 1,))`` per loop, as :func:`loop_curves_3d`.
        tolerance: the largest deviation allowed, model units.

    Returns:
        Per loop ``(poles (M, 3), None, flat knots, degree)``, or the exact curves of
        :func:`loop_curves_3d` (see :func:`approximate_trim_curves`).
    """
    return approximate_trim_curves([(surface, loops, tolerance)])[0]


def approximate_trim_curves(jobs: list[tuple]) -> list[list[tuple]]:
    """The 3-D curves of the trimming loops of many surfaces at once: per job
    ``(surface, loops, tolerance)`` the curves of :func:`approximate_loop_curves_3d`.

    Why approximate: the exact image (:func:`loop_curves_3d`) is rational of degree
    ``p + q`` with ``p + q`` poles per piece; for bicubic patches it was three quarters of
    a STEP file, and writing, reading back and checking it most of the time of
    ``write_cad``. CAD systems keep a 3-D edge curve within the edge's tolerance of the
    curve on the surface (the pcurve, which stays the exact trim); ``face_of`` gives the
    edge that tolerance, and ``BRepCheck_Analyzer`` (the check after writing) verifies it.

    Method: only the loop's points are corners of the image: across a knot line of a C1
    (or smoother) surface it stays C1. So each segment of the polyline (cut only where it
    crosses a knot line of multiplicity >= the degree, a possible crease) is interpolated
    at ``APPROX_DEGREE + 1`` Chebyshev-Lobatto nodes in the Bernstein basis (the ends
    exactly), its deviation from the surface measured half-way between the nodes (where
    an interpolant strays most) and at the quarter points, and a sub-piece deviating more
    than ``APPROX_MARGIN * tolerance`` is halved and tried again. Sub-pieces join with C0
    knots; the parameter is the polyline's (``params``), so the 3-D curve and the pcurve
    are the same curve on the surface within ``tolerance``. Each round evaluates the
    surfaces at every node and check point of every surface of the same degrees and
    control-grid size in one batch (nurbskit's basis functions with one knot vector per
    surface, then one contraction with the homogeneous control nets): building the
    faces of 100 patches spent most of its time in per-surface NumPy calls before.
    Starting from the segments rather than the exact Bezier pieces (between the points
    and every knot-line crossing) gave, at degree 4, 220 instead of 282 poles per loop on
    benchmarks/bench_cad.py's patches at 1e-6 of their diagonal (312 against 326 at 1e-7).

    Returns:
        Per job, per loop ``(poles (M, 3), None, flat knots, degree)``; the exact curves
        of :func:`loop_curves_3d` where the exact image is already polynomial of degree
        ``<= APPROX_DEGREE`` (a non-rational surface with ``p + q`` that low), where the
        approximation needs more poles than the exact curves (a strongly curved surface
        with few knots), or where a piece still deviates after ``APPROX_MAX_HALVINGS``
        halvings.
    """
    k = APPROX_DEGREE
    out: list = [None] * len(jobs)
    groups: dict = {}
    for index, (surface, loops, _) in enumerate(jobs):
        if sum(surface.degrees) <= k and not surface.is_rational:
            out[index] = loop_curves_3d(surface, loops)
        else:
            groups.setdefault((tuple(surface.degrees), tuple(surface.sizes)), []).append(index)
    for members in groups.values():
        for index, curves in zip(members, _approximate_group([jobs[i] for i in members])):
            out[index] = curves if curves is not None else loop_curves_3d(jobs[index][0], jobs[index][1])
    return out


def _approximate_group(jobs: list[tuple]) -> list:
    """:func:`approximate_trim_curves` for surfaces of the same degrees and control-grid
    size (one batched evaluation per round); None for a job that falls back to the exact
    curves."""
    k = APPROX_DEGREE
    tau, inverse = _bernstein_inverse(k)
    checks = np.unique(np.concatenate([0.5 * (tau[1:] + tau[:-1]), [0.25, 0.75]]))
    local = np.concatenate([tau, checks])  # where a sub-piece is evaluated, in [0, 1]
    check_basis = _bernstein_matrix(k, checks)  # (C, k + 1)
    evaluate = _BatchEvaluator([surface for surface, _, _ in jobs])
    d = sum(jobs[0][0].degrees)
    # the first sub-pieces ("bases"): the polyline's segments, cut where they cross a crease
    face, loop, p0, p1, s0, s1, exact_poles = [], [], [], [], [], [], []
    for f, (surface, loops, _) in enumerate(jobs):
        corners = _crease_knots(surface)
        knots = [np.unique(kv.detach().cpu().double().numpy()) for kv in surface.knot_vectors]
        count = 0
        for i, (uv, params) in enumerate(loops):
            if len(corners[0]) or len(corners[1]):
                a, b, sa, sb = _loop_pieces(uv, params, corners)
            else:
                a, b, sa, sb = uv[:-1], uv[1:], params[:-1], params[1:]
            face.append(np.full(len(a), f))
            loop.append(np.full(len(a), i))
            p0.append(a), p1.append(b), s0.append(sa), s1.append(sb)
            # the exact curves' pieces: a segment's crossings of the knot lines, counted
            crossings = sum(np.abs(np.searchsorted(kv, uv[1:, axis]) - np.searchsorted(kv, uv[:-1, axis])).sum()
                            for axis, kv in enumerate(knots))
            count += (len(uv) - 1 + crossings) * d
        exact_poles.append(count)
    face, loop = np.concatenate(face), np.concatenate(loop)
    p0, p1, s0, s1 = (np.concatenate(x) for x in (p0, p1, s0, s1))
    base = np.arange(len(face))  # the base a sub-piece lies on
    lo, hi = s0.copy(), s1.copy()
    tolerance = np.array([t for _, _, t in jobs])
    done = []  # accepted sub-pieces: (base, s_start, s_end, poles (P, k + 1, 3))
    for _ in range(APPROX_MAX_HALVINGS + 1):
        s = lo[:, None] + local[None, :] * (hi - lo)[:, None]  # (m, n)
        s[:, 0], s[:, k] = lo, hi  # the ends exactly
        f = (s - s0[base, None]) / (s1 - s0)[base, None]  # along the base: 0 and 1 at its ends exactly
        uv = (1 - f)[..., None] * p0[base, None] + f[..., None] * p1[base, None]
        xyz = evaluate(np.repeat(face[base], len(local)), uv.reshape(-1, 2)).reshape(len(base), len(local), 3)
        poles = inverse @ xyz[:, :k + 1]  # (m, k + 1, 3)
        poles[:, 0], poles[:, -1] = xyz[:, 0], xyz[:, k]  # the ends interpolate exactly
        error = np.linalg.norm(check_basis @ poles - xyz[:, k + 1:], axis=-1).max(axis=1)
        good = error <= APPROX_MARGIN * tolerance[face[base]]
        done.append((base[good], lo[good], hi[good], poles[good]))
        bad = ~good
        if not bad.any():
            break
        mid = 0.5 * (lo[bad] + hi[bad])
        base = np.concatenate([base[bad], base[bad]])
        lo, hi = np.concatenate([lo[bad], mid]), np.concatenate([mid, hi[bad]])
    failed = set(face[base].tolist()) if bad.any() else set()  # pieces the approximation does not reach
    base, s_lo, s_hi, poles = (np.concatenate(parts) for parts in zip(*done))
    order = np.lexsort((s_lo, loop[base], face[base]))
    base, s_lo, s_hi, poles = base[order], s_lo[order], s_hi[order], poles[order]
    sub_face, sub_loop = face[base], loop[base]
    bounds = np.searchsorted(sub_face, np.arange(len(jobs) + 1))
    out = []
    for f, (_, loops, _) in enumerate(jobs):
        a, b = bounds[f], bounds[f + 1]
        if f in failed or (b - a) * k > exact_poles[f]:  # more poles than the exact curves (weights aside)
            out.append(None)
            continue
        curves = []
        cuts = a + np.searchsorted(sub_loop[a:b], np.arange(len(loops) + 1))
        for i in range(len(loops)):
            starts, ends, own = s_lo[cuts[i]:cuts[i + 1]], s_hi[cuts[i]:cuts[i + 1]], poles[cuts[i]:cuts[i + 1]]
            # each sub-piece's poles but its last (the next one's first); closed: the first again
            merged = np.concatenate([own[:, :-1].reshape(-1, 3), own[0, :1]])
            flat = np.concatenate([[starts[0]] * (k + 1), np.repeat(starts[1:], k), [ends[-1]] * (k + 1)])
            curves.append((merged, None, flat, k))
        out.append(curves)
    return out


class _BatchEvaluator:
    """Points of several surfaces of the same degrees and control-grid size: called with
    ``face (N,)`` (which surface) and ``uv (N, 2)``, returns ``S_face(uv) (N, 3)``.

    The non-zero basis functions (The NURBS Book A2.2) come from nurbskit's
    :func:`~nurbskit.core.basis.basis_functions`: with the one knot vector of a direction
    where every surface has the same (patches of one fit usually do), else with one knot
    vector per surface (the points padded to the same count per surface); the sum over
    the ``(p + 1) x (q + 1)`` control points (A3.5 for the homogeneous net, then the
    division by the weight) from one gather and one contraction in NumPy."""

    def __init__(self, surfaces):
        self.degrees = tuple(surfaces[0].degrees)
        self.sizes = tuple(surfaces[0].sizes)
        self.knots = []  # per direction (m,) shared or (F, m)
        for axis in (0, 1):
            knots = torch.stack([s.knot_vectors[axis].detach().cpu().double() for s in surfaces])
            self.knots.append(knots[0] if bool((knots == knots[:1]).all()) else knots)
        self.count = len(surfaces)
        self.net = np.stack([_homogeneous_net(s) for s in surfaces]).reshape(-1, 4)  # (F * nu * nv, 4)

    def __call__(self, face: np.ndarray, uv: np.ndarray) -> np.ndarray:
        from ...core.basis import basis_functions
        from ...core.knots import find_spans

        slot = width = None
        index, values = [], []
        for axis, (degree, size) in enumerate(zip(self.degrees, self.sizes)):
            knots = self.knots[axis]
            if knots.ndim == 1:  # one knot vector for all
                u = torch.from_numpy(np.ascontiguousarray(uv[:, axis]))
                spans = find_spans(knots, degree, size, u)
                values.append(basis_functions(knots, degree, spans, u).numpy())  # (N, p + 1)
                index.append(spans.numpy()[:, None] - degree + np.arange(degree + 1))
                continue
            if slot is None:  # each point's place in its surface's row of the padded (F, width) layout
                per_face = np.bincount(face, minlength=self.count)
                rank = np.empty(len(face), dtype=np.int64)
                rank[np.argsort(face, kind="stable")] = (np.arange(len(face))
                                                         - np.repeat(np.cumsum(per_face) - per_face, per_face))
                width = int(per_face.max())
                slot = face * width + rank
            padded = knots[:, degree:degree + 1].numpy().repeat(width, axis=1)  # the domain's start
            padded.reshape(-1)[slot] = uv[:, axis]
            u = torch.from_numpy(padded)
            spans = find_spans(knots, degree, size, u)
            basis = basis_functions(knots, degree, spans, u)  # (F, width, p + 1)
            values.append(np.take(basis.numpy().reshape(-1, degree + 1), slot, axis=0))
            index.append(np.take(spans.numpy().reshape(-1), slot)[:, None] - degree + np.arange(degree + 1))
        nu, nv = self.sizes
        flat = (face[:, None, None] * (nu * nv) + index[0][:, :, None] * nv + index[1][:, None, :])
        block = np.take(self.net, flat, axis=0)  # (N, p + 1, q + 1, 4); take: 4x faster than [flat]
        weights = values[0][:, :, None] * values[1][:, None, :]
        h = np.matmul(weights.reshape(len(face), 1, -1), block.reshape(len(face), -1, 4))[:, 0]  # (N, 4)
        return h[:, :3] / h[:, 3:]


def _crease_knots(surface) -> list[np.ndarray]:
    """Per direction, the distinct knots inside the domain where the surface is only C0
    (multiplicity >= the degree)."""
    out = []
    for kv, degree, (lo, hi) in zip(surface.knot_vectors, surface.degrees, surface.domain):
        values, counts = np.unique(kv.detach().cpu().double().numpy(), return_counts=True)
        out.append(values[(counts >= degree) & (values > lo) & (values < hi)])
    return out


def _bernstein_matrix(degree: int, t: np.ndarray) -> np.ndarray:
    """Bernstein polynomials of ``degree`` at ``t (*,)``: ``(*, degree + 1)``."""
    from math import comb

    binomial = np.array([comb(degree, i) for i in range(degree + 1)], dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    # powers by running products (exact for 0 and 1, and far cheaper than ``**``)
    ones = np.ones(t.shape)
    up = np.cumprod(np.concatenate([ones] + [t] * degree, axis=-1), axis=-1)  # t^j
    down = np.cumprod(np.concatenate([ones] + [1 - t] * degree, axis=-1), axis=-1)[..., ::-1]  # (1 - t)^(d - j)
    return binomial * up * down


def _loop_pieces(uv: np.ndarray, params: np.ndarray, inner: list[np.ndarray]):
    """The pieces of a closed (u, v) polyline between its points and its crossings of the
    knot lines ``inner`` (u knots, v knots): start and end points ``(P, 2)`` and
    parameters ``(P,)``."""
    a, b = uv[:-1], uv[1:]
    length = params[1:] - params[:-1]  # chord length of each segment
    eps = 1e-12 * params[-1]
    seg = [np.arange(len(a)), np.arange(len(a))]
    cut = [np.zeros(len(a)), np.ones(len(a))]
    for axis in (0, 1):
        delta = b[:, axis] - a[:, axis]
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = (inner[axis][None, :] - a[:, axis, None]) / delta[:, None]  # (S, K)
        ok = (delta[:, None] != 0) & (tau * length[:, None] > eps) & ((1 - tau) * length[:, None] > eps)
        rows, _ = np.nonzero(ok)
        seg.append(rows)
        cut.append(tau[ok])
    seg, cut = np.concatenate(seg), np.concatenate(cut)
    order = np.lexsort((cut, seg))
    seg, cut = seg[order], cut[order]
    # a segment crossing a u and a v knot line at (nearly) one point: one break, not two
    close = np.zeros(len(seg), dtype=bool)
    close[1:] = (seg[1:] == seg[:-1]) & ((cut[1:] - cut[:-1]) * length[seg[1:]] <= eps) & (cut[1:] < 1)
    seg, cut = seg[~close], cut[~close]
    pts = a[seg] + cut[:, None] * (b - a)[seg]
    s = params[seg] + cut * length[seg]
    end = cut == 1  # segment ends exactly at the polyline's points
    pts[end], s[end] = b[seg[end]], params[seg[end] + 1]
    first = np.flatnonzero(seg[:-1] == seg[1:])  # pieces: consecutive breaks of one segment
    return pts[first], pts[first + 1], s[first], s[first + 1]


#: (u, v) segments per edge of a trimming loop; 0: one closed edge per loop. Why not one
#: edge per loop: OCC intersects pcurves (BRepCheck_Face::IntersectWires in the check,
#: ShapeFix's self-intersection tests when a file is read with healing) interval by
#: interval, and a degree-1 pcurve has one C0 interval per segment, so a 64-segment loop
#: against a 32-segment hole is 2048 interval pairs; short edges are first sorted out by
#: their 2-D boxes. Why not one edge per segment: the file's per-edge entities dominate.
#: Measured on benchmarks/bench_cad.py's patches (100, loops of 64 + 32 points; CPU
#: seconds, STEP written = shape + write + read back + BRepCheck, the check without
#: healing; two runs under load 6 to 11): 0 -> 4.4 / 3.9 s, 4 -> 4.5 / 4.3 s, 8 -> 4.0 /
#: 4.3 s (14.6, 17.0, 15.7 MB): within the noise of each other; 8 for half the edges of 4
#: and a smaller file. With healing on reading, earlier: 0 -> 4.1, 1 -> 6.1, 4 -> 3.6 s.
#: results/cad.md has the latest ablation.
EDGE_SEGMENTS = 8


def _bspline_curve_3d(poles, weights, flat, degree):
    """A ``Geom_BSplineCurve`` from poles ``(M, 3)``, optional weights ``(M,)`` and a flat knot vector."""
    from OCP.collections import Array1_gp_Pnt
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt

    from .occ import _array1, knots_and_multiplicities

    knots, mults = knots_and_multiplicities(flat)
    arr = Array1_gp_Pnt(1, len(poles))
    set_pole = arr.SetValue  # hot: hundreds of poles per loop
    for i, xyz in enumerate(poles.tolist(), 1):
        set_pole(i, gp_Pnt(*xyz))
    if weights is None:
        return Geom_BSplineCurve(arr, _array1(knots, "float"), _array1(mults, "int"), degree, False)
    return Geom_BSplineCurve(arr, _array1(weights, "float"), _array1(knots, "float"), _array1(mults, "int"),
                             degree, False)


def _loop_wire(uv: np.ndarray, t: np.ndarray, curve_3d: tuple, surface_geom, tolerance: float,
               segments: int | None = None):
    """A closed wire on ``surface_geom`` along a closed (u, v) polyline ``uv (L + 1, 2)``
    with chord parameters ``t (L + 1,)`` and its exact 3-D image ``curve_3d`` (the tuple of
    :func:`loop_curve_3d`).

    The loop is cut into edges of ``segments`` polyline segments (default
    ``EDGE_SEGMENTS``; 0: one closed edge), each with its piece of the polyline as pcurve
    (degree 1) and its piece of the 3-D curve (``Segment`` of OCC's curve), sharing
    vertices with its neighbours.
    """
    ocp()
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeVertex
    from OCP.collections import Array1_gp_Pnt2d
    from OCP.Geom2d import Geom2d_BSplineCurve
    from OCP.gp import gp_Pnt2d
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS_Wire

    from .occ import _array1

    segments = EDGE_SEGMENTS if segments is None else segments
    count = len(uv) - 1
    curve = _bspline_curve_3d(*curve_3d)
    # the whole loop as a degree-1 B-spline (exact: its poles are the points, its knots
    # the chord parameters); an edge's pcurve is its Segment between two of its knots
    poles2d = Array1_gp_Pnt2d(1, count + 1)
    set_pole = poles2d.SetValue
    for i, uv_i in enumerate(uv.tolist(), 1):
        set_pole(i, gp_Pnt2d(*uv_i))
    mult = np.ones(count + 1, dtype=int)
    mult[0] = mult[-1] = 2
    loop2d = Geom2d_BSplineCurve(poles2d, _array1(t, "float"), _array1(mult, "int"), 1, False)
    pieces = max(1, round(count / segments)) if segments else 1
    cuts = np.unique(np.linspace(0, count, pieces + 1).round().astype(int))
    builder = BRep_Builder()
    wire = TopoDS_Wire()
    builder.MakeWire(wire)
    location = TopLoc_Location()
    if len(cuts) == 2:  # one closed edge: OCC makes its one vertex
        ranges, vertices = [None], None
    else:
        # the curve passes exactly through its C0 poles at the polyline's points
        vertices = [BRepBuilderAPI_MakeVertex(curve.Value(float(t[c]))).Vertex() for c in cuts[:-1]]
        vertices.append(vertices[0])
        ranges = list(zip(t[cuts[:-1]].tolist(), t[cuts[1:]].tolist()))
    for k, piece in enumerate(ranges):
        if piece is None:
            maker, pc = BRepBuilderAPI_MakeEdge(curve), loop2d
        else:
            a, b = piece
            c3, pc = curve.Copy(), loop2d.Copy()
            c3.Segment(a, b)  # at the curves' knots: the same poles
            pc.Segment(a, b)
            maker = BRepBuilderAPI_MakeEdge(c3, vertices[k], vertices[k + 1], a, b)
        if not maker.IsDone():
            raise NurbskitError(f"OpenCASCADE could not make an edge of a trimming loop (error {maker.Error()})")
        edge = maker.Edge()
        builder.UpdateEdge(edge, pc, surface_geom, location, tolerance)
        builder.SameParameter(edge, True)
        builder.SameRange(edge, True)
        builder.Add(wire, edge)
    wire.Closed(True)
    return wire


def face_of(obj, tolerance: float = TOLERANCE, *, prepared: tuple | None = None):
    """A ``TopoDS_Face`` for a NURBSSurface (natural bounds) or a TrimmedSurface (its loops).

    ``prepared``: ``(closed loops, their parameters, edge tolerance, 3-D curves)`` of a
    TrimmedSurface, as ``to_shape`` computes them for all its surfaces at once
    (:func:`_trim_job`, :func:`approximate_trim_curves`); default: computed here."""
    ocp()
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    trimmed = obj if isinstance(obj, TrimmedSurface) else TrimmedSurface(obj, [])
    geom = surface_to_occ(trimmed.surface)
    if not trimmed.loops:
        maker = BRepBuilderAPI_MakeFace(geom, tolerance)
        if not maker.IsDone():
            raise NurbskitError(f"OpenCASCADE could not make a face from this surface (error {maker.Error()})")
        return maker.Face()
    if prepared is None:
        closed, params, edge_tolerance = _trim_job(trimmed, tolerance)
        curves = _trim_curves([(trimmed.surface, list(zip(closed, params)), edge_tolerance)])[0]
    else:
        closed, params, edge_tolerance, curves = prepared
    wires = [_loop_wire(uv, t, c, geom, edge_tolerance) for uv, t, c in zip(closed, params, curves)]
    outer = wires[0] if trimmed.outer is not None else None
    if outer is None:  # holes only: the natural boundary is the outer loop
        maker = BRepBuilderAPI_MakeFace(BRepBuilderAPI_MakeFace(geom, tolerance).Face())
        for w in wires:
            maker.Add(w)
    else:
        maker = BRepBuilderAPI_MakeFace(geom, outer, True)
        for w in wires[1:]:
            maker.Add(w)
    if not maker.IsDone():
        raise NurbskitError(f"OpenCASCADE could not make a trimmed face (error {maker.Error()})")
    # no ShapeFix_Face::FixOrientation: TrimLoop orients outer loops counter-clockwise and
    # holes clockwise, which is what OCC expects, and the check after writing (its
    # BRepCheck_Face::OrientationOfWires) refuses a file where that went wrong
    return maker.Face()


def _trim_job(trimmed: TrimmedSurface, tolerance: float) -> tuple[list, list, float]:
    """A trimmed surface's loops closed (the first point again at the end) ``(L + 1, 2)``,
    their chord parameters, and its edges' tolerance; a loop outside the domain is an
    OptionError."""
    (u0, u1), (v0, v1) = trimmed.surface.domain
    for loop in trimmed.loops:
        lo, hi = loop.uv.min(axis=0), loop.uv.max(axis=0)
        slack = 1e-9 * max(u1 - u0, v1 - v0)
        if lo[0] < u0 - slack or hi[0] > u1 + slack or lo[1] < v0 - slack or hi[1] > v1 + slack:
            raise OptionError(f"a trimming loop leaves the surface's domain [{u0}, {u1}] x [{v0}, {v1}] "
                              f"(loop bounds {lo.tolist()} to {hi.tolist()})")
    closed = [np.vstack([loop.uv, loop.uv[:1]]) for loop in trimmed.loops]
    params = [_chord_parameters(uv) for uv in closed]
    return closed, params, edge_tolerance(trimmed.surface, tolerance)


def edge_tolerance(surface, tolerance: float = TOLERANCE) -> float:
    """The tolerance of a trimming edge on ``surface`` (model units): ``CURVE_TOLERANCE``
    of its size (the diagonal of its control points, at least 1), within
    ``[tolerance, CURVE_TOLERANCE_MAX]``."""
    return max(tolerance, min(CURVE_TOLERANCE * max(_surface_size(surface), 1.0), CURVE_TOLERANCE_MAX))


def _trim_curves(jobs: list[tuple]) -> list[list[tuple]]:
    """The loops' 3-D curves for ``(surface, loops, edge tolerance)`` jobs: approximated
    (:func:`approximate_trim_curves`), or exact with ``EXACT_CURVES``."""
    if EXACT_CURVES:
        return [loop_curves_3d(surface, loops) for surface, loops, _ in jobs]
    return approximate_trim_curves(jobs)


def _surface_size(surface) -> float:
    cp = surface.control_points.detach().cpu().double().numpy().reshape(-1, surface.dim)
    return float(np.linalg.norm(cp.max(axis=0) - cp.min(axis=0)))


def edge_of(curve: NURBSCurve):
    """A ``TopoDS_Edge`` on the curve's 3-D B-spline over its whole domain."""
    ocp()
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge

    maker = BRepBuilderAPI_MakeEdge(curve_to_occ(curve))
    if not maker.IsDone():
        raise NurbskitError(f"OpenCASCADE could not make an edge from this curve (error {maker.Error()})")
    return maker.Edge()


def mesh_solid(vertices, faces, tolerance: float = TOLERANCE):
    """A triangle mesh as a solid bounded by planar triangular faces sharing edges.

    The mesh's vertices become shared ``TopoDS_Vertex`` objects and each undirected mesh
    edge one shared ``TopoDS_Edge``, so the faces are connected (no sewing needed). A
    closed, consistently oriented mesh (as ``nurbskit volume`` writes) gives a valid
    solid; an open one gives a shell. A mesh of several closed pieces (triangles connected
    through shared vertices) gives a compound of one solid per piece.

    Args:
        vertices: ``(V, 3)``.
        faces: ``(F, 3)`` vertex indices, counter-clockwise seen from outside.
    """
    ocp()
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeVertex
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt
    from OCP.TopoDS import TopoDS_Shell, TopoDS_Solid, TopoDS_Wire

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise OptionError(f"a mesh needs vertices (V, 3) and triangles (F, 3); got {v.shape} and {f.shape}")
    if len(f) == 0:
        raise OptionError("the mesh has no triangles; nothing to write")
    if f.min() < 0 or f.max() >= len(v):
        raise OptionError(f"mesh faces index vertices 0..{len(v) - 1}, found {f.min()}..{f.max()}")
    area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    f = f[area2 > 0]  # degenerate triangles have no plane
    if len(f) == 0:
        raise OptionError("every triangle of the mesh has zero area; nothing to write")
    pieces = _mesh_pieces(len(v), f)
    if 1 < len(pieces) and all(_closed(f[piece]) for piece in pieces):
        # closed pieces apart (two boxes): a solid per piece, in a compound (one shell of
        # them failed the check); open meshes and triangle soups stay one shell
        from OCP.TopoDS import TopoDS_Compound

        builder = BRep_Builder()
        compound = TopoDS_Compound()
        builder.MakeCompound(compound)
        for piece in pieces:
            builder.Add(compound, mesh_solid(v, f[piece], tolerance))
        return compound
    used = np.unique(f)
    occ_vertices = {int(i): BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, v[i]))).Vertex() for i in used}
    edges = {}

    def edge(a, b):
        key = (a, b) if a < b else (b, a)
        e = edges.get(key)
        if e is None:
            e = BRepBuilderAPI_MakeEdge(occ_vertices[key[0]], occ_vertices[key[1]]).Edge()
            edges[key] = e
        return e if key == (a, b) else e.Reversed()

    builder = BRep_Builder()
    shell = TopoDS_Shell()
    builder.MakeShell(shell)
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    for (a, b, c), normal in zip(f.tolist(), normals.tolist()):
        wire = TopoDS_Wire()
        builder.MakeWire(wire)
        for x, y in ((a, b), (b, c), (c, a)):
            builder.Add(wire, edge(x, y))
        # the plane's normal is the triangle's (counter-clockwise) normal: every face forward, outward
        plane = gp_Pln(gp_Pnt(*map(float, v[a])), gp_Dir(*normal))
        face = BRepBuilderAPI_MakeFace(plane, wire, True).Face()
        builder.Add(shell, face)
    closed = _closed(f)
    shell.Closed(closed)
    if not closed:
        return shell
    solid = TopoDS_Solid()
    builder.MakeSolid(solid)
    builder.Add(solid, shell)
    if not BRepCheck_Analyzer(solid).IsValid():
        return shell
    return solid


def _closed(faces: np.ndarray) -> bool:
    """A closed mesh: every edge in exactly two triangles."""
    undirected = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def _mesh_pieces(num_vertices: int, faces: np.ndarray) -> list[np.ndarray]:
    """Indices of the triangles of each connected piece (through shared vertices), in order."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.repeat(np.arange(len(faces)), 3)
    incidence = coo_matrix((np.ones(rows.size), (rows, faces.reshape(-1))), shape=(len(faces), num_vertices)).tocsr()
    count, label = connected_components(incidence @ incidence.T, directed=False)
    order = np.argsort(label, kind="stable")
    return np.split(order, np.cumsum(np.bincount(label, minlength=count))[:-1])


def _is_mesh(obj) -> bool:
    return hasattr(obj, "vertices") and hasattr(obj, "faces") and not isinstance(obj, (TensorSpline, TrimmedSurface))


def to_shape(obj, *, sew_tolerance: float | None = 1e-6, tolerance: float = TOLERANCE, analytic: bool = True,
             solids: bool = True):
    """An OCC shape for a nurbskit object or a list of them.

    NURBSSurface / TrimmedSurface -> face; NURBSCurve -> edge; a mesh (anything with
    ``vertices (V, 3)`` and ``faces (F, 3)``, such as ``nurbskit volume``'s) -> solid;
    :class:`~nurbskit.io.cad.analytic.RevolvedSurface` / ``ExtrudedSurface`` -> a face on
    OCC's surface of revolution / extrusion (``analytic=False``: on their exact NURBS);
    a list -> a compound whose faces are sewn into shells where neighbouring patches
    share edges within ``sew_tolerance`` (``None``: no sewing). With ``solids`` (the
    default), a shell that closes (every edge shared by two faces, or a seam used twice:
    a closed fit, periodic with two poles, on its own) bounds a solid, oriented outward
    (:func:`_solids`).
    """
    from .analytic import is_swept, swept_face

    ocp()
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    items = list(obj) if isinstance(obj, (list, tuple)) and not _is_mesh_tuple(obj) else [obj]
    # the trimming loops' 3-D curves of every trimmed surface at once (one batch per round)
    trimmed = [i for i, item in enumerate(items) if isinstance(item, TrimmedSurface) and item.loops]
    prepared = [_trim_job(items[i], tolerance) for i in trimmed]
    curves = _trim_curves([(items[i].surface, list(zip(closed, params)), edge_tolerance)
                           for i, (closed, params, edge_tolerance) in zip(trimmed, prepared)])
    prepared = {i: (*job, c) for i, job, c in zip(trimmed, prepared, curves)}
    shapes, faces = [], []
    for index, item in enumerate(items):
        if _is_mesh_tuple(item):
            shapes.append(mesh_solid(*item, tolerance=tolerance))
        elif _is_mesh(item):
            shapes.append(mesh_solid(item.vertices, item.faces, tolerance=tolerance))
        elif is_swept(item):
            faces.append(swept_face(item, tolerance) if analytic else face_of(item.to_nurbs(), tolerance))
        elif isinstance(item, TrimmedSurface) or getattr(item, "kind", None) == "surface":
            faces.append(face_of(item, tolerance, prepared=prepared.get(index)))
        elif getattr(item, "kind", None) == "curve":
            shapes.append(edge_of(item))
        elif getattr(item, "kind", None) == "volume":
            raise OptionError("a NURBS volume is a field, not a CAD solid; write its mesh (nurbskit volume's mesh.obj)")
        else:
            raise OptionError(f"cannot write a {type(item).__name__} to a CAD file; expected surfaces, trimmed "
                              "surfaces, curves or a mesh")
    if len(faces) > 1 and sew_tolerance is not None:
        faces = [_sew(faces, sew_tolerance)]
    if solids:
        faces = [_solids(f) for f in faces]
    shapes = faces + shapes
    if len(shapes) == 1:
        return shapes[0]
    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    for s in shapes:
        builder.Add(compound, s)
    return compound


def _is_mesh_tuple(obj) -> bool:
    return (isinstance(obj, tuple) and len(obj) == 2 and all(isinstance(a, np.ndarray) for a in obj)
            and obj[0].ndim == 2 and obj[1].ndim == 2)


def _sew(faces, tolerance: float):
    """Faces sewn where they share edges within ``tolerance``; the others stay free."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing

    sewing = BRepBuilderAPI_Sewing(tolerance)
    for f in faces:
        sewing.Add(f)
    sewing.Perform()
    return sewing.SewedShape()


# ---- checking --------------------------------------------------------------------------

def _solids(shape):
    """``shape`` (a face, a shell, or a compound of shells and faces, as sewing returns)
    with every closed shell, a face on its own included, made a solid; the rest as it is."""
    from OCP.BRep import BRep_Builder
    from OCP.TopAbs import TopAbs_COMPOUND, TopAbs_FACE, TopAbs_SHELL
    from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Iterator, TopoDS_Shell

    kind = shape.ShapeType()
    builder = BRep_Builder()
    if kind == TopAbs_FACE:
        shell = TopoDS_Shell()
        builder.MakeShell(shell)
        builder.Add(shell, shape)
        return _solid_of(shell) or shape
    if kind == TopAbs_SHELL:
        return _solid_of(TopoDS.Shell(shape)) or shape
    if kind != TopAbs_COMPOUND:
        return shape
    out = TopoDS_Compound()
    builder.MakeCompound(out)
    children = TopoDS_Iterator(shape)
    while children.More():
        builder.Add(out, _solids(children.Value()))
        children.Next()
    return out


def _solid_of(shell):
    """The solid a closed shell bounds (oriented outward), or None when the shell is open
    or OCC finds no valid solid in it (``BRepLib::OrientClosedSolid`` fails, or
    ``BRepCheck_Analyzer`` refuses the solid: a closed surface that passes through itself,
    such as a random doubly periodic net, stays a face, as before)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeSolid
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepLib import BRepLib

    if not BRep_Tool.IsClosed_s(shell):
        return None
    shell.Closed(True)  # it is: the flag OCC's solid maker reads
    maker = BRepBuilderAPI_MakeSolid(shell)
    if not maker.IsDone():
        return None
    solid = maker.Solid()
    if not BRepLib.OrientClosedSolid_s(solid) or not BRepCheck_Analyzer(solid).IsValid():
        return None
    return solid


def check_shape(shape, *, parallel: bool = True) -> dict:
    """OCC's validity check (``BRepCheck_Analyzer``, with its geometric controls) and
    counts of the shape's parts.

    ``parallel``: the analyzer checks sub-shapes on OCC's thread pool (its
    ``theIsParallel``; the same checks and verdict, in about half the wall time on two
    cores)."""
    ocp()
    from OCP.BRepCheck import BRepCheck_Analyzer

    counts = count_shapes(shape)
    return {"valid": bool(BRepCheck_Analyzer(shape, True, parallel).IsValid()), **counts}


def count_shapes(shape) -> dict:
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
    from OCP.TopExp import TopExp
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as TopTools_IndexedMapOfShape

    out = {}
    for name, kind in (("solids", TopAbs_SOLID), ("shells", TopAbs_SHELL), ("faces", TopAbs_FACE),
                       ("edges", TopAbs_EDGE)):
        m = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, kind, m)
        out[name] = m.Extent()
    return out


# ---- reading: shapes -> nurbskit ------------------------------------------------------------

def _faces(shape):
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        yield TopoDS.Face(exp.Current())
        exp.Next()


def _type_name(geom) -> str:
    name = type(geom).__name__
    return name[5:] if name.startswith("Geom_") else name


def _face_surface(face):
    """(Geom_BSplineSurface, the face it bounds, the original type name) for one face."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.TopoDS import TopoDS

    from OCP.Geom import Geom_RectangularTrimmedSurface

    geom = BRep_Tool.Surface_s(face)  # with the face's location applied
    basis = geom.BasisSurface() if isinstance(geom, Geom_RectangularTrimmedSurface) else geom
    name = _type_name(basis)
    bspline = as_bspline_surface(geom)
    if bspline is not None:
        return bspline, face, name
    converted = TopoDS.Face(BRepBuilderAPI_NurbsConvert(face, True).Shape())
    bspline = as_bspline_surface(BRep_Tool.Surface_s(converted))
    if bspline is None:  # pragma: no cover - NurbsConvert always yields B-splines
        raise NurbskitError(f"OpenCASCADE could not convert a {name} face to a B-spline surface")
    return bspline, converted, name


def _edge_uv(edge, face, deflection: float) -> np.ndarray:
    """The (u, v) polyline of one edge on a face, in the edge's direction in its wire."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.GCPnts import GCPnts_TangentialDeflection
    from OCP.GeomAbs import GeomAbs_BSplineCurve, GeomAbs_Line
    from OCP.TopAbs import TopAbs_REVERSED

    curve = BRepAdaptor_Curve2d(edge, face)
    a, b = curve.FirstParameter(), curve.LastParameter()
    kind = curve.GetType()
    if kind == GeomAbs_Line:
        params = np.array([a, b])
    elif kind == GeomAbs_BSplineCurve and curve.Degree() == 1:
        bs = curve.BSpline()
        knots = np.array([bs.Knot(i) for i in range(1, bs.NbKnots() + 1)])
        params = np.concatenate([[a], knots[(knots > a) & (knots < b)], [b]])
    else:
        sampler = GCPnts_TangentialDeflection(curve, ANGULAR_DEFLECTION, deflection, 3)
        params = np.array([sampler.Parameter(i) for i in range(1, sampler.NbPoints() + 1)])
    pts = np.array([[curve.Value(t).X(), curve.Value(t).Y()] for t in params])
    if edge.Orientation() == TopAbs_REVERSED:
        pts = pts[::-1]
    return pts


def _wire_uv(wire, face, deflection: float) -> np.ndarray:
    from OCP.BRepTools import BRepTools_WireExplorer

    parts = []
    exp = BRepTools_WireExplorer(wire, face)
    while exp.More():
        parts.append(_edge_uv(exp.Current(), face, deflection))
        exp.Next()
    if not parts:
        return np.zeros((0, 2))
    uv = np.vstack([p[:-1] for p in parts])  # each edge ends where the next begins
    # where one edge ends and the next begins OCC's evaluations may differ in the last bit
    tiny = 1e-12 * max(float(np.ptp(uv, axis=0).max()), 1e-300)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(uv, axis=0), axis=1) > tiny])
    uv = uv[keep]
    if len(uv) > 1 and np.linalg.norm(uv[0] - uv[-1]) <= tiny:
        uv = uv[:-1]
    return uv


def face_to_trimmed(face, *, dtype=torch.float64) -> tuple[TrimmedSurface, str]:
    """A face as a TrimmedSurface (see the module docstring) and its original surface type."""
    ocp()
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    geom, face, name = _face_surface(face)
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    deflection = UV_DEFLECTION * max(u1 - u0, v1 - v0, 1e-12)
    outer = BRepTools.OuterWire_s(face)
    found = []
    exp = TopExp_Explorer(face, TopAbs_WIRE)
    while exp.More():
        wire = TopoDS.Wire(exp.Current())
        uv = _wire_uv(wire, face, deflection)
        exp.Next()
        if len(uv) >= 3:
            found.append((uv, "outer" if wire.IsSame(outer) else "hole"))
    geom, found = _seat_periodic(geom, found)
    surface = surface_from_occ(geom, dtype=dtype)
    loops = [TrimLoop(uv, kind) for uv, kind in found]
    loops = [lp for lp in loops if lp.kind == "outer"][:1] + [lp for lp in loops if lp.kind == "hole"]
    loops = _drop_natural_boundary(loops, surface)
    return TrimmedSurface(surface, loops), name


def _seat_periodic(geom, found):
    """Put a face's loops inside one period of a periodic surface.

    A face on a periodic surface (a full cylinder, say) may have pcurves anywhere on the
    periodic parameter line, and a face that goes once around has loops one period wide
    that start away from the surface's first knot. nurbskit holds one period of the
    unwrapped surface, so the loops are shifted by whole periods into it, and where they
    still cross its end the period is re-seated at the loops' start (a knot inserted
    there and made the origin: ``InsertUKnot`` + ``SetUOrigin``, the same geometry).
    """
    if not found or not hasattr(geom, "IsUPeriodic"):
        return geom, found
    for axis in (0, 1):
        periodic = geom.IsUPeriodic() if axis == 0 else geom.IsVPeriodic()
        bounds = geom.Bounds()  # (u1, u2, v1, v2)
        outside = (min(uv[:, axis].min() for uv, _ in found) < bounds[2 * axis] - 1e-9 * (bounds[2 * axis + 1] - bounds[2 * axis])
                   or max(uv[:, axis].max() for uv, _ in found) > bounds[2 * axis + 1] + 1e-9 * (bounds[2 * axis + 1] - bounds[2 * axis]))
        closed = geom.IsUClosed() if axis == 0 else geom.IsVClosed()
        if not periodic and closed and outside:
            # a closed surface (OCC's conversion of a full cylinder, cone, sphere...) whose face
            # goes around past its end: the periodic form is the same surface, continued
            geom = geom.Copy()
            try:
                geom.SetUPeriodic() if axis == 0 else geom.SetVPeriodic()
                periodic = True
            except Exception:  # pragma: no cover - OCC refuses: keep the surface as it is
                pass
        if not periodic:
            continue
        lo, hi = bounds[2 * axis], bounds[2 * axis + 1]
        period = hi - lo
        eps = 1e-9 * period
        start = min(uv[:, axis].min() for uv, _ in found)
        shift = np.floor((start - lo + eps) / period) * period
        if shift:
            for uv, _ in found:
                uv[:, axis] -= shift
            start -= shift
        end = max(uv[:, axis].max() for uv, _ in found)
        if end <= hi + eps:
            continue
        geom = geom.Copy()
        insert, knot, count, origin = ((geom.InsertUKnot, geom.UKnot, geom.NbUKnots, geom.SetUOrigin) if axis == 0
                                       else (geom.InsertVKnot, geom.VKnot, geom.NbVKnots, geom.SetVOrigin))
        insert(float(start), 1, eps, True)
        index = min(range(1, count() + 1), key=lambda i: abs(knot(i) - start))
        origin(index)
    return geom, found


def _drop_natural_boundary(loops: list[TrimLoop], surface) -> list[TrimLoop]:
    """An outer loop that is the domain's rectangle trims nothing: leave it out."""
    if not loops or loops[0].kind != "outer":
        return loops
    (u0, u1), (v0, v1) = surface.domain
    uv = loops[0].uv
    scale = max(u1 - u0, v1 - v0)
    on_edge = (np.isclose(uv[:, 0], u0, rtol=0, atol=1e-9 * scale) | np.isclose(uv[:, 0], u1, rtol=0, atol=1e-9 * scale)
               | np.isclose(uv[:, 1], v0, rtol=0, atol=1e-9 * scale) | np.isclose(uv[:, 1], v1, rtol=0, atol=1e-9 * scale))
    if on_edge.all() and abs(loops[0].area - (u1 - u0) * (v1 - v0)) <= 1e-9 * (u1 - u0) * (v1 - v0):
        return loops[1:]
    return loops


def shape_to_model(shape, *, dtype=torch.float64) -> CadModel:
    """Every face (as TrimmedSurface) and free edge (as NURBSCurve) of a shape."""
    ocp()
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.Geom import Geom_BSplineCurve
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_REVERSED
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    model = CadModel()
    for face in _faces(shape):
        trimmed, name = face_to_trimmed(face, dtype=dtype)
        model.faces.append(trimmed)
        model.face_types.append(name)
        model.reversed.append(face.Orientation() == TopAbs_REVERSED)
    exp = TopExp_Explorer(shape, TopAbs_EDGE, TopAbs_FACE)  # edges outside faces
    while exp.More():
        edge = TopoDS.Edge(exp.Current())
        exp.Next()
        if BRep_Tool.Degenerated_s(edge):
            continue
        geom = BRep_Tool.Curve_s(edge, 0.0, 1.0)
        if geom is None:
            continue
        if not isinstance(geom, Geom_BSplineCurve):
            converted = TopoDS.Edge(BRepBuilderAPI_NurbsConvert(edge, True).Shape())
            geom = BRep_Tool.Curve_s(converted, 0.0, 1.0)
            if not isinstance(geom, Geom_BSplineCurve):
                continue
        model.curves.append(curve_from_occ(geom, dtype=dtype))
    return model


# ---- tessellation -----------------------------------------------------------------------

def tessellate_shape(shape, tolerance: float, angular: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of every face (``BRepMesh_IncrementalMesh``, chordal ``tolerance`` in model
    units): vertices ``(V, 3)`` float64 and faces ``(F, 3)`` int64, oriented outward for
    forward faces (reversed faces are flipped)."""
    ocp()
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location

    if not tolerance > 0:
        raise OptionError(f"the tessellation tolerance must be positive, got {tolerance}")
    BRepMesh_IncrementalMesh(shape, float(tolerance), False, float(angular), True)
    all_v, all_f, offset = [], [], 0
    for face in _faces(shape):
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        if tri is None:
            continue
        trsf = loc.Transformation()
        nodes = np.array([[p.X(), p.Y(), p.Z()] for p in
                          (tri.Node(i).Transformed(trsf) for i in range(1, tri.NbNodes() + 1))])
        tris = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], dtype=np.int64) - 1
        if face.Orientation() == TopAbs_REVERSED:
            tris = tris[:, ::-1]
        all_v.append(nodes)
        all_f.append(tris + offset)
        offset += len(nodes)
    if not all_v:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return np.vstack(all_v), np.vstack(all_f)
