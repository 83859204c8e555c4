"""Isosurfaces, mesh projections, IoU and the OBJ / PLY writers."""

import numpy as np
import pytest
import torch
import trimesh

from nurbskit.io import write_mesh
from nurbskit.volume.mesh import Mesh, iou, isosurface, rasterize_projection
from nurbskit.volume.views import FRONT, TOP

from _assert import assert_close


def ball(n=33, centre=(0.5, 0.5, 0.5), radius=0.3):
    g = torch.linspace(0, 1, n, dtype=torch.float64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    r = ((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2).sqrt()
    return radius - r


def test_isosurface_of_a_ball_is_closed_outward_and_has_its_volume():
    mesh = isosurface(ball(), 0.0)
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert tm.is_watertight
    assert tm.volume > 0  # outward orientation
    assert tm.volume == pytest.approx(4 / 3 * np.pi * 0.3**3, rel=0.02)
    radii = np.linalg.norm(mesh.vertices - 0.5, axis=1)
    assert np.abs(radii - 0.3).max() < 0.01


def test_solid_touching_the_cube_is_capped_on_its_faces():
    field = torch.ones(6, 7, 8, dtype=torch.float64)  # everything inside
    mesh = isosurface(field, 0.5)
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert tm.is_watertight and tm.volume == pytest.approx(1.0, abs=1e-9)
    assert mesh.vertices.min() == 0.0 and mesh.vertices.max() == 1.0


def test_no_sample_above_the_isovalue_gives_an_empty_mesh():
    mesh = isosurface(ball(), 0.9)
    assert mesh.is_empty and mesh.vertices.shape == (0, 3)
    assert not rasterize_projection(mesh, FRONT, 8, 8).any()


def test_projection_of_a_ball_is_its_disc():
    mesh = isosurface(ball(49, centre=(0.6, 0.45, 0.5), radius=0.3), 0.0)
    n = 101
    r, c = np.mgrid[0:n, 0:n]
    x, y = c / (n - 1), 1 - r / (n - 1)
    disc = (x - 0.6) ** 2 + (y - 0.45) ** 2 <= 0.3**2
    image = rasterize_projection(mesh, FRONT, n, n)
    assert iou(image, disc) > 0.98
    # the top view sees (x, z): same disc centre in x, z = 0.5
    top = rasterize_projection(mesh, TOP, n, n)
    rows, cols = np.nonzero(top)
    assert abs(cols.mean() / (n - 1) - 0.6) < 0.01 and abs(rows.mean() / (n - 1) - 0.5) < 0.01


def test_projection_has_no_cracks_between_triangles():
    # a box spanning pixel centres exactly: every pixel inside must be set
    g = torch.linspace(0, 1, 11, dtype=torch.float64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    field = torch.minimum(torch.minimum(0.33 - (x - 0.5).abs(), 0.33 - (y - 0.5).abs()), 0.33 - (z - 0.5).abs())
    mesh = isosurface(field, 0.0)
    image = rasterize_projection(mesh, FRONT, 41, 41)
    r, c = np.mgrid[0:41, 0:41] / 40
    # inside |x - 0.5|, |y - 0.5| <= 0.32, less the corners that marching cubes chamfers
    inner = (np.abs(c - 0.5) <= 0.32) & (np.abs(r - 0.5) <= 0.32) & (np.abs(c - 0.5) + np.abs(r - 0.5) <= 0.5)
    assert image[inner].all()
    assert not image[(np.abs(c - 0.5) > 0.34) | (np.abs(r - 0.5) > 0.34)].any()


def test_iou():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), bool)
    assert iou(a, b) == 1.0
    a[:2] = True
    b[1:3] = True
    assert iou(a, b) == pytest.approx(4 / 12)


def test_isosurfaces_are_written_by_the_package_writer(tmp_path):
    # The volume has no writers of its own: nurbskit.io.write_mesh takes its meshes.
    import nurbskit.volume as volume
    import nurbskit.volume.mesh as volume_mesh

    assert not hasattr(volume_mesh, "write_obj") and not hasattr(volume_mesh, "write_ply")
    assert not hasattr(volume, "write_mesh")
    mesh = isosurface(ball(17), 0.0)
    for name in ("m.obj", "m.ply"):
        write_mesh(tmp_path / name, mesh.vertices, mesh.faces)
        loaded = trimesh.load(tmp_path / name, process=False, force="mesh")
        assert_close(loaded.vertices, mesh.vertices, atol=1e-6, msg=name)
        assert np.array_equal(loaded.faces, mesh.faces), name
