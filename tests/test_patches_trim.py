"""Trimming in (u, v): holes survive, the mesh border follows the loops."""

import numpy as np

from nurbskit.core.trim import TrimmedSurface
from nurbskit.patches.refit import plane_patch, point_distances
from nurbskit.patches.trim import alpha_shape, trim_patch, trimmed_mesh


def _annulus(n, rng, r0=0.3, r1=1.0):
    r = np.sqrt(rng.uniform(r0**2, r1**2, n))
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t), np.zeros(n)]


def test_disk_with_a_hole_keeps_the_hole_and_its_area():
    rng = np.random.default_rng(0)
    p = _annulus(6000, rng)
    corners = np.array([[-1, -1, 0], [1, 1, 0], [1, -1, 0], [-1, 1, 0]], float)
    surface = plane_patch(np.vstack([p, corners]), 4, 3)
    uv, d = point_distances(surface, p)
    assert d.max() < 1e-9
    faces = trim_patch(uv, surface)
    assert len(faces) == 1
    face = faces[0]
    assert [lp.kind for lp in face.loops] == ["outer", "hole"]
    v, f = trimmed_mesh(face)
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()
    true = np.pi * (1.0 - 0.3**2)
    assert abs(area / true - 1) < 0.02
    # the hole: no mesh vertex well inside it, and the loop's 3D radius near 0.3
    assert np.linalg.norm(v[:, :2], axis=1).min() > 0.25
    hole = face.holes[0].uv
    with np.errstate(all="ignore"):
        import torch

        rim = surface.evaluate(torch.as_tensor(hole)).numpy()
    assert abs(np.median(np.linalg.norm(rim[:, :2], axis=1)) - 0.3) < 0.03
    # the JSON form round-trips
    again = TrimmedSurface.from_dict(face.to_dict())
    assert [lp.kind for lp in again.loops] == ["outer", "hole"]


def test_two_separate_parts_give_two_faces():
    rng = np.random.default_rng(1)
    a = rng.random((1500, 2)) * [0.4, 1.0]
    b = rng.random((1500, 2)) * [0.4, 1.0] + [0.6, 0.0]
    p = np.c_[np.vstack([a, b]), np.zeros(3000)]
    surface = plane_patch(p, 4, 3)
    uv, _ = point_distances(surface, p)
    faces = trim_patch(uv, surface)
    assert len(faces) == 2
    areas = []
    for face in faces:
        v, f = trimmed_mesh(face)
        areas.append(0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())
    assert all(abs(a / 0.4 - 1) < 0.03 for a in areas)


def test_alpha_shape_of_a_square_grid_is_the_square():
    g = np.linspace(0, 1, 11)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    shape = alpha_shape(xy, 0.2)
    assert abs(shape.area - 1.0) < 1e-12 and len(shape.interiors) == 0
    xy = xy[np.linalg.norm(xy - 0.5, axis=1) > 0.3]  # a hole in the middle
    assert len(alpha_shape(xy, 0.1).interiors) == 1
