"""Point projection (core.project) against closed forms, a dense-sampling oracle and
finite differences.

The exact surfaces are rational quadratic: the octant of the unit sphere (tensor product
of two rational quarter circles, a surface of revolution) and a quarter of a cylinder.
For both, the closest point of the *patch* to any point of space has a closed form:

* octant: maximise ``p . q`` over unit ``q >= 0``: ``q = p_+ / |p_+|`` where the positive
  part ``p_+`` is non-zero, else the axis vertex ``e_i`` with the largest ``p_i``;
* quarter cylinder ``(R cos t, R sin t, z)``, ``t in [0, pi/2]``, ``z in [z0, z1]``: the
  same rule in ``(x, y)`` on the quarter circle, and ``z`` clamped.

So points beyond the edges (foot point on a boundary curve) and beyond the corners
(a corner) are covered by the same formulas.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from _assert import assert_close

from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume, NurbskitError
from nurbskit.core.project import nearest_grid_params, project_points, project_points_curve

F64 = torch.float64
S2 = 2 ** -0.5
ARC = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=F64)  # rational quarter circle
ARC_W = torch.tensor([1.0, S2, 1.0], dtype=F64)


def sphere_octant() -> NURBSSurface:
    """Unit sphere, x, y, z >= 0: u is the longitude (0 at +x), v the latitude (1 at the pole)."""
    cp = torch.empty(3, 3, 3, dtype=F64)
    for i in range(3):
        for j in range(3):
            r, z = ARC[j]
            cp[i, j] = torch.stack([r * ARC[i, 0], r * ARC[i, 1], z])
    return NURBSSurface(cp, degrees=(2, 2), weights=ARC_W[:, None] * ARC_W[None, :])


RADIUS, Z0, Z1 = 2.0, 0.5, 3.5
U_DOM, V_DOM = (-1.0, 2.0), (0.0, 4.0)


def cylinder_quarter() -> NURBSSurface:
    """``(2 cos t, 2 sin t, z)``, ``t in [0, pi/2]``, ``z in [0.5, 3.5]`` on the domain [-1, 2] x [0, 4]."""
    cp = torch.empty(3, 2, 3, dtype=F64)
    for i in range(3):
        for j, z in enumerate((Z0, Z1)):
            cp[i, j] = torch.tensor([RADIUS * ARC[i, 0], RADIUS * ARC[i, 1], z], dtype=F64)
    a, b = U_DOM
    c, d = V_DOM
    kv = [torch.tensor([a, a, a, b, b, b], dtype=F64), torch.tensor([c, c, d, d], dtype=F64)]
    return NURBSSurface(cp, degrees=(2, 1), knot_vectors=kv, weights=ARC_W[:, None].expand(3, 2).clone())


def _closest_on_quarter(p: torch.Tensor) -> torch.Tensor:
    """Closest point of the unit quarter sphere/circle ``{q >= 0, |q| = 1}`` to ``p (N, k)``."""
    pos = p.clamp_min(0)
    norm = pos.norm(dim=-1, keepdim=True)
    vertex = torch.nn.functional.one_hot(p.argmax(dim=-1), p.shape[-1]).to(p.dtype)
    return torch.where(norm > 0, pos / norm.clamp_min(1e-300), vertex)


def sphere_closest(p: torch.Tensor) -> torch.Tensor:
    return _closest_on_quarter(p)


def cylinder_closest(p: torch.Tensor) -> torch.Tensor:
    xy = RADIUS * _closest_on_quarter(p[:, :2])
    return torch.cat([xy, p[:, 2:].clamp(Z0, Z1)], dim=-1)


def smooth_height_field(seed: int = 0, n=(6, 5), degrees=(3, 2)) -> NURBSSurface:
    """A gently curved rational height field on [0, 2] x [-1, 1] (unique foot points near it)."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0, 2, n[0])
    v = np.linspace(-1, 1, n[1])
    cp = np.stack([*np.meshgrid(u, v, indexing="ij"), 0.15 * rng.normal(size=n)], axis=-1)
    w = rng.uniform(0.7, 1.4, size=n)
    kv = [
        torch.tensor(np.r_[[0.0] * degrees[0], np.linspace(0, 2, n[0] - degrees[0] + 1), [2.0] * degrees[0]], dtype=F64),
        torch.tensor(np.r_[[-1.0] * degrees[1], np.linspace(-1, 1, n[1] - degrees[1] + 1), [1.0] * degrees[1]], dtype=F64),
    ]
    return NURBSSurface(torch.tensor(cp, dtype=F64), degrees=degrees, knot_vectors=kv, weights=torch.tensor(w, dtype=F64))


# ---- closed forms -----------------------------------------------------------------------
def test_sphere_octant_is_exact():
    s = sphere_octant()
    uv = torch.rand(200, 2, dtype=F64, generator=torch.Generator().manual_seed(0))
    assert_close(s.evaluate(uv).norm(dim=-1), torch.ones(200, dtype=F64), atol=1e-14)


def test_sphere_points_above_and_below_the_patch():
    g = torch.Generator().manual_seed(1)
    d = torch.randn(1500, 3, dtype=F64, generator=g).abs()
    d = d / d.norm(dim=-1, keepdim=True)
    rho = 0.2 + 2.8 * torch.rand(1500, dtype=F64, generator=g)
    params, closest, distance = project_points(sphere_octant(), d * rho[:, None])
    assert params.shape == (1500, 2) and closest.shape == (1500, 3) and distance.shape == (1500,)
    assert_close(distance, (rho - 1).abs(), atol=1e-9)
    assert_close(closest, d, atol=1e-9)
    assert (params >= 0).all() and (params <= 1).all()


def test_sphere_any_point_of_space_edges_corners_and_pole():
    # Most of these points lie beyond an edge or a corner of the octant, or have the pole
    # (where the parametrisation degenerates) as their foot point.
    g = torch.Generator().manual_seed(2)
    p = 1.5 * torch.randn(3000, 3, dtype=F64, generator=g)
    _, closest, distance = project_points(sphere_octant(), p)
    q = sphere_closest(p)
    assert_close(distance, (p - q).norm(dim=-1), atol=1e-9)
    assert_close(closest, q, atol=1e-7)  # foot point: first order in the distance error


def test_sphere_boundary_curves_closed_form():
    # y < 0: the foot point lies on the meridian u = 0 (the y = 0 edge), at (x, 0, z) / |(x, 0, z)|.
    g = torch.Generator().manual_seed(3)
    p = torch.rand(400, 3, dtype=F64, generator=g) * torch.tensor([2.0, -2.0, 2.0], dtype=F64) + torch.tensor([0.05, -0.01, 0.05], dtype=F64)
    params, closest, distance = project_points(sphere_octant(), p)
    q = p * torch.tensor([1.0, 0.0, 1.0], dtype=F64)
    q = q / q.norm(dim=-1, keepdim=True)
    assert_close(params[:, 0], torch.zeros(400, dtype=F64), atol=0)  # held exactly on the edge
    assert_close(closest, q, atol=1e-9)
    assert_close(distance, (p - q).norm(dim=-1), atol=1e-9)
    # z < 0, x, y > 0: the foot point is on the equator v = 0.
    p = p * torch.tensor([1.0, -1.0, -1.0], dtype=F64)
    params, closest, _ = project_points(sphere_octant(), p)
    q = p * torch.tensor([1.0, 1.0, 0.0], dtype=F64)
    assert torch.equal(params[:, 1], torch.zeros(400, dtype=F64))
    assert_close(closest, q / q.norm(dim=-1, keepdim=True), atol=1e-9)


def test_cylinder_radial_distance_and_outside_points():
    g = torch.Generator().manual_seed(4)
    n = 1500
    theta = torch.rand(n, dtype=F64, generator=g) * math.pi / 2
    rho = 0.3 + 3.7 * torch.rand(n, dtype=F64, generator=g)
    z = Z0 + (Z1 - Z0) * torch.rand(n, dtype=F64, generator=g)
    p = torch.stack([rho * theta.cos(), rho * theta.sin(), z], dim=-1)
    params, closest, distance = project_points(cylinder_quarter(), p)
    assert_close(distance, (rho - RADIUS).abs(), atol=1e-9)
    assert_close(closest, torch.stack([RADIUS * theta.cos(), RADIUS * theta.sin(), z], -1), atol=1e-9)
    # v is linear in z on this patch: z = Z0 + (Z1 - Z0) * (v - 0) / 4
    assert_close(params[:, 1], (z - Z0) / (Z1 - Z0) * V_DOM[1], atol=1e-9)
    assert ((params[:, 0] >= U_DOM[0]) & (params[:, 0] <= U_DOM[1])).all()
    # anywhere in space: beyond the top, bottom and side edges, and the corners
    p = torch.randn(3000, 3, dtype=F64, generator=g) * torch.tensor([3.0, 3.0, 3.0], dtype=F64) + torch.tensor([0, 0, 2.0], dtype=F64)
    params, closest, distance = project_points(cylinder_quarter(), p)
    q = cylinder_closest(p)
    assert_close(distance, (p - q).norm(dim=-1), atol=1e-9)
    assert_close(closest, q, atol=1e-7)
    assert ((params >= torch.tensor([U_DOM[0], V_DOM[0]], dtype=F64)) & (params <= torch.tensor([U_DOM[1], V_DOM[1]], dtype=F64))).all()


def test_points_on_the_surface_recover_their_parameters():
    s = smooth_height_field()
    g = torch.Generator().manual_seed(5)
    uv = torch.rand(500, 2, dtype=F64, generator=g) * torch.tensor([2.0, 2.0], dtype=F64) + torch.tensor([0.0, -1.0], dtype=F64)
    edges = torch.tensor([[0, -1], [2, -1], [0, 1], [2, 1], [0, 0.3], [2, -0.4], [1.1, -1], [0.7, 1]], dtype=F64)
    uv = torch.cat([edges, uv])
    params, closest, distance = project_points(s, s.evaluate(uv))
    assert distance.max() < 1e-12
    assert_close(params, uv, atol=1e-9)
    on_edge = (edges == edges.amin(0)) | (edges == edges.amax(0))
    # the gradient vanishes on the surface, so an edge parameter may move by rounding only
    assert_close(params[:8][on_edge], edges[on_edge], atol=1e-13)


def test_never_worse_than_dense_sampling():
    # Oracle: the nearest of 500 x 500 samples (a KD-tree). Newton from the nearest grid
    # sample finds the minimum of that sample's basin; for points far above a curved
    # surface another basin can be (slightly) better, which more starts catch.
    from scipy.spatial import cKDTree

    s = smooth_height_field(seed=6)
    g = torch.Generator().manual_seed(6)
    p = torch.rand(1000, 3, dtype=F64, generator=g) * torch.tensor([3.0, 3.0, 1.0], dtype=F64) - torch.tensor([0.5, 1.5, 0.5], dtype=F64)
    dense = s.sample(500).reshape(-1, 3).numpy()
    oracle = torch.as_tensor(cKDTree(dense).query(p.numpy())[0])
    one = project_points(s, p).distance
    four = project_points(s, p, starts=4).distance
    assert (four <= oracle + 1e-12).all()
    assert (four <= one + 1e-12).all()
    assert (one <= oracle + 1e-12).float().mean() > 0.99
    assert (oracle - four).max() < 1e-2  # and the oracle is not far off either (500 samples)


# ---- gradients --------------------------------------------------------------------------
def _fd_check(make, tensor, points, eps=1e-6, entries=None):
    """Central differences of sum(distance^2) in each entry of ``tensor``, re-projecting each time."""
    base = tensor.detach().clone()
    flat_idx = range(base.numel()) if entries is None else entries
    out = []
    for i in flat_idx:
        vals = []
        for sign in (1, -1):
            t = base.clone().reshape(-1)
            t[i] += sign * eps
            vals.append(float(project_points(make(t.reshape(base.shape)), points).distance.square().sum()))
        out.append((vals[0] - vals[1]) / (2 * eps))
    return torch.tensor(out, dtype=F64)


def test_envelope_gradient_matches_finite_differences():
    s0 = smooth_height_field(seed=7, n=(4, 4), degrees=(2, 3))
    g = torch.Generator().manual_seed(7)
    # inside, above/below, and beyond the edges (boundary foot points)
    p = torch.rand(24, 3, dtype=F64, generator=g) * torch.tensor([2.6, 2.6, 0.8], dtype=F64) - torch.tensor([0.3, 1.3, 0.4], dtype=F64)
    p.requires_grad_(True)
    cp = s0.control_points.clone().requires_grad_(True)
    w = s0.weights.clone().requires_grad_(True)
    s = NURBSSurface(cp, s0.degrees, s0.knot_vectors, w)
    _, closest, distance = project_points(s, p)
    distance.square().sum().backward()

    # a spread of entries (every third coordinate, every other weight) keeps the test short
    cp_entries, w_entries = list(range(0, 48, 3)), list(range(0, 16, 2))
    fd_cp = _fd_check(lambda c: NURBSSurface(c, s0.degrees, s0.knot_vectors, s0.weights), cp, p.detach(), entries=cp_entries)
    assert_close(cp.grad.reshape(-1)[cp_entries], fd_cp, rtol=1e-5, atol=1e-7)
    fd_w = _fd_check(lambda ww: NURBSSurface(s0.control_points, s0.degrees, s0.knot_vectors, ww), w, p.detach(), entries=w_entries)
    assert_close(w.grad.reshape(-1)[w_entries], fd_w, rtol=1e-5, atol=1e-7)
    # gradient w.r.t. the points: d/dp |p - c|^2 = 2 (p - c) with the foot point fixed
    assert_close(p.grad, 2 * (p.detach() - closest.detach()), atol=1e-12)


def test_envelope_gradient_in_an_interior_knot():
    s0 = smooth_height_field(seed=8, n=(5, 4), degrees=(2, 2))
    g = torch.Generator().manual_seed(8)
    p = torch.rand(20, 3, dtype=F64, generator=g) * torch.tensor([2.0, 2.0, 0.6], dtype=F64) - torch.tensor([0.0, 1.0, 0.3], dtype=F64)
    kv = s0.knot_vectors[0].clone().requires_grad_(True)
    s = NURBSSurface(s0.control_points, s0.degrees, [kv, s0.knot_vectors[1]], s0.weights)
    project_points(s, p).distance.square().sum().backward()
    interior = [3, 4]  # [0, 0, 0, k3, k4, 2, 2, 2]
    fd = _fd_check(lambda k: NURBSSurface(s0.control_points, s0.degrees, [k, s0.knot_vectors[1]], s0.weights), kv, p, entries=interior)
    assert_close(kv.grad[interior], fd, rtol=1e-5, atol=1e-7)


def test_gradcheck_distance_in_points_and_control_points():
    s0 = sphere_octant()
    p = torch.tensor([[0.5, 0.6, 0.9], [2.0, -0.5, 0.3], [0.1, 0.2, -1.0]], dtype=F64, requires_grad=True)
    cp = s0.control_points.clone().requires_grad_(True)

    def fn(points, control_points):
        return project_points(NURBSSurface(control_points, (2, 2), None, s0.weights), points).distance

    assert torch.autograd.gradcheck(fn, (p, cp), eps=1e-6, atol=1e-6, fast_mode=True)


# ---- curves -----------------------------------------------------------------------------
def quarter_circle(a=0.0, b=1.0) -> NURBSCurve:
    return NURBSCurve(ARC.clone(), degree=2, knot_vector=torch.tensor([a, a, a, b, b, b], dtype=F64), weights=ARC_W)


def test_curve_quarter_circle_closed_form():
    g = torch.Generator().manual_seed(9)
    p = 2 * torch.randn(2000, 2, dtype=F64, generator=g)
    params, closest, distance = project_points_curve(quarter_circle(-2.0, 3.0), p)
    q = _closest_on_quarter(p)
    assert params.shape == (2000,) and closest.shape == (2000, 2)
    assert_close(distance, (p - q).norm(dim=-1), atol=1e-9)
    assert_close(closest, q, atol=1e-7)
    assert ((params >= -2) & (params <= 3)).all()
    # beyond the ends: exactly the end parameters
    ends = project_points_curve(quarter_circle(-2.0, 3.0), torch.tensor([[3.0, -1.0], [-1.0, 3.0]], dtype=F64)).params
    assert ends.tolist() == [-2.0, 3.0]


def test_curve_in_3d_gradient_and_project_points_accepts_curves():
    rng = np.random.default_rng(10)
    cp = torch.tensor(np.cumsum(rng.normal(size=(6, 3)), axis=0), dtype=F64, requires_grad=True)
    c = NURBSCurve(cp, degree=3, weights=torch.tensor(rng.uniform(0.6, 1.5, 6), dtype=F64))
    p = torch.tensor(rng.normal(size=(15, 3)), dtype=F64) + cp.detach().mean(0)
    res = project_points(c, p)
    assert torch.equal(res.params, project_points_curve(c, p).params)
    dense = c.evaluate(torch.linspace(0, 1, 200001, dtype=F64))
    assert (res.distance.detach() <= torch.cdist(p, dense).min(1).values + 1e-12).all()
    res.distance.square().sum().backward()
    fd = _fd_check(lambda x: NURBSCurve(x, 3, None, c.weights), cp, p)
    assert_close(cp.grad.reshape(-1), fd, rtol=1e-5, atol=1e-7)


# ---- conventions ------------------------------------------------------------------------
def test_batch_dims_dtype_and_empty():
    s = cylinder_quarter()
    p = torch.randn(2, 5, 3, dtype=F64)
    params, closest, distance = project_points(s, p)
    assert params.shape == (2, 5, 2) and closest.shape == (2, 5, 3) and distance.shape == (2, 5)
    flat = project_points(s, p.reshape(10, 3))
    assert_close(distance.reshape(-1), flat.distance, atol=1e-12)
    empty = project_points(s, torch.zeros(0, 3, dtype=F64))
    assert empty.params.shape == (0, 2) and empty.distance.shape == (0,)
    # float32 follows the surface and stays close to the float64 answer
    s32 = s.to(torch.float32)
    r32 = project_points(s32, p.reshape(10, 3))
    assert r32.distance.dtype == torch.float32 and r32.params.dtype == torch.float32
    assert_close(r32.distance.double(), flat.distance, atol=1e-4)


def test_grid_start_is_the_nearest_sample():
    s = cylinder_quarter()
    p = torch.tensor([[2.0, 0.0, 0.5], [0.0, 2.0, 3.5]], dtype=F64)  # two corners of the patch
    assert nearest_grid_params(s, p, grid=5).tolist() == [[-1.0, 0.0], [2.0, 4.0]]
    # an explicit coarse grid still converges (Newton does the rest)
    assert_close(project_points(s, p + 0.1, grid=2).distance, project_points(s, p + 0.1).distance, atol=1e-12)


def test_errors_name_the_problem():
    s = cylinder_quarter()
    with pytest.raises(NurbskitError, match=r"\(\.\.\., N, 3\).*got \(4, 2\)"):
        project_points(s, torch.zeros(4, 2, dtype=F64))
    with pytest.raises(NurbskitError, match="NaN"):
        project_points(s, torch.tensor([[float("nan"), 0, 0]], dtype=F64))
    with pytest.raises(NurbskitError, match="grid must be 2"):
        project_points(s, torch.zeros(1, 3, dtype=F64), grid=(8,))
    with pytest.raises(NurbskitError, match="NURBSVolume"):
        project_points(NURBSVolume(torch.rand(2, 2, 2, 3, dtype=F64), degrees=(1, 1, 1)), torch.zeros(1, 3, dtype=F64))
    with pytest.raises(NurbskitError, match="NURBSCurve"):
        project_points_curve(s, torch.zeros(1, 3, dtype=F64))


def test_nearest_sample_kdtree_and_cdist_agree():
    # the KD-tree serves CPU tensors, tiled exact distances the accelerators: same answers
    from nurbskit.core import neighbors

    g = torch.Generator().manual_seed(14)
    samples = torch.rand(500, 3, dtype=F64, generator=g)
    points = torch.rand(300, 3, dtype=F64, generator=g)
    by_tree = neighbors.k_nearest(points, samples, 3)
    by_cdist = neighbors._index_cdist(points, samples, chunk_bytes=64 * 500 * 8, count=3)
    assert torch.equal(by_tree, by_cdist)
    assert torch.equal(by_tree[:, 0], torch.cdist(points, samples).argmin(dim=1))


def test_zero_distance_has_finite_gradients():
    # points exactly on the surface: |x - S| is not differentiable at 0; the gradient
    # must still be finite (torch's norm takes the zero subgradient there)
    s0 = cylinder_quarter()
    cp = s0.control_points.clone().requires_grad_(True)
    s = NURBSSurface(cp, s0.degrees, s0.knot_vectors, s0.weights)
    p = s0.evaluate(torch.tensor([[0.0, 1.0], [1.5, 4.0]], dtype=F64)).requires_grad_(True)
    distance = project_points(s, p).distance
    assert distance.max() < 1e-14
    distance.sum().backward()
    assert torch.isfinite(cp.grad).all() and torch.isfinite(p.grad).all()


# ---- periodic directions ------------------------------------------------------------------
def closed_cylinder(radius: float = RADIUS, z0: float = Z0, z1: float = Z1) -> NURBSSurface:
    """An exact closed cylinder: v is a rational *periodic* circle (degree 2, double knots,
    periodic spacing, the last two control columns repeating the first two), u is z.

    The circle's polygon alternates square midpoints (weight 1) and corners (weight
    1/sqrt(2)), so every span is an exact rational quarter circle; the seam ``v = 0 = 1``
    is the point ``(radius, 0)``.
    """
    R = radius
    ring = [(R, 0), (R, R), (0, R), (-R, R), (-R, 0), (-R, -R), (0, -R), (R, -R)]
    ring = ring + ring[:2]
    w = torch.tensor([1.0, S2] * 5, dtype=F64)
    cp = torch.tensor([[[x, y, z] for x, y in ring] for z in (z0, z1)], dtype=F64)  # (2, 10, 3)
    kv_v = torch.tensor([-0.25, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1.25, 1.25], dtype=F64)
    kv_u = torch.tensor([0.0, 0.0, 1.0, 1.0], dtype=F64)
    return NURBSSurface(cp, degrees=(1, 2), knot_vectors=[kv_u, kv_v], weights=w[None, :].expand(2, 10).clone())


def _seam_points():
    """1,701 points around the seam: 81 angles in [-0.3, 0.3] rad x 21 radii, inside the z range."""
    theta = torch.linspace(-0.3, 0.3, 81, dtype=F64)
    rho = torch.linspace(0.3, 3.0, 21, dtype=F64) * RADIUS
    t, r = torch.meshgrid(theta, rho, indexing="ij")
    z = Z0 + (Z1 - Z0) * (0.5 + 0.4 * torch.sin(7 * t + 3 * r))
    return torch.stack([r * torch.cos(t), r * torch.sin(t), z], -1).reshape(-1, 3), (r - RADIUS).abs().reshape(-1)


def test_closed_cylinder_is_exact_and_periodic():
    s = closed_cylinder()
    v = torch.linspace(0, 1, 101, dtype=F64)
    pts = s.evaluate(torch.stack([torch.full_like(v, 0.3), v], -1))
    assert_close(pts[:, :2].norm(dim=-1), torch.full_like(v, RADIUS), atol=1e-14)
    from nurbskit.core.project import periodic_directions

    assert periodic_directions(s) == (False, True)
    assert periodic_directions(cylinder_quarter()) == (False, False)


def test_projection_across_a_periodic_seam_is_exact():
    # Points on both sides of the seam of an exact closed cylinder: the distance is
    # |rho - R| in closed form. Without periodic directions, Newton stops at the domain
    # edge v = 0 or v = 1 and returns the seam point instead of the foot point (before the
    # fix 801 of these 1,701 points came back up to 8.8e-2 off).
    s = closed_cylinder()
    p, truth = _seam_points()
    res = project_points(s, p)
    assert_close(res.distance, truth, atol=1e-12)
    # the foot point is the radial one: same angle, same z
    foot = res.closest
    assert_close(foot[:, 2], p[:, 2], atol=1e-12)
    assert_close(torch.atan2(foot[:, 1], foot[:, 0]), torch.atan2(p[:, 1], p[:, 0]), atol=1e-12)
    # the parameters stay in the knot domain, and saying it explicitly gives the same answer
    assert bool((res.params[:, 1] >= 0).all() and (res.params[:, 1] <= 1).all())
    said = project_points(s, p, periodic=(False, True))
    assert torch.equal(said.params, res.params)
    # float32: the same points to float32 rounding
    r32 = project_points(s.to(torch.float32), p.float())
    assert_close(r32.distance, truth.float(), atol=2e-6)


# ---- host reads, batches, warm starts ------------------------------------------------------
def test_warm_projection_in_a_loop_reads_nothing_back():
    from nurbskit._opcount import OperationCounter

    s = closed_cylinder()
    p, truth = _seam_points()
    first = project_points(s, p)
    with OperationCounter() as count:
        warm = project_points(s, p, params=first.params, periodic=(False, True), iterations=3, check_every=0,
                              validate=False)
    assert count.host_reads == 0, count.host_read_names()
    assert_close(warm.distance, truth, atol=1e-12)
    # the default call reads a bounded number of values, independent of the number of points
    with OperationCounter() as small:
        project_points(s, p[:100])
    with OperationCounter() as large:
        project_points(s, p)
    assert small.host_reads <= 40 and large.host_reads <= 40


def test_warm_start_and_restart():
    s = cylinder_quarter()
    g = torch.Generator().manual_seed(50)
    p = torch.rand(200, 3, dtype=F64, generator=g) * 3
    cold = project_points(s, p)
    # a warm start at the answer stays there; a bad warm start with restart recovers it
    assert_close(project_points(s, p, params=cold.params).distance, cold.distance, atol=1e-12)
    bad = torch.full_like(cold.params, 0.5)
    fixed = project_points(s, p, params=bad, restart=True)
    assert_close(fixed.distance, cold.distance, atol=1e-12)


def _batched(spline, cps, ws, kvs=None):
    """A batched spline object: control points ``(*B, ...)``, knots shared or per element."""
    return spline._replace(control_points=cps, weights=ws, knot_vectors=kvs or list(spline.knot_vectors))


def _each_alone(batch, points, params=None, **options):
    """The oracle of a batch: ``project_points`` on every element alone, stacked."""
    out = []
    for index in np.ndindex(batch.batch_shape):
        warm = None if params is None else params[index]
        out.append(project_points(batch[index], points[index], params=warm, **options))
    return [torch.stack([o[j] for o in out]).reshape(batch.batch_shape + out[0][j].shape) for j in range(3)]


def _assert_like_each_alone(res, alone):
    # the same iterates point by point: equal, up to the rounding of a batched final evaluation
    assert torch.equal(res.params, alone[0])
    assert_close(res.closest, alone[1], atol=1e-14)
    assert_close(res.distance, alone[2], atol=1e-14)


def test_batched_surfaces_project_like_a_loop():
    base = cylinder_quarter()
    g = torch.Generator().manual_seed(51)
    cps = torch.stack([base.control_points * (1 + 0.1 * i) for i in range(3)])  # (3, 3, 2, 3)
    ws = base.weights.expand(3, 3, 2).clone()
    kvs = [torch.stack([base.knot_vectors[0] * (1 + 0.5 * i) for i in range(3)]), base.knot_vectors[1]]
    batch = _batched(base, cps, ws, kvs)  # u knots per element (three domains), v shared
    p = torch.rand(3, 40, 3, dtype=F64, generator=g) * 3
    res = project_points(batch, p)
    assert res.params.shape == (3, 40, 2) and res.distance.shape == (3, 40)
    _assert_like_each_alone(res, _each_alone(batch, p))
    # each element in its own domain, and at the closed-form distance of its scaled cylinder
    for i in range(3):
        assert bool((res.params[i, :, 0] >= -1 - 0.5 * i).all() and (res.params[i, :, 0] <= 2 + i).all())
        truth = cylinder_closest(p[i] / (1 + 0.1 * i)) * (1 + 0.1 * i)
        assert_close(res.closest[i], truth, atol=1e-12)
    # several starts, warm starts and restarts take the same path
    _assert_like_each_alone(project_points(batch, p, starts=3), _each_alone(batch, p, starts=3))
    bad = torch.zeros(3, 40, 2, dtype=F64)
    _assert_like_each_alone(project_points(batch, p, params=bad, restart=True),
                            _each_alone(batch, p, params=bad, restart=True))
    _assert_like_each_alone(project_points(batch, p, params=res.params, iterations=2, check_every=0),
                            _each_alone(batch, p, params=res.params, iterations=2, check_every=0))
    with pytest.raises(NurbskitError, match="spline batch"):
        project_points(batch, p[:2])


def _closed_and_open_cylinders():
    """A closed cylinder beside one whose seam is open (its last control columns moved)."""
    s = closed_cylinder()
    opened = s.control_points.clone()
    opened[:, -2:, 2] += 0.25
    return _batched(s, torch.stack([s.control_points, opened]), s.weights.expand(2, 2, 10).clone())


def test_a_batch_searched_coarse_to_fine_projects_like_a_loop(monkeypatch):
    # the accelerators' start search for large inputs, forced on the CPU: per element
    from nurbskit.core import project as P

    monkeypatch.setattr(P, "_use_coarse", lambda device, pairs: True)
    base = smooth_height_field(54)
    g = torch.Generator().manual_seed(54)
    cps = base.control_points + 0.05 * torch.randn((3,) + base.control_points.shape, dtype=F64, generator=g)
    batch = _batched(base, cps, base.weights.expand((3,) + base.weights.shape).clone())
    p = torch.rand(3, 60, 3, dtype=F64, generator=g) * torch.tensor([2.0, 2.0, 0.4]) - torch.tensor([0.0, 1.0, 0.2])
    _assert_like_each_alone(project_points(batch, p), _each_alone(batch, p))


def test_a_batch_keeps_each_elements_periodic_directions():
    # the closed cylinder wraps across the seam, the open one stops at its domain edge,
    # each as when alone
    batch = _closed_and_open_cylinders()
    from nurbskit.core.project import periodic_directions

    assert [periodic_directions(batch[i]) for i in range(2)] == [(False, True), (False, False)]
    assert periodic_directions(batch) == ((False, True), (False, False))
    p, truth = _seam_points()
    p = torch.stack([p, p])
    res = project_points(batch, p)
    _assert_like_each_alone(res, _each_alone(batch, p))
    assert_close(res.distance[0], truth, atol=1e-12)
    # said explicitly for the whole batch, the open seam wraps too: the caller's choice
    said = project_points(batch, p, periodic=(False, True))
    assert torch.equal(said.params[0], res.params[0])


def test_batched_curves_any_batch_shape_and_no_points():
    rng = np.random.default_rng(52)
    cps = torch.tensor(rng.normal(size=(2, 3, 6, 2)), dtype=F64)
    ws = torch.tensor(rng.uniform(0.5, 2.0, size=(2, 3, 6)), dtype=F64)
    batch = NURBSCurve(cps, degree=3, weights=ws)
    p = torch.tensor(rng.normal(size=(2, 3, 25, 2)), dtype=F64)
    res = project_points_curve(batch, p)
    assert res.params.shape == (2, 3, 25) and res.closest.shape == (2, 3, 25, 2)
    _assert_like_each_alone(res, _each_alone(batch, p))
    empty = project_points(batch, p[:, :, :0])
    assert empty.params.shape == (2, 3, 0) and empty.distance.shape == (2, 3, 0)


def test_batched_projection_is_one_pass_with_per_element_gradients():
    from nurbskit._opcount import OperationCounter

    base = smooth_height_field(53)
    g = torch.Generator().manual_seed(53)

    def batch_of(count):
        cps = base.control_points + 0.05 * torch.randn((count,) + base.control_points.shape, dtype=F64, generator=g)
        return _batched(base, cps.requires_grad_(True), base.weights.expand((count,) + base.weights.shape).clone())

    def points(batch):
        uv = torch.rand(batch.control_points.shape[0], 50, 2, dtype=F64, generator=g) * 2 - torch.tensor([0.0, 1.0])
        return (batch.detach().evaluate(uv) + 0.05 * torch.randn(uv.shape[:-1] + (3,), dtype=F64, generator=g))

    counts = []
    for count in (2, 16):
        b = batch_of(count)
        x = points(b)
        first = project_points(b, x)
        with OperationCounter() as ops:  # a fit's warm refresh: nothing read back, no loop over elements
            project_points(b, x, params=first.params, iterations=2, check_every=0, validate=False,
                           periodic=(False, False), second_order=False)
        assert ops.host_reads == 0, ops.host_read_names()
        counts.append(ops.operations)
    assert counts[0] == counts[1]
    # gradients reach each element's control points from its own points only
    first.distance.sum().backward()
    grad = b.control_points.grad
    for i in (0, 7, 15):
        cp = b.control_points.detach()[i].clone().requires_grad_(True)
        project_points(base._replace(control_points=cp), x[i]).distance.sum().backward()
        assert_close(grad[i], cp.grad, atol=1e-13)


def test_coarse_to_fine_grid_search_finds_the_nearest_sample(monkeypatch):
    # The accelerators' two-level start search (sub-grid, then a window of the full grid),
    # run on the CPU: on a smooth patch it finds the exact nearest sample, and the
    # projection from it is the projection from the exact start.
    from nurbskit.core import project as P

    s = cylinder_quarter()
    g = torch.Generator().manual_seed(52)
    p = torch.rand(3000, 3, dtype=F64, generator=g) * 3
    axes = s.grid_axes((40, 33))
    samples = s.evaluate_grid(*axes).reshape(-1, 3)
    fast = P._coarse_to_fine(samples, (40, 33), p)
    exact = torch.cdist(p, samples).argmin(1)
    assert_close((samples[fast] - p).norm(dim=-1), (samples[exact] - p).norm(dim=-1), atol=0)
    plain = project_points(s, p)
    monkeypatch.setattr(P, "_use_coarse", lambda device, pairs: True)
    coarse = project_points(s, p)
    assert_close(coarse.distance, plain.distance, atol=1e-12)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_cuda_projection_matches_cpu(dtype, monkeypatch):
    # the accelerator path (tiled exact search, coarse-to-fine start, masked Newton)
    s = closed_cylinder().to(dtype)
    p, truth = _seam_points()
    p = p.to(dtype)
    cpu = project_points(s, p)
    gpu = project_points(s.to("cuda"), p.cuda())
    assert_close(gpu.distance.cpu(), cpu.distance, atol=1e-12 if dtype == F64 else 2e-6)
    from nurbskit.core import project as P

    monkeypatch.setattr(P, "_COARSE_PAIRS", 0)
    coarse = project_points(s.to("cuda"), p.cuda())
    assert_close(coarse.distance.cpu(), truth.to(dtype), atol=1e-12 if dtype == F64 else 2e-6)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_batched_projection_matches_cpu():
    batch = _closed_and_open_cylinders()
    p, truth = _seam_points()
    p = torch.stack([p, p])
    cpu = project_points(batch, p)
    gpu = project_points(batch.to("cuda"), p.cuda())
    assert_close(gpu.distance.cpu(), cpu.distance, atol=1e-12)
    assert_close(gpu.distance[0].cpu(), truth, atol=1e-12)


def test_closed_clamped_direction_wraps_across_the_seam():
    # A full revolution (the clamped nine-point circle) is closed but not periodic: its
    # seam is only C0 in the parameter. Points whose foot point lies just before the seam
    # used to stop on it (found with a revolved vase: 0.04 off); now the step wraps.
    from nurbskit import revolve
    from nurbskit.core.project import periodic_directions

    line = NURBSCurve(torch.tensor([[2.0, 0.0, -1.0], [2.0, 0.0, 1.0]], dtype=torch.float64), 1)
    cylinder = revolve(line, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    assert periodic_directions(cylinder) == (True, False)
    angles = torch.cat([torch.linspace(-0.3, -1e-6, 40), torch.linspace(1e-6, 0.3, 40)]).double()
    rho = torch.linspace(1.5, 2.5, 80, dtype=torch.float64)
    p = torch.stack([rho * torch.cos(angles), rho * torch.sin(angles), torch.linspace(-0.9, 0.9, 80).double()], -1)
    res = project_points(cylinder, p)
    assert_close(res.distance, (rho - 2.0).abs(), atol=1e-12)
    assert bool(((res.params[:, 0] >= 0) & (res.params[:, 0] <= 1)).all())
    # the foot points are the radial ones: on the circle of radius 2, at the points' angles
    assert_close(res.closest[:, :2].norm(dim=-1), torch.full((80,), 2.0, dtype=torch.float64), atol=1e-12)
    assert_close(torch.atan2(res.closest[:, 1], res.closest[:, 0]), angles, atol=1e-12)


def _segment_distances(x: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """The exact distance of each point to a polyline: the nearest of its segments."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    w = np.clip(np.einsum("nsd,sd->ns", x[:, None] - a, ab) / (ab * ab).sum(-1), 0, 1)
    return np.linalg.norm(x[:, None] - (a + w[..., None] * ab), axis=-1).min(1)


def test_projection_onto_polylines_reaches_their_vertices():
    # A degree-1 curve is C0 at every interior knot: Newton overshot across the kink,
    # halved its step and stopped short of a vertex (118 of 300 points wrong, distances up
    # to 3.6e-3 too large). Within the smooth pieces, then across the knot, it is exact.
    # (8 starts: a random polyline in 3-D has other local minima, whose basins are another
    # matter; with one start 12 to 22 of 300 points end in one of those.)
    rng = np.random.default_rng(21)
    for _ in range(4):
        poly = rng.normal(size=(12, 3))
        c = NURBSCurve(torch.tensor(poly), 1)
        x = rng.normal(size=(300, 3)) * 1.5
        d = project_points(c, torch.tensor(x), starts=8).distance.numpy()
        np.testing.assert_allclose(d, _segment_distances(x, poly), rtol=0, atol=1e-12)


def test_projection_onto_a_crease_of_a_surface():
    # A bilinear roof (C0 along u = 0.5) and a bicubic ridge (a knot of multiplicity 3 in
    # u): the foot points on the crease, against a dense sampling refined by the exact
    # segment distance along the crease line.
    roof = NURBSSurface(torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 1], [1, 1, 1]], [[2, 0, 0], [2, 1, 0]]],
                                     dtype=torch.float64), (1, 1))
    r = project_points(roof, torch.tensor([[1.0, 0.5, 3.0], [0.9, 0.2, 2.5]], dtype=torch.float64))
    assert_close(r.params, torch.tensor([[0.5, 0.5], [0.5, 0.2]], dtype=torch.float64), atol=1e-12)
    assert_close(r.distance, torch.tensor([2.0, math.hypot(0.1, 1.5)], dtype=torch.float64), atol=1e-12)
    rng = np.random.default_rng(22)
    u = torch.tensor([0, 0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1, 1], dtype=torch.float64)
    P = np.zeros((7, 5, 3))
    P[..., 0], P[..., 1] = np.meshgrid(np.linspace(0, 2, 7), np.linspace(0, 1, 5), indexing="ij")
    P[..., 2] = 1 - np.abs(P[..., 0] - 1) + 0.1 * rng.normal(size=(7, 5))
    ridge = NURBSSurface(torch.tensor(P), (3, 3), [u, None])
    x = torch.tensor(np.c_[rng.uniform(0.8, 1.2, 60), rng.uniform(0.1, 0.9, 60), rng.uniform(1.5, 2.5, 60)])
    r = project_points(ridge, x)
    # the oracle: every sample of a fine grid, then the best of a 1-D search along the crease
    fine = ridge.sample(401).reshape(-1, 3)
    d_grid = torch.cdist(x, fine).min(1).values
    crease = ridge.evaluate(torch.stack([torch.full((20001,), 0.5, dtype=torch.float64),
                                         torch.linspace(0, 1, 20001, dtype=torch.float64)], -1))
    d_crease = torch.cdist(x, crease).min(1).values
    oracle = torch.minimum(d_grid, d_crease)
    assert bool((r.distance <= oracle + 1e-12).all()), float((r.distance - oracle).max())
    assert float((oracle - r.distance).max()) < 1e-6  # the oracle's own sampling error


@pytest.mark.parametrize("power", [3, 5])
def test_clustered_knots_start_in_the_right_basin(power):
    # A spiral whose knots crowd towards 0, (i / s)^power, as a fit's moved knots can: the
    # start grid was uniform in the parameter, left most of the spiral to a few samples,
    # and 21 (power 3) / 293 (power 5) of 2,000 points ended on the wrong turn, up to 5.6
    # away. The oracle: the nearest of 400,001 samples, an upper bound on the distance.
    from scipy.spatial import cKDTree

    n, p = 24, 3
    s = n - p
    inner = (torch.arange(s + 1, dtype=torch.float64) / s) ** power
    kv = torch.cat([torch.zeros(p, dtype=torch.float64), inner, torch.ones(p, dtype=torch.float64)])
    turn = torch.linspace(0, 6 * math.pi, n, dtype=torch.float64)
    cp = torch.stack([torch.cos(turn) * (1 + turn), torch.sin(turn) * (1 + turn)], -1)
    c = NURBSCurve(cp, p, kv)
    dense = c.evaluate(torch.linspace(0, 1, 400001, dtype=torch.float64))
    arc = torch.cat([torch.zeros(1, dtype=torch.float64), (dense[1:] - dense[:-1]).norm(dim=-1).cumsum(0)])
    even = torch.searchsorted(arc, torch.linspace(0, float(arc[-1]), 1000, dtype=torch.float64)).clamp(max=400000)
    g = torch.Generator().manual_seed(1)
    x = dense[even] + 0.05 * torch.randn(1000, 2, generator=g, dtype=torch.float64)
    t = project_points(c, x)[0]
    d = (c.evaluate(t.reshape(-1)) - x).norm(dim=-1)
    bound = torch.as_tensor(cKDTree(dense.numpy()).query(x.numpy())[0])
    assert float((d - bound).max()) <= 1e-9


def test_the_start_grid_spreads_over_the_non_empty_knot_spans():
    from nurbskit.core.tensor import span_axis, uniform_axis

    f64 = torch.float64
    clamped = torch.tensor([0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4], dtype=f64)
    assert_close(span_axis(clamped, 3, 7, 33), uniform_axis(clamped, 3, 7, 33), atol=1e-15)
    # a circle's knots: double knots at the quarters; counted as spans, a third of the
    # samples sat on them twice over (a revolution surface's mean distance rose 0.6 %)
    circle = torch.tensor([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1], dtype=f64)
    assert_close(span_axis(circle, 2, 9, 17), torch.linspace(0, 1, 17, dtype=f64), atol=1e-15)
    # clustered knots: the same number of samples in each span, the ends exact
    clustered = torch.tensor([0, 0, 0, 0, .01, .02, .5, 1, 1, 1, 1], dtype=f64)
    t = span_axis(clustered, 3, 7, 13)
    assert (float(t[0]), float(t[-1])) == (0.0, 1.0)
    per_span = torch.histc(torch.bucketize(t[:-1], clustered[4:7], right=True).to(f64), bins=4, min=0, max=3)
    assert per_span.tolist() == [3.0, 3.0, 3.0, 3.0]
    # per-element knots: each row its own
    both = span_axis(torch.stack([clustered, 2 * clustered]), 3, 7, 13)
    assert_close(both, torch.stack([t, 2 * t]), atol=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available: GPU-only check")
def test_a_large_projection_compacts_its_newton_state_on_cuda_to_the_same_result(monkeypatch):
    from nurbskit.core import project as pj

    surface = smooth_height_field(seed=4).to("cuda")
    g = torch.Generator().manual_seed(11)
    points = (torch.rand(pj._COMPACT_MIN + 5000, 3, generator=g, dtype=F64) * 1.4 - 0.2).cuda()
    compacted = project_points(surface, points)
    monkeypatch.setattr(pj, "_COMPACT_MIN", 1 << 62)  # every point through every iteration
    masked = project_points(surface, points)
    assert torch.equal(compacted.params, masked.params)
    assert torch.equal(compacted.distance, masked.distance)


def test_a_batch_of_polylines_reaches_their_vertices_as_each_alone():
    # A batch refines within the smooth pieces between C0 knots as one spline does, with
    # each element's own knots: it did not, and 239 of these 900 points stopped short of a
    # vertex (off by up to 0.023). One point ends in another local minimum of its random
    # 3-D polyline (see above), alone as in the batch.
    rng = np.random.default_rng(23)
    polys = rng.normal(size=(3, 12, 3))
    x = rng.normal(size=(3, 300, 3)) * 1.5
    shared = NURBSCurve(torch.tensor(polys), 1)  # knots (m,) shared by the batch
    inner = np.sort(rng.uniform(0, 1, size=(3, 10)), axis=1)
    own = torch.tensor(np.c_[np.zeros((3, 2)), inner, np.ones((3, 2))])  # knots (3, m): one row per element
    exact = np.stack([_segment_distances(x[e], polys[e]) for e in range(3)])
    for batch in (shared, shared._replace(knot_vectors=[own])):
        res = project_points(batch, torch.tensor(x), starts=8)
        for e in range(3):
            alone = project_points(batch[e], torch.tensor(x[e]), starts=8)
            assert torch.equal(res.params[e], alone.params)
        off = np.abs(res.distance.numpy() - exact) > 1e-12
        assert off.sum() <= 1, int(off.sum())


def test_a_batch_of_creased_surfaces_projects_as_each_alone():
    # The bilinear roof (C0 along u = 0.5) and a copy whose crease is at u = 0.3 (its own
    # knots): foot points on each crease, as each surface gives alone.
    P = torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 1], [1, 1, 1]], [[2, 0, 0], [2, 1, 0]]], dtype=torch.float64)
    roof = NURBSSurface(P, (1, 1))
    kv = torch.tensor([[0, 0, 0.5, 1, 1], [0, 0, 0.3, 1, 1]], dtype=torch.float64)
    batch = roof._replace(control_points=torch.stack([P, P]), weights=torch.ones(2, 3, 2, dtype=torch.float64),
                          knot_vectors=[kv, roof.knot_vectors[1]])
    x = torch.tensor([[[1.0, 0.5, 3.0], [0.9, 0.2, 2.5], [1.2, 0.7, 2.0]]] * 2, dtype=torch.float64)
    res = project_points(batch, x)
    for e in range(2):
        alone = project_points(batch[e], x[e])
        assert torch.equal(res.params[e], alone.params)
        assert_close(res.params[e, :, 0], kv[e, 2].expand(3), atol=1e-12)  # on the crease


def _closed_polygon(vertices: np.ndarray, periodic: bool) -> NURBSCurve:
    """A closed polygon as a degree-1 curve: periodic (its first vertex repeated once over a
    periodic knot vector) or clamped with its ends on the first vertex."""
    from nurbskit.fit.params import periodic_knots

    P = torch.tensor(np.r_[vertices, vertices[:1]])
    if periodic:
        return NURBSCurve(P, 1, knot_vector=periodic_knots(P.shape[0], 1, dtype=torch.float64))
    return NURBSCurve(P, 1)


def test_projection_onto_closed_polygons_reaches_every_vertex():
    # A closed polygon wraps (its seam is a vertex too) and is C0 at every knot. The C0
    # knots of wrapping directions were not split: 640 of these 2,000 points around the
    # square stopped short of a vertex (off by up to 6.6e-4; with one start 647, up to
    # 0.036), and 678 of 1,500 around the tube below (up to 5.0e-3). Now a wrapping direction with C0
    # knots is cut into pieces that end at its seam as well, and a result on the seam
    # starts again on the other side of it. (8 starts: inside a polygon, near a corner,
    # the nearest grid sample can lie on the other side's basin; see the polyline test.)
    from nurbskit.core.project import periodic_directions

    rng = np.random.default_rng(29)
    square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    for vertices in (square, rng.normal(size=(9, 3))):
        x = rng.uniform(-1, 2, size=(2000, 3)) if vertices is square else rng.normal(size=(600, 3)) * 1.5
        exact = _segment_distances(x, np.r_[vertices, vertices[:1]])
        for periodic in (True, False):
            c = _closed_polygon(vertices, periodic)
            assert periodic_directions(c) == (True,)
            d = project_points(c, torch.tensor(x), starts=8).distance.numpy()
            np.testing.assert_allclose(d, exact, rtol=0, atol=1e-12)


def test_projection_onto_a_square_tube_and_a_batch_of_closed_polygons():
    # A surface closed along a polygon (periodic degree 1 in u, a line in v): the foot
    # points on its edges, where the tube's corners are. And a batch of closed polygons,
    # each with its own knots: each element as it projects alone.
    from nurbskit.fit.params import periodic_knots

    rng = np.random.default_rng(31)
    square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]])
    P = torch.tensor(np.stack([square, square + [0, 0, 2]], 1))  # (5, 2, 3): u around, v up
    tube = NURBSSurface(P, (1, 1), knot_vectors=[periodic_knots(5, 1, dtype=torch.float64),
                                                 torch.tensor([0.0, 0, 1, 1], dtype=torch.float64)])
    x = np.c_[rng.uniform(-1, 2, size=(1500, 2)), rng.uniform(0.1, 1.9, size=1500)]
    d = project_points(tube, torch.tensor(x), starts=8).distance.numpy()
    np.testing.assert_allclose(d, _segment_distances(x * [1, 1, 0], square), rtol=0, atol=1e-12)

    polys = rng.normal(size=(3, 7, 3))
    own = torch.stack([periodic_knots(8, 1, dtype=torch.float64) * s for s in (1.0, 2.0, 0.5)])  # (3, m)
    batch = NURBSCurve(torch.tensor(np.concatenate([polys, polys[:, :1]], 1)), 1, knot_vector=own)
    x = rng.normal(size=(3, 300, 3)) * 1.5
    res = project_points(batch, torch.tensor(x), starts=8)
    for e in range(3):
        alone = project_points(batch[e], torch.tensor(x[e]), starts=8)
        assert torch.equal(res.params[e], alone.params)
        np.testing.assert_allclose(res.distance[e].numpy(), _segment_distances(x[e], np.r_[polys[e], polys[e, :1]]),
                                   rtol=0, atol=1e-12)


def test_only_knots_where_the_tangent_turns_are_corners():
    # A rational circle's double knots are C0 in the parameter, but its tangent does not
    # turn there: no piece boxes (cutting there cost a revolved surface 30 % more time for
    # the same foot points). A closed polygon's vertices, its seam included, are corners.
    from nurbskit import revolve
    from nurbskit.core import tensor as tp
    from nurbskit.core.project import _c0_breaks, periodic_directions

    line = NURBSCurve(torch.tensor([[2.0, 0.0, -1.0], [2.0, 0.0, 1.0]], dtype=torch.float64), 1)
    cylinder = revolve(line, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    polygon = _closed_polygon(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]), True)
    roof = NURBSSurface(torch.tensor([[[0.0, 0, 0], [0, 1, 0]], [[1, 0, 1], [1, 1, 1]], [[2, 0, 0], [2, 1, 0]]],
                                     dtype=torch.float64), (1, 1))

    def corners(s):
        return _c0_breaks(s, tp.homogeneous(s.control_points, s.weights), periodic_directions(s))

    assert corners(cylinder) is None
    assert corners(polygon)[0].tolist() == [[0.0, 0.25, 0.5, 0.75]]
    assert [b.tolist() for b in corners(roof)] == [[[0.5]], [[]]]
    flat = roof._replace(control_points=roof.control_points * torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64))
    assert corners(flat) is None  # a flat roof does not turn at its knot
