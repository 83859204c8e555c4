"""Losses against naive loops, closed forms and gradcheck (float64)."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F
from _assert import assert_close

from nurbskit import NURBSSurface
from nurbskit import losses as L
from nurbskit.errors import NurbskitError

F64 = torch.float64


def _rand(*shape, seed=0):
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed), dtype=F64)


def _separated(n, d, seed, spacing=0.2):
    """Random points on a coarse lattice plus small jitter: nearest neighbours are unique
    and stay the same under gradcheck's 1e-6 perturbations."""
    g = torch.Generator().manual_seed(seed)
    lattice = torch.randperm(10**d, generator=g)[:n]
    coords = torch.stack([(lattice // 10**k) % 10 for k in range(d)], -1).to(F64) * spacing
    return coords + 0.05 * spacing * torch.rand(n, d, generator=g, dtype=F64)


# ---- L2 -----------------------------------------------------------------------------

def test_l2_is_mean_over_points_of_squared_distance():
    x, y = _rand(17, 3, seed=1), _rand(17, 3, seed=2)
    expected = sum(float(((x[i] - y[i]) ** 2).sum()) for i in range(17)) / 17
    assert L.l2_loss(x, y).item() == pytest.approx(expected, rel=1e-14)
    # thesis eq. 2.6 averages over points, not coordinates: D times torch's MSE
    assert L.l2_loss(x, y).item() == pytest.approx(3 * F.mse_loss(x, y).item(), rel=1e-14)
    assert L.l2_loss(x, y, "sum").item() == pytest.approx(17 * expected, rel=1e-14)
    assert L.l2_loss(x, y, "none").shape == (17,)


def test_l2_batched_and_order_sensitive():
    x, y = _rand(4, 9, 2, seed=3), _rand(4, 9, 2, seed=4)
    out = L.l2_loss(x, y)
    assert out.shape == (4,)
    assert_close(out[2], L.l2_loss(x[2], y[2]))
    assert L.l2_loss(x[0], x[0].flip(0)).item() > 0


def test_l2_rejects_different_sizes():
    with pytest.raises(NurbskitError, match="same"):
        L.l2_loss(torch.rand(5, 3), torch.rand(6, 3))
    with pytest.raises(NurbskitError, match="reduction"):
        L.l2_loss(torch.rand(5, 3), torch.rand(5, 3), "max")


# ---- Chamfer ------------------------------------------------------------------------

@pytest.mark.parametrize("n,m,d", [(1, 1, 3), (3, 8, 3), (20, 13, 3), (9, 25, 2)])
@pytest.mark.parametrize("reduction", ["mean", "sum"])
def test_chamfer_matches_brute_force(n, m, d, reduction):
    x, y = _rand(n, d, seed=n), _rand(m, d, seed=100 + m)
    got = L.chamfer_distance(x, y, reduction)
    torch.testing.assert_close(got, L.chamfer_distance_naive(x, y, reduction), rtol=1e-13, atol=0)


def test_chamfer_sum_is_thesis_equation_2_7():
    x = torch.tensor([[0.0, 0.0], [1.0, 0.0]], dtype=F64)
    y = torch.tensor([[0.0, 0.0], [1.0, 1.0], [3.0, 0.0]], dtype=F64)
    # x->y: 0, 1 ; y->x: 0, 1, 4
    assert L.chamfer_distance(x, y, "sum").item() == 6.0
    total, px, py = L.chamfer_distance(x, y, return_parts=True)
    assert (px.item(), py.item()) == (0.5, 5 / 3)
    assert total.item() == pytest.approx(0.5 + 5 / 3)


def test_chamfer_symmetric_and_permutation_invariant():
    x, y = _rand(30, 3, seed=5), _rand(21, 3, seed=6)
    a = L.chamfer_distance(x, y)
    assert_close(a, L.chamfer_distance(y, x))
    assert_close(a, L.chamfer_distance(x[torch.randperm(30)], y.flip(0)))
    assert L.chamfer_distance(x, x).item() == 0.0


def test_chamfer_batched():
    x, y = _rand(3, 12, 3, seed=7), _rand(3, 8, 3, seed=8)
    out = L.chamfer_distance(x, y)
    assert out.shape == (3,)
    for b in range(3):
        assert_close(out[b], L.chamfer_distance_naive(x[b], y[b]))


def test_chamfer_gradcheck():
    x = _separated(12, 3, seed=9).requires_grad_(True)
    y = (_separated(9, 3, seed=10) + 0.01).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a, b: L.chamfer_distance(a, b), (x, y))
    assert torch.autograd.gradcheck(lambda a, b: L.chamfer_distance(a, b, "sum"), (x, y))


def test_chamfer_gradient_equals_naive_gradient():
    x = _rand(15, 3, seed=11).requires_grad_(True)
    y = _rand(10, 3, seed=12).requires_grad_(True)
    g = torch.autograd.grad(L.chamfer_distance(x, y), (x, y))
    g0 = torch.autograd.grad(L.chamfer_distance_naive(x, y), (x, y))
    for a, b in zip(g, g0):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-14)


def test_a_kept_index_on_y_gives_the_same_distances_and_gradients():
    from nurbskit.core.neighbors import NeighborIndex

    x = _rand(40, 3, seed=21).requires_grad_(True)
    y = _rand(25, 3, seed=22).requires_grad_(True)
    index = NeighborIndex(y)
    for fn in (L.chamfer_distance, L.hausdorff_distance):
        want = fn(x, y)
        g_want = torch.autograd.grad(want, (x, y))
        for _ in range(2):  # the index is reused
            got = fn(x, y, y_index=index)
            assert got.item() == want.item()
            for a, b in zip(torch.autograd.grad(got, (x, y)), g_want):
                assert torch.equal(a, b)
    with pytest.raises(NurbskitError, match="built on y itself"):
        L.chamfer_distance(x, y[:20], y_index=index)
    with pytest.raises(NurbskitError, match="built on y itself"):
        L.chamfer_distance(x, y.detach().clone(), y_index=index)
    with pytest.raises(NurbskitError, match=r"x one \(N, D\) cloud"):
        L.chamfer_distance(x[None], y, y_index=index)


def test_chamfer_errors():
    with pytest.raises(NurbskitError, match="at least one point"):
        L.chamfer_distance(torch.rand(0, 3), torch.rand(4, 3))
    with pytest.raises(NurbskitError, match="reduction"):
        L.chamfer_distance(torch.rand(3, 3), torch.rand(4, 3), "none")
    with pytest.raises(NurbskitError, match="dimension"):
        L.chamfer_distance(torch.rand(3, 3), torch.rand(4, 2))


def test_chamfer_float32_follows_input():
    x, y = torch.rand(20, 3), torch.rand(30, 3)
    out = L.chamfer_distance(x, y)
    assert out.dtype == torch.float32
    assert out.item() == pytest.approx(L.chamfer_distance_naive(x.double(), y.double()).item(), rel=1e-5)


# ---- Hausdorff ----------------------------------------------------------------------

@pytest.mark.parametrize("n,m,d", [(1, 1, 3), (3, 8, 3), (20, 13, 3), (9, 25, 2)])
@pytest.mark.parametrize("squared", [False, True])
def test_hausdorff_matches_brute_force(n, m, d, squared):
    x, y = _rand(n, d, seed=n + 7), _rand(m, d, seed=200 + m)
    got = L.hausdorff_distance(x, y, squared=squared)
    torch.testing.assert_close(got, L.hausdorff_distance_naive(x, y, squared=squared), rtol=1e-13, atol=0)


def test_hausdorff_closed_form_and_parts():
    x = torch.tensor([[0.0, 0.0], [1.0, 0.0]], dtype=F64)
    y = torch.tensor([[0.0, 0.0], [1.0, 1.0], [3.0, 0.0]], dtype=F64)
    total, hx, hy = L.hausdorff_distance(x, y, return_parts=True)
    assert (total.item(), hx.item(), hy.item()) == (2.0, 1.0, 2.0)
    assert L.hausdorff_distance(x, y, squared=True).item() == 4.0


def test_hausdorff_gradcheck_and_zero_distance_gradient():
    x = _separated(10, 3, seed=13).requires_grad_(True)
    y = (_separated(14, 3, seed=14) + 0.01).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a, b: L.hausdorff_distance(a, b), (x, y))
    assert torch.autograd.gradcheck(lambda a, b: L.hausdorff_distance(a, b, squared=True), (x, y))
    z = _rand(5, 3, seed=15).requires_grad_(True)
    (g,) = torch.autograd.grad(L.hausdorff_distance(z, z.detach().clone()), (z,))
    assert torch.isfinite(g).all() and (g == 0).all()


def test_hausdorff_gradient_reaches_only_the_extreme_pair():
    x = torch.tensor([[0.0, 0.0], [1.0, 0.0]], dtype=F64, requires_grad=True)
    y = torch.tensor([[0.0, 0.0], [1.0, 1.0], [3.0, 0.0]], dtype=F64, requires_grad=True)
    gx, gy = torch.autograd.grad(L.hausdorff_distance(x, y), (x, y))
    # the maximum is |y_2 - x_1| = 2 along +x
    assert_close(gy, torch.tensor([[0, 0], [0, 0], [1.0, 0]], dtype=F64))
    assert_close(gx, torch.tensor([[0, 0], [-1.0, 0]], dtype=F64))


# ---- Laplacian ----------------------------------------------------------------------

def _param_grid(r, s, hu, hv, dtype=F64):
    u = torch.arange(r, dtype=dtype) * hu - 0.3
    v = torch.arange(s, dtype=dtype) * hv + 0.1
    return torch.meshgrid(u, v, indexing="ij")


@pytest.mark.parametrize("closed_u", [False, True])
@pytest.mark.parametrize("closed_v", [False, True])
def test_grid_laplacian_matches_loop(closed_u, closed_v):
    g = _rand(2, 6, 5, 3, seed=16)
    got = L.grid_laplacian(g, closed_u=closed_u, closed_v=closed_v)
    ref = torch.stack([L.grid_laplacian_naive(x, closed_u, closed_v) for x in g])
    torch.testing.assert_close(got, ref, rtol=0, atol=1e-15)
    interior = L.grid_laplacian(g, closed_u=closed_u, closed_v=closed_v, boundary="interior")
    iu = slice(None) if closed_u else slice(1, -1)
    iv = slice(None) if closed_v else slice(1, -1)
    torch.testing.assert_close(interior, ref[:, iu, iv], rtol=0, atol=1e-15)


def test_zeros_boundary_reproduces_splinenet_filter():
    g = _rand(7, 6, 3, seed=17)
    filt = -torch.tensor([[0.0, 0.25, 0.0], [0.25, -1.0, 0.25], [0.0, 0.25, 0.0]], dtype=F64)
    conv = F.conv2d(g.permute(2, 0, 1)[:, None], filt[None, None], padding=1)[:, 0].permute(1, 2, 0)
    # SplineNet's filter is the negated umbrella; the sign vanishes in every squared loss
    torch.testing.assert_close(L.grid_laplacian(g, boundary="zeros"), -conv, rtol=0, atol=1e-15)


@pytest.mark.parametrize("boundary", ["edge", "interior", "zeros"])
def test_laplacian_of_planar_regular_grid_is_zero_inside(boundary):
    u, v = _param_grid(6, 7, 0.3, 0.17)
    plane = torch.stack([u, v, 2.0 * u - 0.5 * v + 3.0], -1)
    lap = L.grid_laplacian(plane, boundary=boundary)
    inner = lap if boundary == "interior" else lap[1:-1, 1:-1]
    assert inner.abs().max().item() < 1e-14
    if boundary == "edge":  # the edge rule keeps affine grids at zero on the boundary too
        assert lap.abs().max().item() < 1e-14
    if boundary == "zeros":  # zero padding does not: it pulls edges towards the origin
        assert lap.abs().max().item() > 0.1


def test_laplacian_of_paraboloid_closed_form():
    a, b, hu, hv = 0.7, -1.3, 0.2, 0.35
    u, v = _param_grid(6, 5, hu, hv)
    grid = torch.stack([u, v, a * u**2 + b * v**2], -1)
    lap = L.grid_laplacian(grid)
    # interior: mean of the 4 neighbours minus the point = (a hu^2 + b hv^2) / 2 in z
    assert_close(lap[1:-1, 1:-1, 2], torch.full((4, 3), (a * hu**2 + b * hv**2) / 2, dtype=F64))
    assert lap[..., :2].abs().max().item() < 1e-15
    # edge rule: only the along-edge second difference, halved; corners 0
    assert_close(lap[0, 1:-1, 2], torch.full((3,), b * hv**2 / 2, dtype=F64))
    assert_close(lap[1:-1, -1, 2], torch.full((4,), a * hu**2 / 2, dtype=F64))
    assert lap[0, 0].abs().max().item() < 1e-15
    # the energy: mean over nodes of |L|^2
    expected = (lap**2).sum(-1).mean()
    assert_close(L.laplacian_grid(grid), expected)
    assert_close(L.laplacian_grid(grid, "sum"), expected * 30)


def test_closed_u_wraps_the_seam_of_a_cylinder():
    r = 12
    theta = torch.arange(r, dtype=F64) * (2 * math.pi / r)  # seam not repeated
    z = torch.linspace(0, 1, 5, dtype=F64)
    t, zz = torch.meshgrid(theta, z, indexing="ij")
    grid = torch.stack([2 * torch.cos(t), 2 * torch.sin(t), zz], -1)
    lap = L.grid_laplacian(grid, closed_u=True)
    # on a circle (p_prev + p_next)/2 - p = (cos(dt) - 1) p (radial); halved by the umbrella
    expected = grid.clone()
    expected[..., 2] = 0
    expected = 0.5 * (math.cos(2 * math.pi / r) - 1) * expected
    torch.testing.assert_close(lap, expected, rtol=0, atol=1e-14)
    # open in u, the seam rows only see the v term
    assert L.grid_laplacian(grid)[0].abs().max().item() < 1e-14


def test_laplacian_gradchecks():
    g = _rand(5, 4, 3, seed=18).requires_grad_(True)
    t = _rand(5, 4, 3, seed=19)
    for boundary in ("edge", "interior", "zeros"):
        assert torch.autograd.gradcheck(lambda a: L.laplacian_grid(a, boundary=boundary), (g,))
        assert torch.autograd.gradcheck(lambda a: L.laplacian_control(a, boundary=boundary, closed_u=True), (g,))
        assert torch.autograd.gradcheck(lambda a: L.laplacian_supervised(a, t, boundary=boundary), (g,))


def test_supervised_is_energy_of_difference_and_translation_invariant():
    p, t = _rand(2, 5, 6, 3, seed=20), _rand(2, 5, 6, 3, seed=21)
    assert_close(L.laplacian_supervised(p, t), L.laplacian_grid(p - t))
    assert L.laplacian_supervised(p, t).shape == (2,)
    shift = torch.tensor([1.0, -2.0, 0.5], dtype=F64)
    assert L.laplacian_supervised(t + shift, t).abs().max().item() < 1e-28
    # the thesis's zero padding is not translation invariant
    assert L.laplacian_supervised(t + shift, t, boundary="zeros").min().item() > 0.01
    with pytest.raises(NurbskitError, match="same shape"):
        L.laplacian_supervised(p, t[:, :4])


def test_laplacian_control_accepts_a_surface():
    cp = _rand(5, 6, 3, seed=22)
    s = NURBSSurface(cp, degrees=(3, 2))
    assert_close(L.laplacian_control(s), L.laplacian_grid(cp))


def test_laplacian_errors():
    with pytest.raises(NurbskitError, match="boundary"):
        L.grid_laplacian(torch.rand(4, 4, 3), boundary="reflect")
    with pytest.raises(NurbskitError, match="interior"):
        L.grid_laplacian(torch.rand(2, 4, 3), boundary="interior")
    with pytest.raises(NurbskitError, match=r"\(\*, R, S, D\)"):
        L.laplacian_grid(torch.rand(4, 3))


# ---- point to surface ---------------------------------------------------------------

def _plane(n=4, degree=3):
    g = torch.linspace(0, 1, n, dtype=F64)
    u, v = torch.meshgrid(g, g, indexing="ij")
    return NURBSSurface(torch.stack([u, v, torch.zeros_like(u)], -1), degrees=(degree, degree))


def _sphere_octant(radius=1.0):
    """Exact rational patch of the unit sphere with x, y, z >= 0 (a revolved quarter circle)."""
    w = math.sqrt(0.5)
    arc = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=F64)  # (r, z) and (cos, sin)
    aw = torch.tensor([1.0, w, 1.0], dtype=F64)
    cp = torch.empty(3, 3, 3, dtype=F64)
    for i in range(3):
        for j in range(3):
            cp[i, j] = radius * torch.stack([arc[i, 0] * arc[j, 0], arc[i, 0] * arc[j, 1], arc[i, 1]])
    return NURBSSurface(cp, degrees=(2, 2), weights=aw[:, None] * aw[None, :])


def test_point_to_surface_plane_closed_form():
    plane = _plane()
    g = torch.Generator().manual_seed(23)
    xy = 0.1 + 0.8 * torch.rand(40, 2, generator=g, dtype=F64)
    h = torch.randn(40, generator=g, dtype=F64)
    pts = torch.cat([xy, h[:, None]], -1)
    assert_close(L.point_to_surface_distance(plane, pts), (h**2).mean())
    assert_close(L.point_to_surface_distance(plane, pts, squared=False), h.abs().mean())
    assert_close(L.point_to_surface_distance(plane, pts, "none", squared=False), h.abs())


def _octant_points(n, seed):
    g = torch.Generator().manual_seed(seed)
    az = 0.2 + 1.1 * torch.rand(n, generator=g, dtype=F64)
    el = 0.2 + 1.0 * torch.rand(n, generator=g, dtype=F64)
    rho = 0.5 + torch.rand(n, generator=g, dtype=F64)
    direction = torch.stack([torch.cos(el) * torch.cos(az), torch.cos(el) * torch.sin(az), torch.sin(el)], -1)
    return rho[:, None] * direction, rho, direction


def test_point_to_surface_sphere_closed_form_and_point_gradient():
    sphere = _sphere_octant()
    pts, rho, direction = _octant_points(30, seed=24)
    assert_close(L.point_to_surface_distance(sphere, pts, "none", squared=False), (rho - 1).abs())
    pts.requires_grad_(True)
    (g,) = torch.autograd.grad(L.point_to_surface_distance(sphere, pts, "sum"), (pts,))
    assert_close(g, 2 * (rho - 1)[:, None] * direction)


def test_point_to_surface_control_point_gradient_is_the_envelope_gradient():
    # d/de of the re-projected distance (finite differences) must equal autograd's
    # gradient at fixed foot points: the envelope theorem.
    base = _sphere_octant()
    pts, _, _ = _octant_points(12, seed=25)
    cp = base.control_points.clone().requires_grad_(True)
    surface = NURBSSurface(cp, degrees=(2, 2), weights=base.weights)
    (grad,) = torch.autograd.grad(L.point_to_surface_distance(surface, pts), (cp,))
    direction = _rand(3, 3, 3, seed=26) - 0.5
    eps = 1e-6

    def at(e):
        s = NURBSSurface(base.control_points + e * direction, degrees=(2, 2), weights=base.weights)
        return L.point_to_surface_distance(s, pts).item()

    fd = (at(eps) - at(-eps)) / (2 * eps)
    assert (grad * direction).sum().item() == pytest.approx(fd, rel=1e-6, abs=1e-10)


# ---- modules ------------------------------------------------------------------------

def test_modules_match_functions():
    x, y = _rand(9, 3, seed=27), _rand(9, 3, seed=28)
    g, t = _rand(4, 5, 3, seed=29), _rand(4, 5, 3, seed=30)
    assert L.L2Loss("sum")(x, y) == L.l2_loss(x, y, "sum")
    assert L.ChamferLoss()(x, y) == L.chamfer_distance(x, y)
    assert L.HausdorffLoss(squared=True)(x, y) == L.hausdorff_distance(x, y, squared=True)
    assert L.LaplacianLoss("grid", closed_u=True)(g) == L.laplacian_grid(g, closed_u=True)
    assert L.LaplacianLoss("control", boundary="zeros")(g) == L.laplacian_control(g, boundary="zeros")
    assert L.LaplacianLoss("supervised")(g, t) == L.laplacian_supervised(g, t)
    plane = _plane()
    pts = _rand(6, 3, seed=31)
    assert L.PointToSurfaceLoss(squared=False, iterations=16)(plane, pts) == L.point_to_surface_distance(
        plane, pts, squared=False, iterations=16
    )
    assert list(L.ChamferLoss().parameters()) == []


def test_module_errors():
    with pytest.raises(NurbskitError, match="mode"):
        L.LaplacianLoss("smooth")
    with pytest.raises(NurbskitError, match="target"):
        L.LaplacianLoss("supervised")(torch.rand(4, 4, 3))
    with pytest.raises(NurbskitError, match="no target"):
        L.LaplacianLoss("grid")(torch.rand(4, 4, 3), torch.rand(4, 4, 3))
    with pytest.raises(NurbskitError, match="reduction"):
        L.ChamferLoss("none")


def test_docstring_examples_run():
    import doctest

    assert doctest.testmod(L, raise_on_error=False).failed == 0


# ---- batches and host reads -------------------------------------------------------------

def test_chamfer_and_hausdorff_broadcast_one_cloud_against_a_batch():
    x, y = _rand(2, 3, 12, 3, seed=40), _rand(9, 3, seed=41)
    out = L.chamfer_distance(x, y)
    hd = L.hausdorff_distance(x, y)
    assert out.shape == (2, 3) and hd.shape == (2, 3)
    for a in range(2):
        for b in range(3):
            assert_close(out[a, b], L.chamfer_distance_naive(x[a, b], y), atol=1e-15)
            assert_close(hd[a, b], L.hausdorff_distance_naive(x[a, b], y), atol=1e-15)
    with pytest.raises(NurbskitError, match="do not broadcast"):
        L.chamfer_distance(_rand(2, 5, 3), _rand(3, 5, 3))


def test_chamfer_reads_nothing_back_to_the_host():
    from nurbskit._opcount import OperationCounter

    x = _rand(4, 300, 3, seed=42).requires_grad_(True)
    y = _rand(4, 200, 3, seed=43)
    with OperationCounter() as count:
        loss = L.chamfer_distance(x, y).sum()
        loss.backward()
    assert count.host_reads == 0, count.host_read_names()
    assert count.operations < 200  # a handful per batch element, not per point


def test_point_to_surface_on_batched_points_equals_a_loop():
    sphere = _sphere_octant()
    pts, _, _ = _octant_points(24, seed=44)
    batched = L.point_to_surface_distance(sphere, pts.reshape(3, 8, 3), "none")
    assert batched.shape == (3, 8)
    for b in range(3):
        assert_close(batched[b], L.point_to_surface_distance(sphere, pts.reshape(3, 8, 3)[b], "none"), atol=0)
