"""Tessellation (core.tessellate): vertices against evaluation, the face layout,
orientation against S_u x S_v, and closed-form normals on the sphere octant (pole
included, in every parametric orientation) and the cylinder."""

from __future__ import annotations

import math

import pytest
import torch

from nurbskit import NURBSCurve, NURBSSurface, NurbskitError
from nurbskit.core.tessellate import grid_faces, tessellate, tessellate_adaptive

from _assert import assert_close
from test_core_project import F64, RADIUS, cylinder_quarter, smooth_height_field, sphere_octant


def _grid_params(surface, R, S):
    u, v = surface.grid_axes((R, S))
    return torch.stack(torch.meshgrid(u, v, indexing="ij"), dim=-1).reshape(-1, 2)


def _face_normals(vertices, faces):
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return torch.linalg.cross(b - a, c - a, dim=-1)


def test_vertices_are_surface_points_and_layout():
    s = smooth_height_field(seed=11)
    R, S = 9, 6
    vertices, faces, normals = tessellate(s, (R, S))
    assert vertices.shape == (R * S, 3) and normals.shape == (R * S, 3)
    assert faces.shape == (2 * (R - 1) * (S - 1), 3) and faces.dtype == torch.int64
    assert_close(vertices, s.evaluate(_grid_params(s, R, S)), rtol=0, atol=1e-13)
    assert_close(normals, s.normals(_grid_params(s, R, S)), rtol=0, atol=1e-12)
    assert faces.min() == 0 and faces.max() == R * S - 1
    assert torch.equal(torch.unique(faces), torch.arange(R * S))
    # every cell (i, j) is split along its diagonal (i, j) - (i+1, j+1), into faces 2k and 2k+1
    cells = faces.reshape(R - 1, S - 1, 2, 3)
    i, j = 3, 2
    a = i * S + j
    assert cells[i, j].tolist() == [[a, a + S, a + S + 1], [a, a + S + 1, a + 1]]


def test_orientation_follows_su_x_sv():
    s = smooth_height_field(seed=12)
    vertices, faces, normals = tessellate(s, 12)
    fn = _face_normals(vertices, faces)
    vn = normals[faces].mean(dim=1)
    assert ((fn * vn).sum(-1) > 0).all()


def test_sphere_normals_are_the_position_pole_included():
    s = sphere_octant()
    vertices, faces, normals = tessellate(s, (9, 7))
    assert_close(vertices.norm(dim=-1), torch.ones(63, dtype=F64), atol=1e-14)
    # outward unit normal of the unit sphere = the point itself, also at the pole (v = 1 row)
    assert_close(normals, vertices, rtol=0, atol=1e-12)
    pole = torch.arange(6, 63, 7)
    assert_close(normals[pole], torch.tensor([0.0, 0.0, 1.0], dtype=F64).expand(9, 3), atol=1e-12)
    fn = _face_normals(vertices, faces)
    area = fn.norm(dim=-1)
    regular = area > 1e-12
    assert regular.sum() == len(faces) - 8  # one zero-area triangle per cell touching the pole
    assert ((fn * vertices[faces].mean(1)).sum(-1)[regular] > 0).all()


def test_collapsed_edge_in_each_parametric_position():
    # The same octant with the directions swapped (pole on u = u_max, S_v = 0 there) and
    # with v reversed (pole on v = v_min): S_u x S_v then points inward in both.
    s = sphere_octant()
    swapped = NURBSSurface(s.control_points.transpose(0, 1), (2, 2), None, s.weights.T)
    flipped = NURBSSurface(s.control_points.flip(1), (2, 2), None, s.weights.flip(1))
    for surface in (swapped, flipped):
        vertices, _, normals = tessellate(surface, (7, 5))
        assert_close(normals, -vertices, rtol=0, atol=1e-12)


def test_face_average_where_the_limit_vanishes_too():
    # Quadratic in u with the first two rows collapsed onto the origin: S_v and S_uv both
    # vanish on u = 0, so the limit rule gives nothing and the face average takes over
    # (and at the corner (0, S-1), whose only triangle has zero area, the grid neighbours).
    # The patch is planar (z = 0), so every normal is exactly +z or -z.
    cp = torch.zeros(3, 3, 3, dtype=F64)
    cp[2, :, 0] = torch.tensor([1.0, 1.2, 1.0], dtype=F64)
    cp[2, :, 1] = torch.tensor([-1.0, 0.0, 1.0], dtype=F64)
    s = NURBSSurface(cp, (2, 2))
    vertices, faces, normals = tessellate(s, (6, 5))
    expected = s.normals(torch.tensor([[0.5, 0.5]], dtype=F64))[0]  # a regular point
    assert_close(expected.abs(), torch.tensor([0.0, 0.0, 1.0], dtype=F64), atol=1e-12)
    assert_close(normals, expected.expand_as(normals), atol=1e-12)
    assert torch.isfinite(normals).all()


def test_cylinder_normals_closed_form():
    s = cylinder_quarter()
    vertices, faces, normals = tessellate(s, (10, 4))
    radial = vertices.clone()
    radial[:, 2] = 0
    assert_close(radial.norm(dim=-1), torch.full((40,), RADIUS, dtype=F64), atol=1e-14)
    assert_close(normals, radial / RADIUS, atol=1e-12)
    theta = torch.atan2(vertices[:, 1], vertices[:, 0])
    assert theta.min() > -1e-15 and theta.max() < math.pi / 2 + 1e-15


def test_gradients_reach_control_points():
    s0 = smooth_height_field(seed=13, n=(4, 3), degrees=(2, 2))
    cp = s0.control_points.clone().requires_grad_(True)

    def fn(control_points):
        vertices, _, normals = tessellate(NURBSSurface(control_points, s0.degrees, s0.knot_vectors, s0.weights), (4, 3))
        return vertices, normals

    assert torch.autograd.gradcheck(fn, (cp,), eps=1e-6, atol=1e-6, fast_mode=True)
    # At a pole the normal is a limit that moving one pole control point destroys, so only
    # finiteness is asked of its gradient there.
    s1 = sphere_octant()
    cp = s1.control_points.clone().requires_grad_(True)
    tessellate(NURBSSurface(cp, (2, 2), None, s1.weights), 5).normals.sum().backward()
    assert torch.isfinite(cp.grad).all()


def _edge_midpoints(vertices, faces):
    edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return vertices[edges].mean(dim=1)


@pytest.mark.parametrize("tolerance", [1e-2, 1e-4])
def test_adaptive_chords_within_tolerance_on_the_sphere(tolerance):
    s = sphere_octant()
    vertices, faces, normals = tessellate_adaptive(s, tolerance)
    assert_close(vertices.norm(dim=-1), torch.ones(len(vertices), dtype=F64), atol=1e-14)
    assert_close(normals, vertices, atol=1e-12)
    # every triangle edge's midpoint lies inside the unit sphere within the tolerance
    gap = 1 - _edge_midpoints(vertices, faces).norm(dim=-1)
    assert gap.min() > -1e-14 and gap.max() <= tolerance
    # and the refinement is not wasteful: some edge needs most of the tolerance
    assert gap.max() > tolerance / 8


def test_adaptive_keeps_straight_directions_coarse():
    s = cylinder_quarter()  # straight in v
    coarse = tessellate_adaptive(s, 1e-2)
    fine = tessellate_adaptive(s, 1e-4)
    assert len(coarse.vertices) % 2 == 0 and len(fine.vertices) % 2 == 0
    rows_coarse, rows_fine = len(coarse.vertices) // 2, len(fine.vertices) // 2
    assert rows_fine > 2 * rows_coarse  # sag ~ h^2: 100x less needs ~10x more rows
    for mesh, tol in ((coarse, 1e-2), (fine, 1e-4)):
        assert len(mesh.faces) == 2 * (len(mesh.vertices) // 2 - 1)  # S = 2: one strip
        xy = _edge_midpoints(mesh.vertices, mesh.faces)[:, :2]
        assert (RADIUS - xy.norm(dim=-1)).max() <= tol
    fn = _face_normals(fine.vertices, fine.faces)
    assert ((fn * fine.normals[fine.faces].mean(1)).sum(-1) > 0).all()
    with pytest.raises(NurbskitError, match="tolerance"):
        tessellate_adaptive(s, 0.0)


def test_dtype_device_and_errors():
    s = cylinder_quarter().to(torch.float32)
    vertices, faces, normals = tessellate(s, 5)
    assert vertices.dtype == normals.dtype == torch.float32 and faces.dtype == torch.int64
    assert grid_faces(2, 3).tolist() == [[0, 3, 4], [0, 4, 1], [1, 4, 5], [1, 5, 2]]
    with pytest.raises(NurbskitError, match="resolution"):
        tessellate(s, (1, 4))
    with pytest.raises(NurbskitError, match="3-D"):
        tessellate(NURBSSurface(torch.rand(3, 3, 2), (2, 2)), 4)
    with pytest.raises(NurbskitError, match="NURBSSurface"):
        tessellate(NURBSCurve(torch.rand(3, 3), 2), 4)
