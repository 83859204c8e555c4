"""Evaluation and derivatives against geomdl, closed forms and the grid/scattered identity."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume
from nurbskit.core import to_geomdl

from _assert import assert_close
from _splines import random_params, random_spline, to_geomdl_params

TOL = 1e-10


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("rational", [False, True])
def test_curve_matches_geomdl(degree, rational):
    rng = np.random.default_rng(100 + degree)
    for dim in (2, 3):
        c = random_spline(NURBSCurve, rng, (degree,), (degree + 1 + int(rng.integers(0, 6)),), dim, rational)
        g = to_geomdl(c)
        u = random_params(rng, c, 40)
        t, scale = to_geomdl_params(c, u)
        order = min(degree + 1, 4)
        ours = c.derivatives(u[:, 0], order=order)
        assert torch.allclose(c.evaluate(u[:, 0]), ours[:, 0], atol=0, rtol=0)
        for i, ti in enumerate(t[:, 0]):
            ref = np.array(g.derivatives(float(ti), order=order))
            ref = ref / scale[0] ** np.arange(order + 1)[:, None]
            np.testing.assert_allclose(ours[i].numpy(), ref, atol=TOL * max(1, np.abs(ref).max()), rtol=0)


@pytest.mark.parametrize("degrees", [(1, 1), (2, 3), (3, 3), (4, 2), (5, 4)])
@pytest.mark.parametrize("rational", [False, True])
def test_surface_matches_geomdl(degrees, rational):
    rng = np.random.default_rng(sum(degrees) * 7 + rational)
    sizes = [p + 1 + int(rng.integers(0, 5)) for p in degrees]
    s = random_spline(NURBSSurface, rng, degrees, sizes, 3, rational)
    g = to_geomdl(s)
    uv = random_params(rng, s, 30)
    t, scale = to_geomdl_params(s, uv)
    order = 2
    ours = s.derivatives(uv, order=order).numpy()
    np.testing.assert_array_equal(s.evaluate(uv).numpy(), ours[:, 0, 0])
    for i, (tu, tv) in enumerate(t):
        ref = np.array(g.derivatives(float(tu), float(tv), order=order))
        for a in range(order + 1):
            for b in range(order + 1 - a):  # geomdl fills only a + b <= order
                expect = ref[a][b] / (scale[0] ** a * scale[1] ** b)
                np.testing.assert_allclose(ours[i, a, b], expect, atol=TOL * max(1, np.abs(expect).max()), rtol=0)


@pytest.mark.parametrize("degrees", [(1, 2, 3), (3, 3, 3), (2, 4, 1)])
def test_volume_matches_geomdl(degrees):
    rng = np.random.default_rng(sum(degrees))
    sizes = [p + 1 + int(rng.integers(0, 4)) for p in degrees]
    vol = random_spline(NURBSVolume, rng, degrees, sizes, 3, True)
    g = to_geomdl(vol)
    uvw = random_params(rng, vol, 30)
    t, _ = to_geomdl_params(vol, uvw)
    ref = np.array([g.evaluate_single([float(x) for x in p]) for p in t])
    np.testing.assert_allclose(vol.evaluate(uvw).numpy(), ref, atol=TOL, rtol=0)


@pytest.mark.parametrize("cls,degrees,sizes", [
    (NURBSCurve, (3,), (9,)),
    (NURBSSurface, (3, 2), (7, 6)),
    (NURBSVolume, (2, 3, 1), (4, 5, 3)),
])
def test_grid_equals_scattered(cls, degrees, sizes):
    rng = np.random.default_rng(5)
    s = random_spline(cls, rng, degrees, sizes, 2, True)
    axes = [torch.tensor(np.sort(rng.uniform(a, b, 5 + i)).tolist() + [b]) for i, (a, b) in enumerate(s.domain)]
    mesh = torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1)
    flat = mesh.reshape(-1, len(axes))
    shape = tuple(len(a) for a in axes)
    grid = s.evaluate_grid(*axes)
    scat = s.evaluate(flat[:, 0] if cls is NURBSCurve else flat).reshape(shape + (2,))
    torch.testing.assert_close(grid, scat, atol=1e-12, rtol=0)
    dgrid = s.evaluate_grid(*axes, order=2)
    dscat = s.derivatives(flat[:, 0] if cls is NURBSCurve else flat, order=2)
    assert_close(dgrid, dscat.reshape(shape + dscat.shape[1:]), atol=1e-9 * float(dscat.abs().max()))


def test_domain_end_is_the_last_control_point_exactly():
    rng = np.random.default_rng(1)
    s = random_spline(NURBSSurface, rng, (3, 2), (6, 5), 3, rational=False)
    corners = torch.tensor([[a, c] for a in s.domain[0] for c in s.domain[1]], dtype=s.dtype)
    got = s.evaluate(corners)
    cp = s.control_points
    expect = torch.stack([cp[0, 0], cp[0, -1], cp[-1, 0], cp[-1, -1]])
    assert torch.equal(got, expect)  # exact, not approximately
    assert torch.equal(s.sample((4, 3))[-1, -1], cp[-1, -1])
    # on any domain: on [3, 52] the basis at the end was 1 - 2^-53 (49 * (1 / 49) != 1), and 12
    # of 150 random surfaces missed a corner by an ulp
    k = torch.tensor([3.0, 3.0, 52.0, 52.0], dtype=torch.float64)
    cp = torch.tensor([[[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0.7]]], dtype=torch.float64)
    assert torch.equal(NURBSSurface(cp, (1, 1), [k, k]).evaluate(torch.tensor([[52.0, 52.0]], dtype=torch.float64)),
                       cp[1:, 1])
    for seed in range(150):
        g = np.random.default_rng(100 + seed)
        dtype = torch.float64 if seed % 2 else torch.float32
        p, q = int(g.integers(1, 5)), int(g.integers(1, 5))
        (a, b), (c, d) = (np.sort(g.uniform(-50, 60, 2)) for _ in range(2))
        ku = torch.tensor(np.r_[[a] * p, np.linspace(a, b, 6 - p + 1), [b] * p], dtype=dtype)
        kv = torch.tensor(np.r_[[c] * q, np.linspace(c, d, 5 - q + 1), [d] * q], dtype=dtype)
        cp = torch.tensor(g.normal(size=(6, 5, 3)), dtype=dtype)
        s = NURBSSurface(cp, (p, q), [ku, kv])
        (a, b), (c, d) = s.domain
        corners = torch.tensor([[a, c], [a, d], [b, c], [b, d]], dtype=dtype)
        expect = torch.stack([cp[0, 0], cp[0, -1], cp[-1, 0], cp[-1, -1]])
        assert torch.equal(s.evaluate(corners), expect), (seed, p, q)
        assert torch.equal(s.derivatives(corners, 1)[:, 0, 0], expect), (seed, p, q)
        grid = s.sample((4, 3))
        assert torch.equal(torch.stack([grid[0, 0], grid[0, -1], grid[-1, 0], grid[-1, -1]]), expect), (seed, p, q)


def test_quarter_circle_closed_form():
    # Rational quadratic quarter circle: |C(u)| = 1 everywhere, C'(0) direction is +y.
    w = 2 ** -0.5
    c = NURBSCurve(torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=torch.float64), 2,
                   weights=torch.tensor([1.0, w, 1.0], dtype=torch.float64))
    u = torch.linspace(0, 1, 101, dtype=torch.float64)
    pts = c.evaluate(u)
    torch.testing.assert_close(pts.norm(dim=-1), torch.ones(101, dtype=torch.float64), atol=1e-15, rtol=0)
    d = c.derivatives(u, order=2)
    # velocity is tangent: perpendicular to the radius
    torch.testing.assert_close((d[:, 0] * d[:, 1]).sum(-1), torch.zeros(101, dtype=torch.float64), atol=1e-13, rtol=0)
    # arc length by quadrature equals pi / 2
    speed = d[:, 1].norm(dim=-1)
    length = torch.trapezoid(speed, u)
    assert abs(float(length) - math.pi / 2) < 1e-4


def test_cylinder_surface_normals_closed_form():
    # Quarter cylinder of radius 2 and height 3: normals are radial.
    w = 2 ** -0.5
    arc = torch.tensor([[2.0, 0.0], [2.0, 2.0], [0.0, 2.0]], dtype=torch.float64)
    cp = torch.zeros(3, 2, 3, dtype=torch.float64)
    cp[:, :, :2] = arc[:, None, :]
    cp[:, 1, 2] = 3.0
    weights = torch.tensor([1.0, w, 1.0], dtype=torch.float64)[:, None].expand(3, 2)
    s = NURBSSurface(cp, (2, 1), weights=weights)
    uv = torch.rand(50, 2, dtype=torch.float64)
    p = s.evaluate(uv)
    torch.testing.assert_close(p[:, :2].norm(dim=-1), torch.full((50,), 2.0, dtype=torch.float64), atol=1e-14, rtol=0)
    n = s.normals(uv)
    radial = torch.nn.functional.pad(p[:, :2] / 2.0, (0, 1))
    torch.testing.assert_close(n.abs(), radial.abs(), atol=1e-13, rtol=0)


def test_dtype_follows_inputs():
    s = NURBSSurface(torch.rand(5, 4, 3, dtype=torch.float32), (2, 2))
    assert s.knot_vectors[0].dtype == torch.float32
    assert s.evaluate(torch.rand(7, 2)).dtype == torch.float32
    assert s.sample(8).dtype == torch.float32
    s64 = NURBSSurface(torch.rand(5, 4, 3, dtype=torch.float64), (2, 2))
    assert s64.evaluate([[0.5, 0.5]]).dtype == torch.float64


def test_float32_error_is_small():
    rng = np.random.default_rng(3)
    s = random_spline(NURBSSurface, rng, (3, 3), (14, 13), 3, True, domains=[(0, 1), (0, 1)])
    s32 = s.to(torch.float32)
    axes = s.grid_axes(64)
    err = (s32.evaluate_grid(*[a.float() for a in axes]).double() - s.evaluate_grid(*axes)).abs().max()
    assert err < 1e-5 * s.control_points.abs().max()


def test_batched_parameters():
    rng = np.random.default_rng(4)
    s = random_spline(NURBSSurface, rng, (2, 3), (5, 6), 3, True)
    uv = random_params(rng, s, 12, ends=False).reshape(3, 4, 2)
    out = s.evaluate(uv)
    assert out.shape == (3, 4, 3)
    assert_close(out.reshape(12, 3), s.evaluate(uv.reshape(12, 2)), atol=0)
    assert s.derivatives(uv, order=1).shape == (3, 4, 2, 2, 3)


@pytest.mark.parametrize("weight", [1.0, 2.5])
def test_derivatives_above_the_degree_are_exactly_zero_for_a_polynomial_spline(weight):
    # The basis derivatives sum to zero only up to rounding: with the weights contracted as
    # they are, a degree-7 curve's 8th derivative came out 0.07 (its 7th is 3e9) and a
    # degree-3 surface's (4, 0) derivative 2e-11. Equal weights are no rational spline.
    g = torch.Generator().manual_seed(0)
    c = NURBSCurve(10 * torch.rand(12, 3, generator=g, dtype=torch.float64), 7,
                   weights=torch.full((12,), weight, dtype=torch.float64))
    t = torch.linspace(0, 1, 9, dtype=torch.float64)
    d = c.derivatives(t, 8)
    assert torch.equal(d[:, 8], torch.zeros_like(d[:, 8]))
    assert torch.equal(c.evaluate_grid(t, order=8)[:, 8], torch.zeros_like(d[:, 8]))
    for degrees in [(3, 3), (5, 2)]:
        cp = 10 * torch.rand(2, 8, 7, 3, generator=g, dtype=torch.float64)  # a batch of two
        s = NURBSSurface(cp, degrees, weights=torch.full((8, 7), weight, dtype=torch.float64))
        o = max(degrees) + 1
        uv = torch.rand(6, 2, generator=g, dtype=torch.float64)
        ds = s.derivatives(uv, o)  # (2, 6, o + 1, o + 1, 3)
        grid = s.evaluate_grid(uv[:, 0], uv[:, 1], order=o)  # (2, 6, 6, o + 1, o + 1, 3)
        for table in (ds, grid):
            above_u = table[..., degrees[0] + 1:, :, :]
            above_v = table[..., :, degrees[1] + 1:, :]
            assert torch.equal(above_u, torch.zeros_like(above_u))
            assert torch.equal(above_v, torch.zeros_like(above_v))
