"""Mesh sampling: Poisson-disk spread and count, uniform area weighting, the vectorised
greedy independent set against the one-by-one dart-throwing loop, torch gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

import nurbskit
from nurbskit.errors import InputError, OptionError
from nurbskit.geometry.sampling import greedy_independent_set, nearest_neighbor_distances, sample_mesh, sample_parametric


def _sphere(subdivisions=3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _on_their_faces(points, vertices, faces, face_index) -> bool:
    """Each point lies inside its triangle: barycentric coordinates by least squares."""
    tri = vertices[faces[face_index]]
    e = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)  # (n, 3, 2)
    coef = np.stack([np.linalg.lstsq(e[i], points[i] - tri[i, 0], rcond=None)[0] for i in range(len(points))])
    residual = np.linalg.norm(np.einsum("nij,nj->ni", e, coef) - (points - tri[:, 0]), axis=1)
    return bool(residual.max() < 1e-12 and coef.min() > -1e-12 and coef.sum(axis=1).max() < 1 + 1e-12)


def test_greedy_independent_set_equals_sequential_dart_throwing():
    rng = np.random.default_rng(0)
    pts = rng.random((400, 2))
    r = 0.07
    pairs = cKDTree(pts).query_pairs(r, output_type="ndarray")
    rank = rng.permutation(400)
    kept = []
    for i in np.argsort(rank):  # the textbook loop: visit in rank order, keep if far from all kept
        if all(np.linalg.norm(pts[i] - pts[j]) >= r for j in kept):
            kept.append(i)
    mask = greedy_independent_set(400, pairs, rank)
    assert sorted(np.flatnonzero(mask).tolist()) == sorted(kept)


@pytest.mark.parametrize("n", [100, 1000, 5000])
def test_poisson_on_sphere_is_spread_and_exact(n):
    v, f = _sphere()
    pts, face = sample_mesh(v, f, n, seed=1, return_faces=True)
    d = nearest_neighbor_distances(pts)
    assert pts.shape == (n, 3)
    assert d.min() >= 0.4 * d.mean()
    assert _on_their_faces(pts, v, f, face)


def test_poisson_on_real_bunny(shared_data):
    mesh = nurbskit.io.read_mesh(shared_data / "classic_meshes/bunny.off")
    pts = nurbskit.sample_mesh(mesh.vertices, mesh.faces, 5000, method="poisson", seed=0)
    d = nearest_neighbor_distances(pts)
    assert abs(len(pts) - 5000) <= 0.05 * 5000
    assert d.min() >= 0.4 * d.mean()
    # uniform samples of the same size are not spread: the contrast is what "blue noise" means
    u = nurbskit.sample_mesh(mesh.vertices, mesh.faces, 5000, method="uniform", seed=0)
    du = nearest_neighbor_distances(u)
    assert du.min() < 0.2 * du.mean()


def test_uniform_is_area_weighted():
    # two triangles of areas 0.5 and 1.5: three quarters of the points land on the second
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [10, 0, 0], [13, 0, 0], [10, 1, 0]], float)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    n = 40000
    pts, face = sample_mesh(v, f, n, method="uniform", seed=5, return_faces=True)
    assert pts.shape == (n, 3)
    share = (face == 1).mean()
    sigma = np.sqrt(0.75 * 0.25 / n)
    assert abs(share - 0.75) < 5 * sigma
    np.testing.assert_array_equal(pts[:, 0] >= 10, face == 1)
    # within a triangle, uniform: the fraction below the midline y < 1/2 of the first triangle is 3/4
    first = pts[face == 0]
    assert abs((first[:, 1] < 0.5).mean() - 0.75) < 5 * np.sqrt(0.75 * 0.25 / len(first))


def test_seeds():
    v, f = _sphere(2)
    a = sample_mesh(v, f, 300, seed=4)
    np.testing.assert_array_equal(a, sample_mesh(v, f, 300, seed=4))
    assert not np.array_equal(a, sample_mesh(v, f, 300, seed=5))


def test_torch_vertices_get_gradients_and_keep_dtype():
    v, f = _sphere(1)
    vt = torch.tensor(v, dtype=torch.float32, requires_grad=True)
    pts = sample_mesh(vt, torch.tensor(f), 64, seed=0)
    assert pts.dtype == torch.float32 and pts.shape == (64, 3)
    pts.sum().backward()
    # every sample is a convex combination: the gradient of the sum over vertices totals n per axis
    torch.testing.assert_close(vt.grad.sum(dim=0), torch.full((3,), 64.0))
    assert sample_mesh(v.astype(np.float32), f, 10, seed=0).dtype == np.float32


@pytest.mark.parametrize("kwargs, error, message", [
    (dict(n=0), OptionError, "positive integer"),
    (dict(n=10, method="blue"), OptionError, "method must be one of"),
    (dict(n=2.5), OptionError, "positive integer"),
])
def test_bad_arguments(kwargs, error, message):
    v, f = _sphere(1)
    with pytest.raises(error, match=message):
        sample_mesh(v, f, **kwargs)


def test_bad_meshes():
    with pytest.raises(InputError, match="zero surface area"):
        sample_mesh(np.zeros((3, 3)), np.array([[0, 1, 2]]), 10)
    with pytest.raises(OptionError, match="faces index vertices"):
        sample_mesh(np.eye(3), np.array([[0, 1, 3]]), 10)
    with pytest.raises(InputError, match="no faces"):
        sample_mesh(np.eye(3), np.zeros((0, 3), int), 10)


def test_parametric_sampling_is_the_core_grid():
    s = nurbskit.NURBSSurface(torch.rand(5, 4, 3, dtype=torch.float64), (3, 2))
    pts = sample_parametric(s, (7, 6))
    assert pts.shape == (42, 3)
    torch.testing.assert_close(pts.reshape(7, 6, 3), s.sample((7, 6)))
    torch.testing.assert_close(pts[0], s.control_points[0, 0])  # clamped: the corner interpolates
