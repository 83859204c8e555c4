"""Exact constructors (revolve, extrude) against analytic cylinders, cones, spheres and tori.

Oracles: the implicit equations (to 1e-12 in float64), the analytic parametrisation
(every analytic point is reached: projection distance ~ 0), and geomdl's evaluation of the
same control net.
"""

from __future__ import annotations

import math

import pytest
import torch

import nurbskit
from nurbskit import NURBSCurve
from nurbskit.core.construct import arc_count, extrude, revolve
from nurbskit.core.project import project_points
from nurbskit.errors import NurbskitError

from _assert import assert_close

F64 = torch.float64
S2 = 2 ** -0.5


def _rand_params(n=400, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 2, generator=g, dtype=F64)


def _frame(direction):
    """Orthonormal (e1, e2, a) with a along direction."""
    a = torch.as_tensor(direction, dtype=F64)
    a = a / a.norm()
    h = torch.tensor([1.0, 0.0, 0.0], dtype=F64) if abs(a[0]) < 0.9 else torch.tensor([0.0, 1.0, 0.0], dtype=F64)
    e1 = h - (h @ a) * a
    e1 = e1 / e1.norm()
    e2 = torch.linalg.cross(a, e1)
    return e1, e2, a


# A tilted axis through an off-origin point, so no test relies on the z axis.
O = torch.tensor([0.3, -1.2, 0.7], dtype=F64)
A = torch.tensor([1.0, 2.0, 2.0], dtype=F64) / 3.0
E1, E2, _ = _frame(A)


def _local(points):
    """(r, h) of points about the axis (O, A)."""
    rel = points - O
    h = rel @ A
    r = (rel - h[:, None] * A).norm(dim=-1)
    return r, h


def _profile_in_plane(rz, degree, weights=None, knots=None):
    """A profile given in the half-plane (r along E1, z along A)."""
    rz = torch.as_tensor(rz, dtype=F64)
    pts = O + rz[:, :1] * E1 + rz[:, 1:2] * A
    return NURBSCurve(pts, degree=degree, weights=weights, knot_vector=knots)


def _covers(surface, analytic_points):
    """Every analytic point is on the NURBS surface (projection distance)."""
    _, _, dist = project_points(surface, analytic_points, grid=128, starts=4, iterations=100)
    return float(dist.max())


def test_full_turn_is_the_nine_point_circle():
    line = _profile_in_plane([[1.0, 0.0], [1.0, 2.0]], 1)
    s = revolve(line, O, A)
    assert s.sizes == (9, 2) and s.degrees == (2, 1)
    w = s.weights[:, 0]
    assert_close(w, torch.tensor([1, S2, 1, S2, 1, S2, 1, S2, 1], dtype=F64), atol=1e-15)
    assert_close(s.knot_vectors[0], torch.tensor([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1], dtype=F64), atol=0)
    # the corners of the circumscribed square sit at r * sqrt(2)
    r, _ = _local(s.control_points[:, 0])
    assert_close(r, torch.tensor([1, 2 ** .5] * 4 + [1], dtype=F64), atol=1e-14)


def test_cylinder_implicit_and_coverage():
    radius, height = 0.8, 2.5
    s = revolve(_profile_in_plane([[radius, 0.0], [radius, height]], 1), O, A)
    p = s.evaluate(_rand_params())
    r, h = _local(p)
    assert_close(r, torch.full_like(r, radius), atol=1e-12)
    assert float(h.min()) >= -1e-12 and float(h.max()) <= height + 1e-12
    phi = torch.linspace(0, 2 * math.pi, 37, dtype=F64)[:-1]
    z = torch.linspace(0, height, 7, dtype=F64)
    P, Z = torch.meshgrid(phi, z, indexing="ij")
    ana = O + radius * (torch.cos(P)[..., None] * E1 + torch.sin(P)[..., None] * E2) + Z[..., None] * A
    assert _covers(s, ana.reshape(-1, 3)) < 1e-10


def test_cone_implicit_and_coverage():
    # apex at height 2 on the axis; half-angle atan(1 / 2)
    s = revolve(_profile_in_plane([[1.0, 0.0], [0.5, 1.0], [0.0, 2.0]], 2), O, A)
    p = s.evaluate(_rand_params())
    r, h = _local(p)
    assert_close(r, (2.0 - h) / 2.0, atol=1e-12)
    phi = torch.linspace(0, 2 * math.pi, 25, dtype=F64)[:-1]
    z = torch.linspace(0, 1.8, 6, dtype=F64)
    P, Z = torch.meshgrid(phi, z, indexing="ij")
    rad = (2.0 - Z) / 2
    ana = O + rad[..., None] * (torch.cos(P)[..., None] * E1 + torch.sin(P)[..., None] * E2) + Z[..., None] * A
    assert _covers(s, ana.reshape(-1, 3)) < 1e-10


def _semicircle(radius):
    """A rational quadratic semicircle from the south pole to the north pole (2 arcs)."""
    rz = [[0, -radius], [radius, -radius], [radius, 0], [radius, radius], [0, radius]]
    return _profile_in_plane(rz, 2, weights=torch.tensor([1, S2, 1, S2, 1], dtype=F64),
                             knots=torch.tensor([0, 0, 0, .5, .5, 1, 1, 1], dtype=F64))


def test_sphere_implicit_and_coverage():
    radius = 1.3
    s = revolve(_semicircle(radius), O, A)
    p = s.evaluate(_rand_params(1000))
    assert_close((p - O).norm(dim=-1), torch.full((1000,), radius, dtype=F64), atol=1e-12)
    g = torch.Generator().manual_seed(1)
    ana = torch.randn(300, 3, generator=g, dtype=F64)
    ana = O + radius * ana / ana.norm(dim=-1, keepdim=True)
    assert _covers(s, ana) < 1e-9


def test_torus_from_full_circle_profile():
    R, rho = 2.0, 0.5
    # the nine-point circle of radius rho centred at (R, 0) in the (r, z) half-plane
    ang = torch.arange(9, dtype=F64) * (math.pi / 4)
    scale = torch.tensor([1, 2 ** .5] * 4 + [1], dtype=F64)
    rz = torch.stack([R + rho * scale * torch.cos(ang), rho * scale * torch.sin(ang)], -1)
    w = torch.tensor([1, S2] * 4 + [1], dtype=F64)
    kv = torch.tensor([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1], dtype=F64)
    s = revolve(_profile_in_plane(rz, 2, weights=w, knots=kv), O, A)
    assert s.sizes == (9, 9)
    p = s.evaluate(_rand_params(1000))
    r, h = _local(p)
    assert_close((r - R) ** 2 + h ** 2, torch.full_like(r, rho ** 2), atol=1e-12)
    g = torch.Generator().manual_seed(2)
    t = torch.rand(300, 2, generator=g, dtype=F64) * 2 * math.pi
    rad = R + rho * torch.cos(t[:, 1:])
    ana = O + rad * (torch.cos(t[:, :1]) * E1 + torch.sin(t[:, :1]) * E2) + rho * torch.sin(t[:, 1:]) * A
    assert _covers(s, ana) < 1e-9


def test_higher_degree_polynomial_profile_radius_is_preserved():
    """A cubic profile: each iso-v curve is a circle of the profile point's radius."""
    rz = torch.tensor([[0.5, 0.0], [1.2, 0.4], [0.3, 1.0], [0.9, 1.5], [0.6, 2.0]], dtype=F64)
    prof = _profile_in_plane(rz, 3)
    s = revolve(prof, O, A)
    v = torch.linspace(0, 1, 11, dtype=F64)
    u = torch.linspace(0, 1, 13, dtype=F64)
    grid = s.evaluate_grid(u, v)  # (13, 11, 3)
    r_prof, h_prof = _local(prof.evaluate(v))
    for i in range(13):
        r, h = _local(grid[i])
        assert_close(r, r_prof, atol=1e-12)
        assert_close(h, h_prof, atol=1e-12)


@pytest.mark.parametrize("angle", [math.pi / 3, math.pi / 2, 2.0, math.pi, 4.0, 5.5])
def test_partial_angles(angle):
    prof = _profile_in_plane([[1.0, 0.0], [1.5, 1.0], [0.7, 2.0]], 2)
    s = revolve(prof, O, A, angle)
    assert s.sizes[0] == 2 * arc_count(angle) + 1
    v = torch.linspace(0, 1, 9, dtype=F64)
    end = s.evaluate_grid(torch.tensor([1.0], dtype=F64), v)[0]
    start = s.evaluate_grid(torch.tensor([0.0], dtype=F64), v)[0]
    assert_close(start, prof.evaluate(v), atol=1e-12)
    # the end is the profile rotated by `angle` (Rodrigues)
    rel = prof.evaluate(v) - O
    h = rel @ A
    x = rel - h[:, None] * A
    rot = O + h[:, None] * A + math.cos(angle) * x + math.sin(angle) * torch.linalg.cross(A.expand_as(x), x)
    assert_close(end, rot, atol=1e-12)
    # angles along u grow monotonically from 0 to `angle`
    p = s.evaluate_grid(torch.linspace(0, 1, 101, dtype=F64), torch.tensor([0.5], dtype=F64))[:, 0]
    rel = p - O
    phi = torch.atan2(rel @ E2, rel @ E1) % (2 * math.pi)
    phi[0] = 0.0
    if angle >= 2 * math.pi - 1e-9:
        phi = phi[:-1]
    assert bool((phi[1:] - phi[:-1] > 0).all())
    assert abs(float(phi[-1]) - angle) < 1e-9 or angle > 6


def test_matches_geomdl_evaluation():
    geomdl = pytest.importorskip("geomdl")  # noqa: F841
    from nurbskit import to_geomdl

    prof = _profile_in_plane([[1.0, 0.0], [1.5, 1.0], [0.7, 2.0], [0.2, 2.5]], 3,
                             weights=torch.tensor([1.0, 0.7, 1.4, 1.0], dtype=F64))
    s = revolve(prof, O, A, 3.0)
    g = to_geomdl(s)
    uv = _rand_params(50, seed=3)
    ref = torch.tensor(g.evaluate_list(uv.tolist()), dtype=F64)
    assert_close(s.evaluate(uv), ref, atol=1e-12)


def test_point_on_axis_and_gradients_reach_axis_and_profile():
    cp = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [0.0, 0.0, 1.0]], dtype=F64, requires_grad=True)
    w = torch.ones(3, dtype=F64, requires_grad=True)
    axis_p = torch.zeros(3, dtype=F64, requires_grad=True)
    axis_d = torch.tensor([0.0, 0.1, 1.0], dtype=F64, requires_grad=True)
    s = revolve(NURBSCurve(cp, degree=2, weights=w), axis_p, axis_d)
    assert torch.isfinite(s.control_points).all()
    out = s.evaluate(_rand_params(20)).sum()
    out.backward()
    for t in (cp, w, axis_p, axis_d):
        assert t.grad is not None and torch.isfinite(t.grad).all()


def test_gradcheck_through_revolve():
    cp = torch.tensor([[1.0, 0.0, 0.0], [1.4, 0.2, 0.5], [0.8, 0.1, 1.0]], dtype=F64, requires_grad=True)
    axis_d = torch.tensor([0.1, 0.0, 1.0], dtype=F64, requires_grad=True)
    uv = _rand_params(8, seed=5)

    def f(c, d):
        return revolve(NURBSCurve(c, degree=2), torch.zeros(3, dtype=F64), d, 4.0).evaluate(uv)

    assert torch.autograd.gradcheck(f, (cp, axis_d))


def test_extrude_prism_and_plane_equations():
    d = torch.tensor([0.2, -0.3, 1.0], dtype=F64)
    prof = _semicircle(1.0)  # a planar rational curve
    s = extrude(prof, d, 2.5)
    assert s.sizes == (2, 5) and s.degrees == (1, 2)
    uv = _rand_params(300)
    p = s.evaluate(uv)
    dn = d / d.norm()
    # p - 2.5 u dn lies on the profile: the semicircle (centre O, radius 1, in the E1/A plane)
    base = p - 2.5 * uv[:, :1] * dn
    assert_close((base - O).norm(dim=-1), torch.ones(300, dtype=F64), atol=1e-12)
    assert_close((base - O) @ E2, torch.zeros(300, dtype=F64), atol=1e-12)
    # the top edge is the translate of the profile
    v = torch.linspace(0, 1, 7, dtype=F64)
    top = s.evaluate_grid(torch.tensor([1.0], dtype=F64), v)[0]
    assert_close(top, prof.evaluate(v) + 2.5 * dn, atol=1e-12)


def test_extrude_cylinder_from_circle():
    """A circle extruded along its normal is a cylinder: implicit equation and coverage."""
    ang = torch.arange(9, dtype=F64) * (math.pi / 4)
    scale = torch.tensor([1, 2 ** .5] * 4 + [1], dtype=F64)
    pts = O + (0.7 * scale * torch.cos(ang))[:, None] * E1 + (0.7 * scale * torch.sin(ang))[:, None] * E2
    circle = NURBSCurve(pts, degree=2, weights=torch.tensor([1, S2] * 4 + [1], dtype=F64),
                        knot_vector=torch.tensor([0, 0, 0, .25, .25, .5, .5, .75, .75, 1, 1, 1], dtype=F64))
    s = extrude(circle, A, 1.5)
    r, h = _local(s.evaluate(_rand_params()))
    assert_close(r, torch.full_like(r, 0.7), atol=1e-12)
    phi = torch.linspace(0, 2 * math.pi, 25, dtype=F64)[:-1]
    z = torch.linspace(0, 1.5, 5, dtype=F64)
    P, Z = torch.meshgrid(phi, z, indexing="ij")
    ana = O + 0.7 * (torch.cos(P)[..., None] * E1 + torch.sin(P)[..., None] * E2) + Z[..., None] * A
    assert _covers(s, ana.reshape(-1, 3)) < 1e-10


def test_bad_arguments_raise():
    line = _profile_in_plane([[1.0, 0.0], [1.0, 2.0]], 1)
    with pytest.raises(NurbskitError, match="angle"):
        revolve(line, O, A, 0.0)
    with pytest.raises(NurbskitError, match="angle"):
        revolve(line, O, A, 7.0)
    with pytest.raises(NurbskitError, match="axis_direction"):
        revolve(line, O, [0.0, 0.0, 0.0])
    with pytest.raises(NurbskitError, match="3-vector"):
        revolve(line, O, [0.0, 1.0])
    with pytest.raises(NurbskitError, match="direction"):
        extrude(line, [0.0, 0.0, 0.0], 1.0)
    with pytest.raises(NurbskitError, match="length"):
        extrude(line, A, 0.0)
    with pytest.raises(NurbskitError, match="3D"):
        revolve(NURBSCurve(torch.rand(3, 2, dtype=F64), degree=2), O, A)


def test_exported_from_package():
    assert nurbskit.revolve is revolve and nurbskit.extrude is extrude


def test_docstring_examples():
    import doctest

    from nurbskit.core import construct

    assert doctest.testmod(construct, raise_on_error=False).failed == 0
