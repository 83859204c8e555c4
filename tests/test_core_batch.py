"""Batches of splines (issue 16): a batch equals a loop over its elements, gradients stay per
element, nothing reads back to the host on the hot paths, and the basis cache is never stale.

Oracles: the same method called on each element (``batch[i]``) in float64, gradcheck,
closed forms (a Bezier polynomial outside its domain, the sphere's normal at its pole),
and the operation counter (``nurbskit._opcount``) for host reads and aten operations.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
import torch
from torch.autograd import gradcheck

from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume, NurbskitError
from nurbskit._opcount import OperationCounter
from nurbskit.core import logits_to_knots
from nurbskit.core.ops import elevate_degree, insert_knot, refine_knots, reverse, split
from nurbskit.core.tensor import basis_cache
from nurbskit.core.tessellate import tessellate

from _assert import assert_close
from _splines import random_batch, sphere_octant

F64 = torch.float64
CASES = [
    (NURBSCurve, (3,), (7,), (4,)),
    (NURBSSurface, (3, 2), (6, 5), (2, 3)),
    (NURBSVolume, (2, 1, 2), (4, 3, 4), (3,)),
]
IDS = ["curve", "surface", "volume"]


def _params(obj, rng, m, batch=()):
    """``(*batch, M, k)`` parameters in the (common) domain, corners included."""
    lo = np.array([float(np.asarray(d[0]).reshape(-1)[0]) for d in obj.domain])
    hi = np.array([float(np.asarray(d[1]).reshape(-1)[0]) for d in obj.domain])
    pts = rng.uniform(lo, hi, size=tuple(batch) + (m, lo.size))
    pts[..., 0, :], pts[..., 1, :] = lo, hi
    t = torch.tensor(pts, dtype=F64)
    return t[..., 0] if obj.para_dim == 1 else t


def _loop(obj, fn, per_element=None):
    """``fn`` on every element, stacked back into the batch shape."""
    out = []
    for index in np.ndindex(obj.batch_shape):
        args = () if per_element is None else (per_element[index],)
        out.append(fn(obj[index], *args))
    return torch.stack(out).reshape(obj.batch_shape + out[0].shape)


@pytest.mark.parametrize("per_element_knots", [False, True], ids=["shared-knots", "knots-per-element"])
@pytest.mark.parametrize("cls,degrees,sizes,batch", CASES, ids=IDS)
def test_batch_equals_a_loop_over_elements(cls, degrees, sizes, batch, per_element_knots):
    rng = np.random.default_rng(7)
    domains = [(-1.0, 2.0)] * len(degrees)  # a common domain, so that shared parameters fit every element
    b = random_batch(cls, rng, batch, degrees, sizes, 2, per_element_knots, domains=domains)
    shared = _params(b, rng, 9)
    own = _params(b, rng, 9, batch)
    order = 2 if cls is not NURBSVolume else 1
    res = (5, 4, 3)[: cls.para_dim]
    axes = [torch.linspace(-1.0, 2.0, r, dtype=F64) for r in res]
    checks = {
        "evaluate shared": (b.evaluate(shared), _loop(b, lambda e: e.evaluate(shared))),
        "evaluate own": (b.evaluate(own), _loop(b, lambda e, t: e.evaluate(t), own)),
        "derivatives shared": (b.derivatives(shared, order), _loop(b, lambda e: e.derivatives(shared, order))),
        "derivatives own": (b.derivatives(own, order), _loop(b, lambda e, t: e.derivatives(t, order), own)),
        "sample": (b.sample(res), _loop(b, lambda e: e.sample(res))),
        "sample order 1": (b.sample(res, order=1), _loop(b, lambda e: e.sample(res, order=1))),
        "evaluate_grid": (b.evaluate_grid(*axes), _loop(b, lambda e: e.evaluate_grid(*axes))),
        "grid_axes": (torch.stack(b.grid_axes(4)[0].expand(batch + (4,)).unbind(-1), -1),
                      _loop(b, lambda e: e.grid_axes(4)[0])),
    }
    if cls is NURBSSurface:
        b3 = random_batch(cls, rng, batch, degrees, sizes, 3, per_element_knots, domains=domains)
        checks["normals"] = (b3.normals(own), _loop(b3, lambda e, t: e.normals(t), own))
        mesh = tessellate(b3, (5, 4))
        checks["tessellate vertices"] = (mesh.vertices, _loop(b3, lambda e: tessellate(e, (5, 4)).vertices))
        checks["tessellate normals"] = (mesh.normals, _loop(b3, lambda e: tessellate(e, (5, 4)).normals))
    for name, (got, expected) in checks.items():
        assert got.shape == expected.shape, name
        # the same arithmetic in another order: equal to the last bits of float64
        assert_close(got, expected, atol=1e-13 * max(1.0, float(expected.abs().max())), msg=name)


def test_batch_shapes_and_broadcasting():
    rng = np.random.default_rng(1)
    b = random_batch(NURBSSurface, rng, (2, 3), (3, 3), (5, 6), domains=[(0.0, 1.0)] * 2)
    assert b.batch_shape == (2, 3) and b.sizes == (5, 6) and b.dim == 3 and len(b) == 2
    assert b.evaluate(torch.rand(7, 2, dtype=F64)).shape == (2, 3, 7, 3)
    assert b.evaluate(torch.rand(3, 7, 2, dtype=F64)).shape == (2, 3, 7, 3)  # broadcast over the last batch axis
    assert b.derivatives(torch.rand(2, 3, 7, 2, dtype=F64), order=1).shape == (2, 3, 7, 2, 2, 3)
    assert b.sample((4, 5)).shape == (2, 3, 4, 5, 3)
    assert b[1].batch_shape == (3,) and b[1, 2].batch_shape == ()
    one = NURBSSurface(b.control_points[0, 0], (3, 3), b.knot_vectors, b.weights[0, 0])
    # a single spline keeps any leading parameter axes, as before
    assert one.evaluate(torch.rand(4, 7, 2, dtype=F64)).shape == (4, 7, 3)
    # parameters whose batch does not broadcast: a one-line error naming both shapes
    with pytest.raises(NurbskitError, match=r"batch shape \(4, 7\) does not broadcast with the surface's \(2, 3\)"):
        b.evaluate(torch.rand(4, 7, 5, 2, dtype=F64))
    with pytest.raises(NurbskitError, match="does not broadcast"):
        b.derivatives(torch.rand(3, 3, 5, 2, dtype=F64), order=1)


def test_gradcheck_on_a_batch():
    rng = np.random.default_rng(2)
    b = random_batch(NURBSSurface, rng, (2,), (2, 2), (4, 4), per_element_knots=True, domains=[(0.0, 1.0)] * 2)
    uv = _params(b, rng, 5, (2,))
    cp = b.control_points.clone().requires_grad_()
    w = b.weights.clone().requires_grad_()
    assert gradcheck(lambda c, ww: b._replace(control_points=c, weights=ww).evaluate(uv), (cp, w), fast_mode=True)
    assert gradcheck(lambda c, ww: b._replace(control_points=c, weights=ww).sample(4), (cp, w), fast_mode=True)
    # interior knots, one vector per element (distinct, so the gradient exists)
    kv = torch.tensor([[0, 0, 0, 0.3, 0.6, 1, 1, 1], [0, 0, 0, 0.45, 0.7, 1, 1, 1]], dtype=F64)
    inner = kv[:, 3:5].clone().requires_grad_()

    def with_inner(k):
        full = torch.cat([kv[:, :3], k, kv[:, 5:]], dim=-1)
        return b._replace(knot_vectors=[full, full.flip(-1).neg().add(1)], validate=False).evaluate(uv)

    assert gradcheck(with_inner, (inner,))


def test_gradients_stay_per_element():
    rng = np.random.default_rng(3)
    b = random_batch(NURBSCurve, rng, (3,), (3,), (6,), domains=[(0.0, 1.0)])
    cp = b.control_points.clone().requires_grad_()
    out = b._replace(control_points=cp).sample(16)
    out[1].square().sum().backward()
    assert float(cp.grad[0].abs().max()) == 0.0 and float(cp.grad[2].abs().max()) == 0.0
    single = b[1]._replace(control_points=b.control_points[1].clone().requires_grad_())
    single.sample(16).square().sum().backward()
    assert_close(cp.grad[1], single.control_points.grad, atol=1e-13)


# ---- host reads and operation counts ----------------------------------------------------------

def _surface(dtype=torch.float32, device="cpu", validate=True):
    g = torch.Generator().manual_seed(0)
    cp = torch.rand(32, 32, 3, generator=g, dtype=dtype).to(device)
    w = (torch.rand(32, 32, generator=g, dtype=dtype) + 0.5).to(device)
    return NURBSSurface(cp, (3, 3), weights=w, validate=validate)


def test_sample_reads_nothing_back_and_costs_a_dozen_operations():
    s = _surface()
    basis_cache.clear()
    with OperationCounter() as first:
        s.sample(64)  # builds the basis
    assert first.host_reads == 0, first.host_read_names()
    for step in range(3):  # control points change between calls, as in a fit
        moved = s._replace(control_points=s.control_points + step)
        with OperationCounter() as count:
            out = moved.sample(64)
        assert count.host_reads == 0, count.host_read_names()
        assert count.operations <= 12, count.summary()
        assert out.shape == (64, 64, 3)
    rebuilt = NURBSSurface(s.control_points * 2, (3, 3), s.knot_vectors, s.weights, validate=False)
    with OperationCounter() as count:
        rebuilt.sample(64)
    assert count.operations <= 12 and count.host_reads == 0, count.summary()


@pytest.mark.parametrize("trainable_knots", [False, True], ids=["fixed-knots", "trainable-knots"])
def test_evaluate_and_derivatives_read_nothing_back(trainable_knots):
    s = _surface(validate=False)
    if trainable_knots:
        s = s._replace(knot_vectors=[k.clone().requires_grad_() for k in s.knot_vectors])
    uv = torch.rand(500, 2)
    for fn in (lambda: s.evaluate(uv), lambda: s.derivatives(uv, order=2), lambda: s.sample((16, 8)),
               lambda: s.evaluate_grid(uv[:10, 0], uv[:12, 1])):
        fn()
        with OperationCounter() as count:
            fn()
        assert count.host_reads == 0, count.host_read_names()
    batch = NURBSSurface(torch.rand(8, 6, 6, 3), (3, 3), validate=False)
    for fn in (lambda: batch.evaluate(uv), lambda: batch.evaluate(torch.rand(8, 20, 2)), lambda: batch.sample(9)):
        with OperationCounter() as count:
            fn()
        assert count.host_reads == 0, count.host_read_names()


def test_a_validated_object_checks_the_domain_with_one_host_read():
    s = _surface()
    uv = torch.rand(100, 2)
    with OperationCounter() as count:
        s.evaluate(uv)
    assert count.host_reads == 1
    with OperationCounter() as count:
        s.evaluate(uv, extrapolate=True)
    assert count.host_reads == 0
    # a grid: one host read for all its axes, and the axis out of the domain is named
    u = torch.linspace(0, 1, 7)
    with OperationCounter() as count:
        s.evaluate_grid(u, u)
    assert count.host_reads == 1
    with pytest.raises(NurbskitError, match="parameter v = 1.5"):
        s.evaluate_grid(u, torch.linspace(0, 1.5, 4))


def test_trainable_knots_build_the_basis_vectorised_over_the_degree():
    # A2.2/A2.3 term by term cost O(p^2) small operations per direction (measured before:
    # +54, +64, +74, +84 per degree for a surface's sample); level by level, a constant
    # number per degree and direction.
    counts = []
    for p in (2, 3, 4, 5):
        s = NURBSSurface(torch.rand(12, 12, 3), (p, p), validate=False)
        t = s._replace(knot_vectors=[k.clone().requires_grad_() for k in s.knot_vectors])
        with OperationCounter() as count:
            t.sample(16)
        counts.append(count.operations)
    steps = np.diff(counts)
    assert len(set(steps.tolist())) == 1 and steps[0] <= 20, counts


_VIEWS = {"view", "_unsafe_view", "reshape", "transpose", "t", "split", "split_with_sizes", "slice", "select",
          "expand", "unsqueeze", "squeeze", "permute", "as_strided", "detach", "alias", "unflatten", "movedim"}


def _grid_sized_operations(fn, grid_points: int) -> list[str]:
    """Names of the operations in ``fn()`` (forward and backward) that write a tensor with at
    least ``grid_points`` elements: the passes over the output grid (views excluded)."""
    names = []

    class Big(OperationCounter):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            out = super().__torch_dispatch__(func, types, args, kwargs)
            first = out[0] if isinstance(out, (tuple, list)) and out else out
            name = str(func.overloadpacket).replace("aten::", "").replace("aten.", "")
            if isinstance(first, torch.Tensor) and first.numel() >= grid_points and name not in _VIEWS:
                names.append(name)
            return out

    with Big():
        fn()
    return names


def test_knot_gradients_add_two_gemms_not_passes_over_the_grid():
    # The regression of issue 16 (knot-gradient fwd+bwd 1.3-2.2x slower) came from autograd
    # through a channel-last division over the grid; the one-node path adds only the two
    # GEMMs for dB_u and dB_v^T, whose outputs are the size of the basis, not of the grid.
    s = _surface(dtype=torch.float64, validate=False)
    cp = s.control_points.clone().requires_grad_()
    kv = [k.clone().requires_grad_() for k in s.knot_vectors]
    R = 64

    def run(knots):
        t = s._replace(control_points=cp, knot_vectors=kv if knots else s.knot_vectors)
        t.sample(R).sum().backward()

    run(False), run(True)
    fixed = _grid_sized_operations(lambda: run(False), 3 * R * R)
    trained = _grid_sized_operations(lambda: run(True), 3 * R * R)
    assert trained == fixed, (fixed, trained)
    # the backward writes its gradient of the grid once (no cat, no per-channel temporary)
    assert "cat" not in fixed and len(fixed) <= 6, fixed


# ---- the basis cache is never stale -------------------------------------------------------------

def _fresh(fn):
    basis_cache.enabled = False
    try:
        return fn()
    finally:
        basis_cache.enabled = True


def test_cache_follows_in_place_changes_of_knots_params_and_axes():
    s = NURBSSurface(torch.rand(6, 5, 3, dtype=F64), (3, 2))
    kv = s.knot_vectors[0]
    before = s.sample(7)
    with torch.no_grad():
        kv[4] = 0.8  # an interior knot moves: same tensor, new version
    after = s.sample(7)
    assert_close(after, _fresh(lambda: s.sample(7)), atol=0)
    assert float((after - before).abs().max()) > 1e-3
    uv = torch.rand(20, 2, dtype=F64)
    s.evaluate(uv)
    uv.mul_(0.5)
    assert_close(s.evaluate(uv), _fresh(lambda: s.evaluate(uv)), atol=0)
    u = torch.linspace(0, 1, 9, dtype=F64)
    v = torch.linspace(0, 1, 4, dtype=F64)
    s.evaluate_grid(u, v)
    u.pow_(2)
    assert_close(s.evaluate_grid(u, v), _fresh(lambda: s.evaluate_grid(u, v)), atol=0)


def test_cache_never_serves_a_freed_tensors_entry():
    # New knot tensors of the same shape, made and freed in turn (ids are reused).
    rng = np.random.default_rng(4)
    cp = torch.tensor(rng.normal(size=(7, 3)))
    u = torch.linspace(0, 1, 11, dtype=F64)
    for _ in range(20):
        inner = np.sort(rng.uniform(0.05, 0.95, 3))
        kv = torch.tensor(np.r_[[0.0] * 4, inner, [1.0] * 4])
        c = NURBSCurve(cp, 3, kv)
        assert_close(c.sample(11), _fresh(lambda: c.sample(11)), atol=0)
        assert_close(c.evaluate(u), _fresh(lambda: c.evaluate(u)), atol=0)
        del c, kv


def test_knots_that_need_gradients_are_not_cached():
    s = NURBSSurface(torch.rand(6, 5, 3, dtype=F64), (3, 2))
    s.sample(7)
    kv = [k.clone().requires_grad_() for k in s.knot_vectors]
    t = s._replace(knot_vectors=kv)
    t.sample(7).square().sum().backward()
    assert kv[0].grad is not None and float(kv[0].grad[4:6].abs().max()) > 0


# ---- the domain ----------------------------------------------------------------------------------

def test_evaluation_outside_the_domain_names_parameter_value_and_domain():
    c = NURBSCurve(torch.rand(4, 2, dtype=F64), 3)
    with pytest.raises(NurbskitError, match=r"curve parameter u = 1\.5 lies outside the domain \[0\.0, 1\.0\]"):
        c.evaluate(torch.tensor([0.2, 1.5], dtype=F64))
    s = NURBSSurface(torch.rand(4, 4, 3, dtype=F64), (2, 2), [torch.tensor([0, 0, 0, 1, 2, 2, 2.], dtype=F64), None])
    with pytest.raises(NurbskitError, match=r"surface parameter v = -0\.25 lies outside the domain \[0\.0, 1\.0\].*extrapolate=True"):
        s.derivatives(torch.tensor([[1.5, -0.25]], dtype=F64))
    with pytest.raises(NurbskitError, match=r"parameter u = 2\.5"):
        s.evaluate_grid(torch.tensor([0.0, 2.5], dtype=F64), torch.tensor([0.5], dtype=F64))
    # the domain ends themselves, and float32 parameters rounded at the ends, are inside
    s.evaluate(torch.tensor([[2.0, 1.0]], dtype=torch.float32))
    s._replace(validate=False).evaluate(torch.tensor([[9.0, 9.0]], dtype=F64))  # unchecked object: no error
    # what a validated object derives keeps the check: a batch element, a knot operation's result
    b = NURBSSurface(torch.rand(2, 4, 4, 3, dtype=F64), (2, 2))
    left, _ = split(s, 1.0, axis=0)  # s's u-domain is [0, 2]; the left piece's [0, 1]
    for derived, u in [(b[0], 1.5), (refine_knots(s, [0.5]), 2.5), (elevate_degree(s), 2.5), (reverse(s), 2.5),
                       (left, 1.5)]:
        with pytest.raises(NurbskitError, match=rf"parameter u = {u} lies outside the domain"):
            derived.evaluate(torch.tensor([[u, 0.5]], dtype=F64))


def test_extrapolate_evaluates_the_end_polynomial():
    # A cubic Bezier curve: one polynomial, so outside [0, 1] it is the Bernstein form.
    P = torch.tensor([[0.0, 0.0], [1.0, 2.0], [3.0, 2.0], [4.0, 0.0]], dtype=F64)
    c = NURBSCurve(P, 3)
    u = torch.tensor([-0.5, 1.25], dtype=F64)
    bern = torch.stack([math.comb(3, i) * u**i * (1 - u) ** (3 - i) for i in range(4)], -1)
    assert_close(c.evaluate(u, extrapolate=True), bern @ P, atol=1e-13)


# ---- knots closer than the tolerance are one knot ----------------------------------------------

def test_construction_merges_knots_closer_than_the_tolerance():
    near = torch.tensor([0, 0, 0, 0.5, 0.5 + 1e-17, 1, 1, 1], dtype=F64)  # 0.5 + 1e-17 == 0.5 in float64
    near[4] = torch.nextafter(torch.tensor(0.5, dtype=F64), torch.tensor(1.0, dtype=F64))
    cp = torch.rand(5, 2, dtype=F64)
    c = NURBSCurve(cp, 2, near)
    assert float(c.knot_vector[4]) == 0.5
    exact = NURBSCurve(cp, 2, torch.tensor([0, 0, 0, 0.5, 0.5, 1, 1, 1], dtype=F64))
    u = torch.linspace(0, 1, 33, dtype=F64)
    assert_close(c.evaluate(u), exact.evaluate(u), atol=0)
    # issue 8: a subnormal span [0, 5e-324] at the start; u = 0 gave NaN
    line = NURBSCurve(torch.rand(3, 2, dtype=F64), 1, torch.tensor([0, 0, 5e-324, 1, 1], dtype=F64),
                      torch.tensor([1.0, 2.0, 1.0], dtype=F64))
    assert torch.isfinite(line.evaluate(torch.tensor([0.0, 1e-300, 0.5], dtype=F64))).all()


def test_inserting_next_to_a_knot_raises_its_multiplicity():
    c = NURBSCurve(torch.rand(6, 3, dtype=F64), 3, weights=torch.rand(6, dtype=F64) + 0.5)
    k = float(c.knot_vector[4])
    near = k + 2 * math.ulp(k)
    new = insert_knot(c, near)
    assert int((new.knot_vector == k).sum()) == 2 and int((new.knot_vector == near).sum()) == 0
    refined = refine_knots(c, [0.25, 0.25 + 1e-17, near])
    assert int((refined.knot_vector == 0.25).sum()) == 2
    u = torch.linspace(0, 1, 41, dtype=F64)
    assert_close(new.evaluate(u), c.evaluate(u), atol=1e-13)
    assert_close(refined.evaluate(u), c.evaluate(u), atol=1e-13)
    line = NURBSCurve(torch.rand(2, 2, dtype=F64), 1, torch.tensor([0, 0, 1, 1.], dtype=F64),
                      torch.tensor([1.0, 2.0], dtype=F64))
    with pytest.raises(NurbskitError, match="knot 0.0 has multiplicity 2"):
        insert_knot(line, 5e-324)


def test_trained_knots_keep_spans_the_basis_can_divide_by():
    logits = torch.tensor([800.0, -800.0, -800.0, 0.0], dtype=F64, requires_grad=True)
    kv = logits_to_knots(logits, 3, (0.0, 2.0))
    gaps = kv[4:8] - kv[3:7]
    assert float(gaps.detach().min()) >= 2.0 * 1e-7 * 0.999
    c = NURBSCurve(torch.rand(7, 2, dtype=F64), 3, kv, validate=False)
    out = c.sample(50)
    out.sum().backward()
    assert torch.isfinite(out).all() and torch.isfinite(logits.grad).all()


# ---- normals at a pole ------------------------------------------------------------------------

def test_normals_at_a_pole_are_the_limit_normal():
    s = sphere_octant()
    u = torch.linspace(0, 1, 7, dtype=F64)
    pole = torch.stack([u, torch.ones_like(u)], -1)  # the collapsed edge v = 1
    expected = torch.tensor([0.0, 0.0, 1.0], dtype=F64).expand(7, 3)
    assert_close(s.normals(pole), expected, atol=1e-12)
    uv = torch.rand(30, 2, dtype=F64)
    assert_close(s.normals(uv), s.evaluate(uv), atol=1e-12)  # the unit sphere's normal is the point
    grid = s.normals_grid(u, torch.linspace(0, 1, 5, dtype=F64))
    assert_close(grid[:, -1], expected, atol=1e-12)
    swapped = NURBSSurface(s.control_points.transpose(0, 1), (2, 2), None, s.weights.T)  # pole on u = 1
    assert_close(swapped.normals(pole.flip(-1)), -expected, atol=1e-12)  # S_u x S_v points inward there
    # next to the pole (not on it) the test for a degenerate point fires too: the point's
    # side of the domain gives the sign (it took the lower edge's, flipping the normal)
    for gap in (1e-9, 1e-8, 1e-7):
        near = torch.stack([u, torch.full_like(u, 1 - gap)], -1)
        assert_close(s.normals(near), s.evaluate(near) / s.evaluate(near).norm(dim=-1, keepdim=True), atol=1e-6)
        assert_close(swapped.normals(near.flip(-1)), -s.evaluate(near) / s.evaluate(near).norm(dim=-1, keepdim=True),
                     atol=1e-6)


# ---- knot operations and output on a batch ----------------------------------------------------

def test_knot_operations_on_a_batch_with_shared_knots_act_per_element():
    rng = np.random.default_rng(5)
    b = random_batch(NURBSSurface, rng, (3,), (3, 2), (6, 5), domains=[(0.0, 1.0)] * 2)
    for op in (lambda o: insert_knot(o, 0.4, 2, axis=1), lambda o: refine_knots(o, [0.2, 0.7], axis=0),
               lambda o: elevate_degree(o, 1, axis=1), lambda o: reverse(o, axis=0)):
        got = op(b)
        for i in range(3):
            one = op(b[i])
            assert_close(got.control_points[i], one.control_points, atol=1e-13)
            assert_close(got.weights[i], one.weights, atol=1e-13)
            for k_got, k_one in zip(got.knot_vectors, one.knot_vectors):
                assert_close(k_got, k_one, atol=0)


def test_per_element_knots_and_file_output_refuse_a_batch():
    rng = np.random.default_rng(6)
    b = random_batch(NURBSCurve, rng, (2,), (2,), (5,), per_element_knots=True, domains=[(0.0, 1.0)])
    with pytest.raises(NurbskitError, match="one knot vector per element"):
        insert_knot(b, 0.5)
    with pytest.raises(NurbskitError, match=r"to_dict works on one curve, got a batch of shape \(2,\)"):
        b.to_dict()
    with pytest.raises(NurbskitError, match=r"knot vector must have shape \(m,\) or \(2, 'm'\)"):
        NURBSCurve(torch.rand(2, 5, 2), 2, torch.zeros(3, 8))
    with pytest.raises(NurbskitError, match=r"batch element \(1,\).*decreases"):
        NURBSCurve(torch.rand(2, 5, 2), 2, torch.tensor([[0, 0, 0, .2, .5, 1, 1, 1], [0, 0, 0, .6, .5, 1, 1, 1.]]))


def test_core_loads_ops_lazily():
    code = ("import sys, nurbskit, nurbskit.core as core; "
            "assert 'nurbskit.core.ops' not in sys.modules; "
            "core.insert_knot; assert 'nurbskit.core.ops' in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "ok", out.stderr


# ---- the same on a GPU ------------------------------------------------------------------------

requires_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available: GPU-only check")


@requires_cuda
def test_cuda_matches_cpu_and_reads_nothing_back():
    rng = np.random.default_rng(8)
    b = random_batch(NURBSSurface, rng, (4,), (3, 3), (8, 7), per_element_knots=True, domains=[(0.0, 1.0)] * 2)
    g = b.to("cuda")
    uv = _params(b, rng, 50, (4,))
    for got, expected in ((g.evaluate(uv.cuda()), b.evaluate(uv)),
                          (g.derivatives(uv.cuda(), order=2), b.derivatives(uv, order=2)),
                          (g.sample(33), b.sample(33)), (g.sample(9, order=1), b.sample(9, order=1))):
        # float64 on both devices; the derivatives grow with the knot spacing, hence a relative scale
        assert_close(got.cpu(), expected, atol=1e-12 * max(1.0, float(expected.abs().max())))
    s = _surface(device="cuda", validate=False)
    s.sample(256)
    with OperationCounter() as count:
        s._replace(control_points=s.control_points * 2).sample(256)
        s.evaluate(torch.rand(100, 2, device="cuda"))
    assert count.host_reads == 0, count.host_read_names()


@requires_cuda
def test_a_surface_step_replays_as_a_cuda_graph():
    # Capture needs no host read and no allocation outside the graph's pool: the forward,
    # loss and backward of a surface grid, captured once, replays to the eager gradients
    # for new values of the control points and weights.
    s = _surface(dtype=torch.float64, device="cuda", validate=False)
    cp, w = s.control_points.clone().requires_grad_(), s.weights.clone().requires_grad_()

    def step():
        s._replace(control_points=cp, weights=w).sample(48).square().sum().backward()

    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        for _ in range(3):
            cp.grad = w.grad = None
            step()
    torch.cuda.current_stream().wait_stream(side)
    cp.grad = w.grad = None
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        step()
    with torch.no_grad():
        cp.mul_(1.5)
        w.add_(0.25)
    graph.replay()
    torch.cuda.synchronize()
    replayed = cp.grad.clone(), w.grad.clone()
    cp.grad = w.grad = None
    step()
    for got, expected in zip(replayed, (cp.grad, w.grad)):
        assert_close(got, expected, atol=1e-10 * float(expected.abs().max()))


def test_weights_shared_by_a_batch_work_unvalidated_too():
    # A fit loop builds its splines with validate=False; weights shared by the batch, (n)
    # or (n_u, n_v), used to be expanded only when validated (evaluate crashed).
    g = torch.Generator().manual_seed(4)
    uv = torch.rand(7, 2, generator=g, dtype=torch.float64)
    cases = [(NURBSSurface, torch.rand(2, 3, 5, 4, 3, generator=g, dtype=torch.float64),
              torch.rand(5, 4, generator=g, dtype=torch.float64) + 0.5, (2, 3), uv),
             (NURBSCurve, torch.rand(3, 5, 2, generator=g, dtype=torch.float64),
              torch.rand(5, generator=g, dtype=torch.float64) + 0.5, 2, uv[:, 0])]
    for cls, cp, w, degrees, t in cases:
        checked, unchecked = (cls(cp, degrees, weights=w, validate=v) for v in (True, False))
        for call in (lambda s: s.evaluate(t), lambda s: s.derivatives(t, 1), lambda s: s.sample(4)):
            assert_close(call(unchecked), call(checked), atol=0.0)


def test_sample_gradient_follows_the_domain_ends():
    # The sample grid is uniform over the domain, so moving an end knot moves every sample:
    # gradcheck against finite differences of the clamped end knots (they were detached).
    g = torch.Generator().manual_seed(5)
    cp = torch.rand(6, 5, 3, generator=g, dtype=torch.float64)
    inner_u = torch.tensor([0.3, 0.55], dtype=torch.float64)
    inner_v = torch.tensor([0.4], dtype=torch.float64)

    def grid(a, b):
        ku = torch.cat([a.expand(4), inner_u, b.expand(4)])
        kv = torch.cat([a.expand(4), inner_v, b.expand(4)])
        return NURBSSurface(cp, (3, 3), [ku, kv], validate=False).sample((5, 4))

    ends = (torch.tensor(0.1, dtype=torch.float64, requires_grad=True),
            torch.tensor(0.9, dtype=torch.float64, requires_grad=True))
    assert gradcheck(grid, ends, eps=1e-6, atol=1e-8)


def test_second_derivatives_through_a_surface_grid():
    # The grid's fast backward works in place; with create_graph=True (Hessian-vector
    # products) it takes a differentiable path. Before, the curvature term was dropped
    # without an error (a Hessian-vector product 31.4 where finite differences give 71.0).
    from torch.autograd import gradgradcheck

    g = torch.Generator().manual_seed(6)
    cp = torch.rand(5, 4, 3, generator=g, dtype=torch.float64, requires_grad=True)
    w = (torch.rand(5, 4, generator=g, dtype=torch.float64) + 0.5).requires_grad_()
    inner = torch.tensor([0.35, 0.6], dtype=torch.float64, requires_grad=True)

    def grid(cp, w, inner):
        ku = torch.cat([torch.zeros(4, dtype=torch.float64), inner[:1], torch.ones(4, dtype=torch.float64)])
        kv = torch.cat([torch.zeros(3, dtype=torch.float64), inner[1:], torch.ones(3, dtype=torch.float64)])
        return NURBSSurface(cp, (3, 2), [ku, kv], weights=w, validate=False).sample(4)

    assert gradgradcheck(grid, (cp, w, inner), eps=1e-6, atol=1e-6)
    batch = NURBSSurface(cp.detach().expand(2, -1, -1, -1).clone().requires_grad_(), (3, 2), weights=w.detach())
    assert gradgradcheck(lambda P: batch._replace(control_points=P).sample(3), (batch.control_points,), eps=1e-6, atol=1e-6)
