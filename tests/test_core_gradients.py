"""Gradients reach control points, weights and knots exactly (gradcheck, float64)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.autograd import gradcheck

from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume
from nurbskit.core import clamped_uniform, knots_to_logits, logits_to_knots

from _assert import assert_close
from _splines import random_params, random_spline


def _interior_knot_fn(spline, axis):
    """Function of the interior knots of one direction (ends fixed), for gradcheck."""
    kv = spline.knot_vectors[axis]
    p = spline.degrees[axis]
    n = spline.sizes[axis]
    head, tail = kv[: p + 1], kv[n:]

    def with_inner(inner):
        kvs = list(spline.knot_vectors)
        kvs[axis] = torch.cat([head, inner, tail])
        return spline._replace(knot_vectors=kvs)

    return kv[p + 1 : n].clone(), with_inner


def _distinct_knots_spline(cls, degrees, sizes, seed):
    # Distinct interior knots: the knot gradient is defined (no coinciding knots to split).
    rng = np.random.default_rng(seed)
    s = random_spline(cls, rng, degrees, sizes, 3, True)
    kvs = []
    for (a, b), p, n in zip(s.domain, degrees, sizes):
        inner = np.sort(rng.uniform(a + 0.05 * (b - a), b - 0.05 * (b - a), n - p - 1))
        kvs.append(torch.tensor(np.r_[[a] * (p + 1), inner, [b] * (p + 1)], dtype=torch.float64))
    return s._replace(knot_vectors=kvs), rng


@pytest.mark.parametrize("cls,degrees,sizes", [
    (NURBSCurve, (3,), (7,)),
    (NURBSSurface, (3, 2), (6, 5)),
    (NURBSVolume, (2, 2, 1), (4, 4, 3)),
])
def test_gradcheck_control_points_and_weights(cls, degrees, sizes):
    s, rng = _distinct_knots_spline(cls, degrees, sizes, 11)
    params = random_params(rng, s, 6)
    if cls is NURBSCurve:
        params = params[:, 0]
    cp = s.control_points.clone().requires_grad_()
    w = s.weights.clone().requires_grad_()
    # fast_mode compares random vector-Jacobian projections: the full Jacobian of a
    # volume's derivatives would take hundreds of backward passes.
    assert gradcheck(lambda c, ww: s._replace(control_points=c, weights=ww).evaluate(params), (cp, w), fast_mode=True)
    order = 2 if cls is not NURBSVolume else 1
    assert gradcheck(lambda c, ww: s._replace(control_points=c, weights=ww).derivatives(params, order=order), (cp, w),
                     fast_mode=True)


@pytest.mark.parametrize("cls,degrees,sizes", [
    (NURBSCurve, (3,), (8,)),
    (NURBSCurve, (1,), (5,)),
    (NURBSSurface, (3, 2), (6, 5)),
    (NURBSVolume, (2, 2, 2), (4, 5, 4)),
])
def test_gradcheck_interior_knots(cls, degrees, sizes):
    s, rng = _distinct_knots_spline(cls, degrees, sizes, 12)
    params = random_params(rng, s, 8, ends=False)
    if cls is NURBSCurve:
        params = params[:, 0]
    for axis in range(len(degrees)):
        inner, with_inner = _interior_knot_fn(s, axis)
        inner.requires_grad_()
        assert gradcheck(lambda k: with_inner(k).evaluate(params), (inner,))
        assert gradcheck(lambda k: with_inner(k).derivatives(params, order=1), (inner,), fast_mode=True)


def test_knot_gradient_matches_central_differences():
    # An explicit oracle besides gradcheck: d(sum S)/d knot_i by central differences.
    s, rng = _distinct_knots_spline(NURBSSurface, (3, 3), (7, 6), 13)
    axes = s.grid_axes((9, 8))
    inner, with_inner = _interior_knot_fn(s, 0)
    inner.requires_grad_()
    with_inner(inner).evaluate_grid(*axes).square().sum().backward()
    h = 1e-6
    for i in range(inner.numel()):
        e = torch.zeros_like(inner)
        e[i] = h
        f = lambda k: float(with_inner(k).evaluate_grid(*axes).square().sum())  # noqa: E731
        fd = (f(inner.detach() + e) - f(inner.detach() - e)) / (2 * h)
        assert abs(float(inner.grad[i]) - fd) <= 1e-6 * max(1.0, abs(fd))


def test_grid_gradients_equal_scattered_gradients():
    s, rng = _distinct_knots_spline(NURBSSurface, (3, 2), (6, 7), 14)
    axes = s.grid_axes((5, 6))
    mesh = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 2)
    grads = []
    for mode in ("grid", "scattered"):
        cp = s.control_points.clone().requires_grad_()
        w = s.weights.clone().requires_grad_()
        kv = [k.clone().requires_grad_() for k in s.knot_vectors]
        t = s._replace(control_points=cp, weights=w, knot_vectors=kv)
        out = t.evaluate_grid(*axes).reshape(-1, 3) if mode == "grid" else t.evaluate(mesh)
        (out * torch.arange(out.numel(), dtype=out.dtype).reshape(out.shape).sin()).sum().backward()
        grads.append([cp.grad, w.grad, kv[0].grad, kv[1].grad])
    for a, b in zip(*grads):
        assert_close(a, b, atol=1e-10 * max(1.0, float(b.abs().max())))


@pytest.mark.parametrize("batch", [(), (2,)], ids=["single", "batch"])
def test_gradcheck_grid_through_the_one_node_path(batch):
    # A surface grid is one autograd node with a hand-written backward, also when the
    # knots and the grid parameters train (dB_u = dH X^T, dB_v^T = Pw^T dX): gradcheck
    # every input at once, knots of both directions, on a batch sharing its knots.
    s, rng = _distinct_knots_spline(NURBSSurface, (3, 2), (6, 5), 16)
    if batch:
        g = torch.Generator().manual_seed(0)
        cp0 = s.control_points + 0.1 * torch.rand(batch + s.control_points.shape, generator=g, dtype=torch.float64)
        s = s._replace(control_points=cp0, weights=s.weights.expand(batch + s.weights.shape).clone())
    inner_u, with_u = _interior_knot_fn(s, 0)
    inner_v = s.knot_vectors[1][3:5].clone()
    head_v, tail_v = s.knot_vectors[1][:3], s.knot_vectors[1][5:]
    u, v = s.grid_axes((7, 4))
    inputs = [t.clone().requires_grad_() for t in (s.control_points, s.weights, inner_u, inner_v, u)]

    def f(cp, w, ku, kv, uu):
        t = with_u(ku)
        t = t._replace(control_points=cp, weights=w, knot_vectors=[t.knot_vectors[0], torch.cat([head_v, kv, tail_v])],
                       validate=False)
        return t.evaluate_grid(uu, v)

    assert gradcheck(f, tuple(inputs))
    # the same values as the scattered evaluation, and as the cached (fixed-knot) path
    mesh = torch.stack(torch.meshgrid(u, v, indexing="ij"), -1).reshape(-1, 2)
    out = f(*inputs).detach()
    scale = float(out.abs().max())
    assert_close(out.reshape(batch + (-1, 3)), s.evaluate(mesh), atol=1e-14 * scale)
    assert_close(out, s.evaluate_grid(u, v), atol=1e-15 * scale)


def test_parameter_gradient_is_the_derivative():
    s, rng = _distinct_knots_spline(NURBSSurface, (3, 3), (6, 6), 15)
    uv = random_params(rng, s, 10, ends=False).requires_grad_()
    pts = s.evaluate(uv)
    d = s.derivatives(uv.detach(), order=1)
    for k in range(3):
        (g,) = torch.autograd.grad(pts[:, k].sum(), uv, retain_graph=True)
        assert_close(g[:, 0], d[:, 1, 0, k], atol=1e-12 * max(1.0, float(d.abs().max())))
        assert_close(g[:, 1], d[:, 0, 1, k], atol=1e-12 * max(1.0, float(d.abs().max())))


def test_ordered_knot_parametrisation_round_trip_and_order():
    kv = torch.tensor([0, 0, 0, 0, 0.1, 0.35, 0.36, 0.8, 1, 1, 1, 1], dtype=torch.float64)
    logits = knots_to_logits(kv, 3, 8)
    back = logits_to_knots(logits, 3, (0.0, 1.0))
    torch.testing.assert_close(back, kv, atol=1e-12, rtol=0)
    wild = torch.randn(5, dtype=torch.float64) * 10
    k = logits_to_knots(wild, 3, (-2.0, 5.0))
    assert k.numel() == 12 and float(k[0]) == -2.0 and float(k[-1]) == 5.0
    assert bool((k[4:8] > k[3:7]).all())  # strictly increasing interior
    wild.requires_grad_()
    assert gradcheck(lambda z: logits_to_knots(z, 3, (-2.0, 5.0)), (wild,))


def test_knot_gradient_trains_knots():
    # A target made with moved knots: optimising the knot logits recovers them.
    cp = torch.tensor(np.random.default_rng(0).normal(size=(8, 2)))
    target_kv = torch.tensor([0, 0, 0, 0, 0.15, 0.3, 0.7, 0.85, 1, 1, 1, 1], dtype=torch.float64)
    u = torch.linspace(0, 1, 200, dtype=torch.float64)
    target = NURBSCurve(cp, 3, target_kv).evaluate(u)
    logits = knots_to_logits(clamped_uniform(8, 3, dtype=torch.float64), 3, 8).clone().requires_grad_()
    opt = torch.optim.LBFGS([logits], max_iter=500, line_search_fn="strong_wolfe", tolerance_grad=1e-16, tolerance_change=0)

    def closure():
        opt.zero_grad()
        loss = (NURBSCurve(cp, 3, logits_to_knots(logits, 3, (0.0, 1.0)), validate=False).evaluate(u) - target).square().mean()
        loss.backward()
        return loss

    opt.step(closure)
    torch.testing.assert_close(logits_to_knots(logits.detach(), 3, (0.0, 1.0)), target_kv, atol=1e-6, rtol=0)
