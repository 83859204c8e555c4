"""Normals, the planar start and the .vg reader."""

import numpy as np
import pytest

from nurbskit.errors import InputError
from nurbskit.patches.adjacency import adjacency, link_counts
from nurbskit.patches.normals import estimate_normals, knn_graph, pca_normals
from nurbskit.patches.planar import planar_start, read_vg


def _cube(n_face, rng):
    pts, face = [], []
    for axis in range(3):
        for side in (0.0, 1.0):
            p = rng.random((n_face, 3))
            p[:, axis] = side
            pts.append(p)
            face += [2 * axis + int(side)] * n_face
    return np.vstack(pts), np.array(face)


def test_normals_of_a_sphere_point_outward():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(800, 3))
    p = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = estimate_normals(p, k=10)
    assert np.all(np.einsum("ij,ij->i", n, p) > 0.95)


def test_region_growing_splits_a_cube_into_its_six_faces():
    rng = np.random.default_rng(1)
    p, face = _cube(500, rng)
    _, nb = knn_graph(p, 12)
    n, var = pca_normals(p, nb)
    start = planar_start(p, n, nb, var, tol=0.01 * np.sqrt(3), normal_angle=25, min_region=10)
    assert start.count == 6
    matched = set()
    for r in range(6):
        f = face[start.labels == r]
        top = np.bincount(f, minlength=6)
        assert top.max() / len(f) > 0.98  # each region lies on one face
        assert top.max() > 0.85 * 500  # and covers most of it
        matched.add(int(np.argmax(top)))
    assert matched == set(range(6))
    rep = start.report(p, np.sqrt(3))
    assert rep["planes"] == 6 and rep["coverage"] > 0.85 and rep["mean_error"] < 1e-3
    # the faces that share an edge are adjacent, opposite faces are not
    graph = adjacency(start.labels, nb, 1)
    face_of = {r: int(np.argmax(np.bincount(face[start.labels == r], minlength=6))) for r in range(6)}
    for r, nbrs in graph.items():
        assert {face_of[q] // 2 for q in nbrs} == set(range(3)) - {face_of[r] // 2}


def test_link_counts_by_hand():
    labels = np.array([0, 0, 1, 1, -1])
    nb = np.array([[1, 2], [2, 3], [0, 4], [1, 0], [0, 2]])
    # links 0-2 (0->2), 1-2 (1->2), 1-3 (1->3), 2-0 (2->0), 3-1, 3-0: six links between 0 and 1
    assert link_counts(labels, nb) == {(0, 1): 6}


def test_read_vg(tmp_path):
    text = """num_points: 4
0 0 0
1 0 0
0 1 0
1 1 1
num_colors: 0
num_normals: 0
num_groups: 2
group_type: 0
num_group_parameters: 4
group_parameters: 0 0 1 0
group_label: unknown
group_color: 0.1 0.2 0.3
group_num_point: 2
0 2
num_children: 0
group_type: 0
num_group_parameters: 4
group_parameters: 0 1 0 0
group_label: unknown
group_color: 0.1 0.2 0.3
group_num_point: 1
1
num_children: 0
"""
    path = tmp_path / "a.vg"
    path.write_text(text)
    pts, labels = read_vg(path, n_points=4)
    assert pts.shape == (4, 3) and labels.tolist() == [0, 1, 0, -1]
    with pytest.raises(InputError, match="has 4 points, the input cloud has 5"):
        read_vg(path, n_points=5)
    path.write_text(text.replace("group_num_point: 1\n1", "group_num_point: 1\n9"))
    with pytest.raises(InputError, match="refers to point 9"):
        read_vg(path)
    path.write_text("num_pints: 3")
    with pytest.raises(InputError, match="expected 'num_points:'"):
        read_vg(path)
