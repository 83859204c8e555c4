"""Knot operations (nurbskit.core.ops) against geomdl and against the geometry itself.

Oracles: geomdl's knot insertion, refinement, degree elevation, splitting and Bezier
decomposition (geomdl normalises knot vectors to [0, 1], so knots are compared after
mapping and control points directly); and the original object evaluated at many
random parameters, domain ends and corners included, which every operation must
reproduce to 1e-10 in float64.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from geomdl import helpers as gh
from geomdl import operations as gops

from _assert import assert_close

from nurbskit.core import NURBSCurve, NURBSSurface, NURBSVolume, from_geomdl, to_geomdl
from nurbskit.core.ops import decompose_bezier, elevate_degree, insert_knot, refine_knots, reverse, split
from nurbskit.errors import NurbskitError

TOL = 1e-10
KINDS = {1: NURBSCurve, 2: NURBSSurface, 3: NURBSVolume}


# ---- random objects --------------------------------------------------------------------

def random_knots(rng, n: int, p: int, domain, clamped: bool = True, repeat: bool = True) -> np.ndarray:
    """Non-uniform knots on ``domain``; one interior knot may repeat up to multiplicity ``p``.

    Unclamped vectors put ``p`` random knots outside the domain at each end.
    """
    a, b = domain
    inner = np.sort(rng.uniform(a, b, n - p - 1))
    if repeat and inner.size >= 2 and p >= 2:
        i = int(rng.integers(0, inner.size - 1))
        inner[i : i + min(p, inner.size - i)] = inner[i]
    if clamped:
        start, end = np.full(p + 1, a), np.full(p + 1, b)
    else:
        start = np.append(np.sort(rng.uniform(a - 1.0, a - 0.1, p)), a)
        end = np.insert(np.sort(rng.uniform(b + 0.1, b + 1.0, p)), 0, b)
    return np.concatenate([start, inner, end])


def random_domain(rng) -> tuple[float, float]:
    a = float(rng.uniform(-3, 3))
    return a, a + float(rng.uniform(0.5, 4.0))


def random_object(rng, degrees, sizes, dim=3, clamped=True, repeat=True, dtype=torch.float64):
    """A random rational curve / surface / volume with non-uniform knots on random domains."""
    kvs = [
        torch.tensor(random_knots(rng, n, p, random_domain(rng), clamped, repeat), dtype=dtype)
        for n, p in zip(sizes, degrees)
    ]
    cp = torch.tensor(rng.normal(size=tuple(sizes) + (dim,)), dtype=dtype)
    w = torch.tensor(rng.uniform(0.3, 2.0, size=tuple(sizes)), dtype=dtype)
    cls = KINDS[len(degrees)]
    if len(degrees) == 1:
        return cls(cp, degrees[0], kvs[0], w)
    return cls(cp, degrees, kvs, w)


def random_params(rng, obj, m: int = 150) -> torch.Tensor:
    """``(M, k)`` parameters in the domain, every corner of the domain included."""
    lo = np.array([d[0] for d in obj.domain])
    hi = np.array([d[1] for d in obj.domain])
    corners = np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), -1).reshape(-1, len(lo))
    pts = np.concatenate([corners, rng.uniform(lo, hi, size=(m, len(lo)))])
    return torch.tensor(pts, dtype=obj.dtype)


def evaluate(obj, params: torch.Tensor) -> torch.Tensor:
    return obj.evaluate(params[:, 0] if obj.para_dim == 1 else params)


def assert_same_geometry(new, old, params, tol=TOL):
    np.testing.assert_allclose(evaluate(new, params).numpy(), evaluate(old, params).numpy(), atol=tol, rtol=0)


def normalised(knots) -> np.ndarray:
    k = np.asarray(knots, dtype=np.float64)
    return (k - k[0]) / (k[-1] - k[0])


def assert_matches_geomdl(ours, g, axis_knots=None):
    """Control points and weights equal; knots equal after normalising to [0, 1]."""
    ref = from_geomdl(g)
    np.testing.assert_allclose(ours.control_points.numpy(), ref.control_points.numpy(), atol=TOL, rtol=0)
    np.testing.assert_allclose(ours.weights.numpy(), ref.weights.numpy(), atol=TOL, rtol=0)
    for mine, theirs in zip(ours.knot_vectors, ref.knot_vectors):
        np.testing.assert_allclose(normalised(mine), theirs.numpy(), atol=TOL, rtol=0)


def interior_knot(rng, obj, axis) -> float:
    """A knot already in the vector (to raise its multiplicity) or a fresh value, at random."""
    kv = obj.knot_vectors[axis].numpy()
    a, b = obj.domain[axis]
    inner = kv[(kv > a) & (kv < b)]
    if inner.size and rng.random() < 0.5:
        return float(rng.choice(inner))
    return float(rng.uniform(a, b))


def mapped(obj, axis, value) -> float:
    kv = obj.knot_vectors[axis]
    return (value - float(kv[0])) / (float(kv[-1]) - float(kv[0]))


# ---- knot insertion (A5.1) ---------------------------------------------------------------

@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_insert_knot_curve_matches_geomdl(degree):
    rng = np.random.default_rng(10 + degree)
    for _ in range(6):
        c = random_object(rng, (degree,), (degree + 1 + int(rng.integers(0, 6)),))
        value = interior_knot(rng, c, 0)
        room = degree - int((c.knot_vector.numpy() == value).sum())
        if room < 1:
            continue
        times = int(rng.integers(1, room + 1))
        ours = insert_knot(c, value, times)
        g = to_geomdl(c)
        gops.insert_knot(g, [mapped(c, 0, value)], [times])
        assert_matches_geomdl(ours, g)
        assert ours.sizes == (c.sizes[0] + times,)
        assert_same_geometry(ours, c, random_params(rng, c))


@pytest.mark.parametrize("degrees", [(1, 2), (2, 3), (3, 3), (4, 1), (5, 2)])
@pytest.mark.parametrize("axis", [0, 1])
def test_insert_knot_surface_matches_geomdl(degrees, axis):
    rng = np.random.default_rng(sum(degrees) * 10 + axis)
    s = random_object(rng, degrees, tuple(p + 1 + int(rng.integers(0, 4)) for p in degrees))
    value = interior_knot(rng, s, axis)
    room = degrees[axis] - int((s.knot_vectors[axis].numpy() == value).sum())
    times = max(1, room)
    if room < 1:
        value = float(np.mean(s.domain[axis]))
    ours = insert_knot(s, value, times, axis=axis)
    g = to_geomdl(s)
    param, num = [None, None], [0, 0]
    param[axis], num[axis] = mapped(s, axis, value), times
    gops.insert_knot(g, param, num)
    assert_matches_geomdl(ours, g)
    assert torch.equal(ours.knot_vectors[1 - axis], s.knot_vectors[1 - axis])
    assert_same_geometry(ours, s, random_params(rng, s))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_insert_knot_volume_matches_geomdl(axis):
    rng = np.random.default_rng(30 + axis)
    v = random_object(rng, (2, 3, 1), (4, 5, 3), dim=3)  # geomdl volumes are 3-D
    value = float(np.mean(v.domain[axis]))
    ours = insert_knot(v, value, 1, axis=axis)
    g = to_geomdl(v)
    param, num = [None] * 3, [0] * 3
    param[axis], num[axis] = mapped(v, axis, value), 1
    gops.insert_knot(g, param, num)
    assert_matches_geomdl(ours, g)
    assert_same_geometry(ours, v, random_params(rng, v, 80))


# ---- knot refinement (A5.4) ------------------------------------------------------------

@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_refine_knots_curve_matches_geomdl(degree):
    """geomdl's A5.4 with a knot list: the list and its midpoints (density 1), each to multiplicity p."""
    rng = np.random.default_rng(40 + degree)
    for _ in range(4):
        c = random_object(rng, (degree,), (degree + 1 + int(rng.integers(0, 6)),))
        kv = c.knot_vector.numpy()
        a, b = c.domain[0]
        # The first span always gets a knot: geomdl 5.4's knot_refinement searches the span
        # of the first new knot among n - 1 control points (an off-by-one) and fails when
        # every new knot lies in the last span.
        first_span = (a + kv[kv > a][0]) / 2
        targets = np.unique(np.concatenate([kv[(kv > a) & (kv < b)], rng.uniform(a, b, 3), [first_span]]))
        dense = np.sort(np.concatenate([targets, (targets[:-1] + targets[1:]) / 2]))
        X = np.repeat(dense, [degree - int((kv == t).sum()) for t in dense])
        ours = refine_knots(c, rng.permutation(X).tolist())
        g = to_geomdl(c)
        cpw, new_kv = gh.knot_refinement(
            degree, list(g.knotvector), g.ctrlptsw, knot_list=[mapped(c, 0, t) for t in targets]
        )
        g.set_ctrlpts(cpw)
        g.knotvector = new_kv
        assert_matches_geomdl(ours, g)
        assert_same_geometry(ours, c, random_params(rng, c))


@pytest.mark.parametrize("axis", [0, 1])
def test_refine_knots_surface_matches_geomdl_density(axis):
    """geomdl's refine_knotvector (density 2): every span cut in four, knots to multiplicity p."""
    rng = np.random.default_rng(50 + axis)
    s = random_object(rng, (3, 2), (6, 5))
    kv = s.knot_vectors[axis].numpy()
    p = s.degrees[axis]
    breaks = np.unique(kv[p:-p])
    for _ in range(2):  # geomdl's density doubling: midpoints of the (unique) breaks
        breaks = np.sort(np.concatenate([breaks, (breaks[:-1] + breaks[1:]) / 2]))
    X = np.repeat(breaks, [max(p - int((kv == t).sum()), 0) for t in breaks])
    ours = refine_knots(s, torch.tensor(X), axis=axis)
    g = to_geomdl(s)
    density = [0, 0]
    density[axis] = 2
    gops.refine_knotvector(g, density)
    assert_matches_geomdl(ours, g)
    assert_same_geometry(ours, s, random_params(rng, s))


def test_refine_equals_repeated_insertion():
    """A5.4 (all at once) and A5.1 (one by one) must agree."""
    rng = np.random.default_rng(60)
    s = random_object(rng, (4, 3), (8, 6))
    a, b = s.domain[1]
    values = [float(rng.uniform(a, b)) for _ in range(3)]
    values += [values[0]]
    once = refine_knots(s, values, axis=1)
    stepwise = s
    for v in values:
        stepwise = insert_knot(stepwise, v, axis=1)
    np.testing.assert_allclose(once.control_points.numpy(), stepwise.control_points.numpy(), atol=TOL, rtol=0)
    np.testing.assert_allclose(once.weights.numpy(), stepwise.weights.numpy(), atol=TOL, rtol=0)
    assert torch.equal(once.knot_vectors[1], stepwise.knot_vectors[1])


# ---- degree elevation (Bezier form) --------------------------------------------------------

def geomdl_elevated_pieces(curve: NURBSCurve, times: int) -> list[np.ndarray]:
    """The oracle: geomdl's Bezier decomposition, then eq. 5.36 on each homogeneous piece.

    (geomdl 5.4's own ``degree_operations`` does not keep the geometry of curves with
    more than one span, so it cannot serve: it re-links the pieces with re-normalised
    knots and removes knots with multiplicities taken from an unordered set.)
    """
    return [
        np.array(gh.degree_elevation(piece.degree, piece.ctrlptsw, num=times))
        for piece in gops.decompose_curve(to_geomdl(curve))
    ]


def assert_elevation_matches_geomdl(elevated: NURBSCurve, original: NURBSCurve, times: int):
    """Both decomposed by geomdl: the Bezier pieces of a spline are unique, so they must agree."""
    ours = [np.array(piece.ctrlptsw) for piece in gops.decompose_curve(to_geomdl(elevated))]
    theirs = geomdl_elevated_pieces(original, times)
    assert len(ours) == len(theirs)
    for mine, ref in zip(ours, theirs):
        np.testing.assert_allclose(mine, ref, atol=TOL, rtol=0)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("times", [1, 2])
def test_elevate_degree_curve_matches_geomdl(degree, times):
    rng = np.random.default_rng(70 + 10 * degree + times)
    for _ in range(3):
        c = random_object(rng, (degree,), (degree + 1 + int(rng.integers(0, 5)),))
        ours = elevate_degree(c, times)
        assert ours.degree == degree + times
        assert_elevation_matches_geomdl(ours, c, times)
        assert_same_geometry(ours, c, random_params(rng, c))


@pytest.mark.parametrize("degrees", [(1, 3), (2, 2), (3, 4), (5, 1)])
@pytest.mark.parametrize("axis", [0, 1])
def test_elevate_degree_surface_matches_geomdl_per_row(degrees, axis):
    """Elevation along ``axis`` acts on each control row along ``axis`` as on a curve."""
    rng = np.random.default_rng(sum(degrees) + 5 * axis)
    s = random_object(rng, degrees, tuple(p + 2 + int(rng.integers(0, 3)) for p in degrees))
    ours = elevate_degree(s, 2, axis=axis)
    assert ours.degrees[axis] == degrees[axis] + 2
    assert ours.degrees[1 - axis] == degrees[1 - axis]
    assert torch.equal(ours.knot_vectors[1 - axis], s.knot_vectors[1 - axis])
    for j in range(s.sizes[1 - axis]):
        pick = (slice(None), j) if axis == 0 else (j, slice(None))
        row = NURBSCurve(s.control_points[pick], degrees[axis], s.knot_vectors[axis], s.weights[pick])
        new_row = NURBSCurve(ours.control_points[pick], degrees[axis] + 2, ours.knot_vectors[axis], ours.weights[pick])
        assert_elevation_matches_geomdl(new_row, row, 2)
    assert_same_geometry(ours, s, random_params(rng, s))


@pytest.mark.parametrize("degree", [5, 7])
def test_elevate_degree_is_exact_next_to_very_short_spans(degree):
    """A span of 1e-6 of the domain at high degree: A5.9's knot removal loses all digits
    here (errors of order 1 at degree 7); the Bezier-form solve must not."""
    rng = np.random.default_rng(degree)
    knots = np.concatenate([[0.0] * (degree + 1), [1e-6, 0.5, 0.5, 1 - 3e-6], [1.0] * (degree + 1)])
    n = knots.size - degree - 1
    c = NURBSCurve(torch.tensor(rng.normal(size=(n, 3))), degree, torch.tensor(knots), torch.tensor(rng.uniform(0.5, 2, n)))
    u = torch.tensor(np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 200), rng.uniform(0, 1e-6, 50), 1 - rng.uniform(0, 3e-6, 50)]))
    for times in (1, 3):
        e = elevate_degree(c, times)
        np.testing.assert_allclose(e.evaluate(u).numpy(), c.evaluate(u).numpy(), atol=TOL, rtol=0)
        assert (e.weights > 0).all()


def test_elevate_degree_raises_every_multiplicity():
    rng = np.random.default_rng(80)
    c = random_object(rng, (3,), (9,))
    e = elevate_degree(c, 2)
    before, counts_before = np.unique(c.knot_vector.numpy(), return_counts=True)
    after, counts_after = np.unique(e.knot_vector.numpy(), return_counts=True)
    np.testing.assert_array_equal(before, after)
    np.testing.assert_array_equal(counts_after, counts_before + 2)
    twice = elevate_degree(elevate_degree(c, 1), 1)
    np.testing.assert_allclose(twice.control_points.numpy(), e.control_points.numpy(), atol=TOL, rtol=0)


# ---- geometry preservation for every kind and every direction ----------------------------

CASES = [
    ((3,), (7,)),
    ((1,), (4,)),
    ((5,), (9,)),
    ((2, 3), (5, 6)),
    ((4, 1), (6, 3)),
    ((2, 1, 3), (4, 3, 5)),
]


@pytest.mark.parametrize("degrees,sizes", CASES)
@pytest.mark.parametrize("clamped", [True, False])
def test_every_operation_keeps_the_geometry(degrees, sizes, clamped):
    rng = np.random.default_rng(sum(degrees) * 100 + sum(sizes) * 10 + clamped)
    obj = random_object(rng, degrees, sizes, clamped=clamped)
    params = random_params(rng, obj, 100)
    for axis, p in enumerate(degrees):
        a, b = obj.domain[axis]
        kv = obj.knot_vectors[axis].numpy()
        value = interior_knot(rng, obj, axis)
        room = p - int((kv == value).sum())
        if room:
            assert_same_geometry(insert_knot(obj, value, room, axis=axis), obj, params)
        assert_same_geometry(refine_knots(obj, rng.uniform(a, b, 5), axis=axis), obj, params)
        for t in (1, 3):
            assert_same_geometry(elevate_degree(obj, t, axis=axis), obj, params)
        if not clamped:  # knots at the domain ends: this clamps the direction
            for end in (a, b):
                r = p - int((kv == end).sum())
                if r:
                    assert_same_geometry(insert_knot(obj, end, r, axis=axis), obj, params)
                    assert_same_geometry(refine_knots(obj, [end] * r, axis=axis), obj, params)
        assert_same_geometry_reversed(obj, axis, params)
        assert_pieces_cover(obj, axis, split(obj, float(rng.uniform(a, b)), axis=axis), rng)
        assert_pieces_cover(obj, axis, decompose_bezier(obj, axis=axis), rng)


def assert_same_geometry_reversed(obj, axis, params):
    a, b = obj.domain[axis]
    r = reverse(obj, axis=axis)
    assert r.domain == obj.domain
    mirrored = params.clone()
    mirrored[:, axis] = (a + b) - mirrored[:, axis]
    mirrored[:, axis] = mirrored[:, axis].clamp(a, b)  # a + b - a may round one ulp past b
    np.testing.assert_allclose(evaluate(r, mirrored).numpy(), evaluate(obj, params).numpy(), atol=TOL, rtol=0)


def assert_pieces_cover(obj, axis, pieces, rng):
    """Each piece reproduces the object on its sub-domain; the sub-domains tile the domain."""
    starts = [piece.domain[axis][0] for piece in pieces]
    ends = [piece.domain[axis][1] for piece in pieces]
    assert starts[0] == obj.domain[axis][0] and ends[-1] == obj.domain[axis][1]
    assert starts[1:] == ends[:-1]
    for piece in pieces:
        assert type(piece) is type(obj)
        assert_same_geometry(piece, obj, random_params(rng, piece, 40))


def test_decompose_bezier_cuts_at_a_break():
    # an interior knot of multiplicity p + 1 (a break: two control points there) is accepted
    # at construction and by split; decompose_bezier refused it
    rng = np.random.default_rng(77)
    knots = torch.tensor([0, 0, 0, 0, 0.2, 0.4, 0.4, 0.4, 0.4, 0.7, 1, 1, 1, 1], dtype=torch.float64)
    c = NURBSCurve(torch.tensor(rng.normal(size=(10, 3))), 3, knots, torch.tensor(rng.uniform(0.5, 2, 10)))
    pieces = decompose_bezier(c)
    assert [piece.domain[0] for piece in pieces] == [(0.0, 0.2), (0.2, 0.4), (0.4, 0.7), (0.7, 1.0)]
    assert all(piece.sizes == (4,) for piece in pieces)
    for piece in pieces:  # inside each piece (at the break the curve has two points, one per side)
        (a, b), = piece.domain
        t = torch.tensor(rng.uniform(a, b, 40))
        assert_close(piece.evaluate(t), c.evaluate(t), atol=1e-12)
    # each side of the break ends at its own control point
    assert_close(pieces[1].evaluate(torch.tensor([0.4], dtype=torch.float64)), c.control_points[4:5], atol=1e-12)
    assert_close(pieces[2].evaluate(torch.tensor([0.4], dtype=torch.float64)), c.control_points[5:6], atol=1e-12)


# ---- splitting, Bezier decomposition, reversal against geomdl ----------------------------

@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_split_curve_matches_geomdl(degree):
    rng = np.random.default_rng(90 + degree)
    c = random_object(rng, (degree,), (degree + 4,))
    value = interior_knot(rng, c, 0)
    first, second = split(c, value)
    g1, g2 = gops.split_curve(to_geomdl(c), mapped(c, 0, value))
    for ours, g in ((first, g1), (second, g2)):
        ref = from_geomdl(g)
        np.testing.assert_allclose(ours.control_points.numpy(), ref.control_points.numpy(), atol=TOL, rtol=0)
        np.testing.assert_allclose(ours.weights.numpy(), ref.weights.numpy(), atol=TOL, rtol=0)
    assert first.domain[0] == (c.domain[0][0], value) and second.domain[0] == (value, c.domain[0][1])
    # Joined at the cut: the last control point of one is the first of the other.
    assert torch.allclose(first.control_points[-1], second.control_points[0], atol=TOL, rtol=0)


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_decompose_bezier_curve_matches_geomdl(degree):
    rng = np.random.default_rng(100 + degree)
    c = random_object(rng, (degree,), (degree + 5,))
    ours = decompose_bezier(c)
    theirs = gops.decompose_curve(to_geomdl(c))
    assert len(ours) == len(theirs) == len(np.unique(c.knot_vector.numpy())) - 1
    for piece, g in zip(ours, theirs):
        ref = from_geomdl(g)
        assert piece.sizes == (degree + 1,)
        np.testing.assert_allclose(piece.control_points.numpy(), ref.control_points.numpy(), atol=TOL, rtol=0)
        np.testing.assert_allclose(piece.weights.numpy(), ref.weights.numpy(), atol=TOL, rtol=0)


def test_decompose_bezier_surface_pieces_are_bezier_in_that_direction():
    rng = np.random.default_rng(110)
    s = random_object(rng, (2, 3), (5, 7))
    for axis in (0, 1):
        p = s.degrees[axis]
        for piece in decompose_bezier(s, axis=axis):
            assert piece.sizes[axis] == p + 1
            assert piece.sizes[1 - axis] == s.sizes[1 - axis]
            kv = piece.knot_vectors[axis]
            assert torch.equal(kv[: p + 1], kv[:1].expand(p + 1)) and torch.equal(kv[p + 1 :], kv[-1:].expand(p + 1))


def test_reverse_curve_matches_flipped_geomdl_points_and_is_an_involution():
    rng = np.random.default_rng(120)
    c = random_object(rng, (3,), (8,))
    r = reverse(c)
    assert torch.equal(r.control_points, c.control_points.flip(0))
    assert torch.equal(r.weights, c.weights.flip(0))
    a, b = c.domain[0]
    np.testing.assert_allclose(r.knot_vector.numpy(), (a + b) - c.knot_vector.numpy()[::-1], atol=TOL, rtol=0)
    back = reverse(r)
    np.testing.assert_allclose(back.knot_vector.numpy(), c.knot_vector.numpy(), atol=TOL, rtol=0)
    assert torch.equal(back.control_points, c.control_points)


# ---- differentiability, dtype and device ------------------------------------------------

def _operation(op, s):
    if op == "insert":
        return insert_knot(s, float(np.mean(s.domain[1])), 2, axis=1)
    if op == "refine":
        return refine_knots(s, [float(np.mean(s.domain[0])), s.domain[0][0] + 0.1], axis=0)
    if op == "elevate":
        return elevate_degree(s, 1, axis=1)
    if op == "split":
        return split(s, float(np.mean(s.domain[0])), axis=0)[1]
    return reverse(s, axis=0)


@pytest.mark.parametrize("op", ["insert", "refine", "elevate", "split", "reverse"])
def test_gradients_reach_control_points_and_weights(op):
    rng = np.random.default_rng(130)
    base = random_object(rng, (3, 2), (5, 4), dim=2)

    def run(cp, w):
        out = _operation(op, base._replace(control_points=cp, weights=w))
        return out.control_points, out.weights

    cp = base.control_points.clone().requires_grad_(True)
    w = base.weights.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(run, (cp, w))


@pytest.mark.parametrize("op", ["insert", "refine", "elevate"])
def test_gradient_of_the_kept_geometry_is_the_original_gradient(op):
    """The new object is the same function of (P, w), so are its derivatives at fixed parameters."""
    rng = np.random.default_rng(131)
    base = random_object(rng, (3, 2), (5, 4), dim=2)
    uv = random_params(rng, base, 12)
    grads = []
    for transform in (lambda s: s, lambda s: _operation(op, s)):
        cp = base.control_points.clone().requires_grad_(True)
        w = base.weights.clone().requires_grad_(True)
        value = transform(base._replace(control_points=cp, weights=w)).evaluate(uv)
        grads.append(torch.autograd.grad((value * torch.linspace(1, 2, 2, dtype=value.dtype)).sum(), (cp, w)))
    for new, old in zip(*grads):
        np.testing.assert_allclose(new.numpy(), old.numpy(), atol=TOL, rtol=0)


def test_float32_follows_the_input_and_keeps_the_geometry():
    rng = np.random.default_rng(140)
    s = random_object(rng, (3, 2), (6, 5), dtype=torch.float32)
    params = random_params(rng, s, 60)
    value = 0.1 + float(np.mean(s.domain[0]))  # not a float32 number: rounded to the knot dtype
    for out in (insert_knot(s, value, 2), elevate_degree(s, 1, axis=1), refine_knots(s, [value], axis=0)):
        assert out.control_points.dtype == out.weights.dtype == torch.float32
        assert all(kv.dtype == torch.float32 for kv in out.knot_vectors)
        np.testing.assert_allclose(evaluate(out, params).numpy(), evaluate(s, params).numpy(), atol=2e-5, rtol=0)
    inserted = insert_knot(s, value).knot_vectors[0]
    assert int((inserted == torch.tensor(value, dtype=torch.float32)).sum()) == 1


def test_zero_times_and_empty_values_return_an_equal_copy():
    rng = np.random.default_rng(150)
    c = random_object(rng, (2,), (5,))
    for out in (insert_knot(c, float(np.mean(c.domain[0])), 0), refine_knots(c, []), elevate_degree(c, 0)):
        assert out is not c and type(out) is NURBSCurve
        assert torch.equal(out.control_points, c.control_points) and torch.equal(out.knot_vector, c.knot_vector)


# ---- errors ---------------------------------------------------------------------------

def test_errors_say_what_was_expected_and_what_arrived():
    rng = np.random.default_rng(160)
    c = random_object(rng, (3,), (7,), clamped=True)
    s = random_object(rng, (2, 3), (4, 5))
    a, b = c.domain[0]
    with pytest.raises(NurbskitError, match=r"outside the domain"):
        insert_knot(c, b + 1.0)
    with pytest.raises(NurbskitError, match=r"outside the domain"):
        refine_knots(s, [s.domain[1][0] - 0.5], axis=1)
    with pytest.raises(NurbskitError, match=r"multiplicity 4 .* degree 3; inserting it 1 more"):
        insert_knot(c, a)  # the clamped end already has multiplicity p + 1
    with pytest.raises(NurbskitError, match=r"inserting it 4 more time\(s\) would exceed 3 \(at most 3 more;"):
        insert_knot(c, (a + b) / 2 + 1e-3, times=4)
    with pytest.raises(NurbskitError, match=r"would exceed 3"):
        refine_knots(c, [(a + b) / 2] * 4)
    with pytest.raises(NurbskitError, match=r"axis must be an integer in 0 for a curve, got 1"):
        insert_knot(c, (a + b) / 2, axis=1)
    with pytest.raises(NurbskitError, match=r"axis must be an integer in 0\.\.1 for a surface, got 2"):
        elevate_degree(s, axis=2)
    with pytest.raises(NurbskitError, match=r"axis"):
        reverse(s, axis=-1)
    with pytest.raises(NurbskitError, match=r"times must be a non-negative integer, got -1"):
        elevate_degree(c, -1)
    with pytest.raises(NurbskitError, match=r"times must be a non-negative integer, got 1.5"):
        insert_knot(c, (a + b) / 2, times=1.5)
    with pytest.raises(NurbskitError, match=r"outside the domain \("):
        split(c, a)
    with pytest.raises(NurbskitError, match=r"finite"):
        insert_knot(c, float("nan"))
    with pytest.raises(NurbskitError, match=r"single number"):
        insert_knot(c, [0.1, 0.2])
    with pytest.raises(NurbskitError, match=r"expected a NURBSCurve"):
        insert_knot(torch.zeros(3, 2), 0.5)
    # An interior break (multiplicity p + 1) cannot be elevated across: split there first.
    m = (a + b) / 2
    broken = NURBSCurve(torch.rand(6, 2, dtype=torch.float64), 2, [a] * 3 + [m] * 3 + [b] * 3)
    with pytest.raises(NurbskitError, match=r"interior knot .* has multiplicity 3, more than the degree 2"):
        elevate_degree(broken)
    with pytest.raises(NurbskitError, match=r"direction v of the surface"):
        insert_knot(s, s.domain[1][1] + 1, axis=1)


def test_core_find_spans_at_a_repeated_unclamped_end():
    """Unclamped knots whose domain end ``b = knots[n]`` is a double knot (p = 2): the
    curve passes through ``P[n - 2]`` at ``b`` (what inserting ``b`` produces)."""
    knots = torch.tensor([-1.0, -0.5, 0.0, 0.5, 1.0, 1.0, 1.5, 2.0], dtype=torch.float64)
    c = NURBSCurve(torch.rand(5, 2, dtype=torch.float64), 2, knots)
    end = c.evaluate(torch.tensor([1.0], dtype=torch.float64))[0]
    assert torch.allclose(end, c.control_points[3], atol=TOL, rtol=0)


def test_split_at_an_interior_break_and_clamp_over_long_end_runs():
    """Multiplicity p + 1 inside (a break) splits without insertion; p + 2 equal end knots
    (an empty first span: construction refuses them, an unchecked object may hold them)
    are clamped away by decompose_bezier and elevate_degree."""
    rng = np.random.default_rng(170)
    p, a, m, b = 2, -1.0, 0.25, 2.0
    broken = NURBSCurve(torch.tensor(rng.normal(size=(6, 3))), p, [a] * 3 + [m] * 3 + [b] * 3,
                        torch.tensor(rng.uniform(0.5, 2, 6)))
    first, second = split(broken, m)
    assert first.sizes == second.sizes == (3,)
    assert torch.allclose(first.control_points, broken.control_points[:3], atol=TOL, rtol=0)
    assert torch.allclose(second.control_points, broken.control_points[3:], atol=TOL, rtol=0)
    left = torch.linspace(a, m, 30, dtype=torch.float64)[:-1]  # the break belongs to the right piece
    right = torch.linspace(m, b, 30, dtype=torch.float64)
    np.testing.assert_allclose(first.evaluate(left).numpy(), broken.evaluate(left).numpy(), atol=TOL, rtol=0)
    np.testing.assert_allclose(second.evaluate(right).numpy(), broken.evaluate(right).numpy(), atol=TOL, rtol=0)

    long_knots = [0.0] * 5 + [0.4, 0.7] + [1.0] * 4
    with pytest.raises(NurbskitError, match=r"repeats the knot 0\.0 5 times from index 0; degree 3 allows at most 4"):
        NURBSCurve(torch.tensor(rng.normal(size=(7, 2))), 3, long_knots)
    with pytest.raises(NurbskitError, match=r"knot vector for v repeats the knot 0\.5 4 times from index 3"):
        NURBSSurface(torch.rand(4, 7, 3, dtype=torch.float64), (3, 2), [None, [0, 0, 0, .5, .5, .5, .5, 1, 1, 1]])
    long_run = NURBSCurve(torch.tensor(rng.normal(size=(7, 2))), 3, torch.tensor(long_knots, dtype=torch.float64),
                          validate=False)
    u = torch.linspace(0, 1, 50, dtype=torch.float64)
    for out in (elevate_degree(long_run), *decompose_bezier(long_run)):
        assert int((out.knot_vector == out.knot_vector[0]).sum()) == out.degree + 1
        inside = u[(u >= out.domain[0][0]) & (u <= out.domain[0][1])]
        np.testing.assert_allclose(out.evaluate(inside).numpy(), long_run.evaluate(inside).numpy(), atol=TOL, rtol=0)
