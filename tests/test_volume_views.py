"""The view convention: pixels <-> cube axes, in one place (nurbskit.volume.views)."""

import numpy as np
import pytest
import torch
from _assert import assert_close

from nurbskit.errors import OptionError
from nurbskit.volume.drawings import mask_on_plane
from nurbskit.volume.losses import visual_hull
from nurbskit.volume.mesh import isosurface, rasterize_projection
from nurbskit.volume.views import (
    FRONT,
    LEFT,
    TOP,
    VIEWS,
    get_view,
    image_to_plane,
    plane_to_image,
    points_to_pixels,
    project_grid,
)

H = W = 41  # pixel (r, c) sits at c / 40, r / 40


def dot(row: int, col: int, radius: int = 3) -> torch.Tensor:
    r, c = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    return (((r - row) ** 2 + (c - col) ** 2) <= radius**2).float()


def test_dot_drawings_map_to_the_stated_octant():
    # The point (x, y, z) = (0.8, 0.75, 0.25), drawn by hand from the table in views.py:
    # front: c = x * 40 = 32, r = (1 - y) * 40 = 10;  left: c = z * 40 = 10, r = 10;
    # top:   c = x * 40 = 32, r = z * 40 = 10.
    drawings = {"front": dot(10, 32), "left": dot(10, 10), "top": dot(10, 32)}
    sizes = (H, H, H)
    hull = visual_hull({v.name: mask_on_plane(drawings[v.name], v, sizes) for v in VIEWS})
    idx = torch.nonzero(hull > 0.5).float() / (H - 1)
    assert len(idx) > 0
    centre = idx.mean(0)
    assert_close(centre, torch.tensor([0.8, 0.75, 0.25]), atol=0.02)
    # every occupied cell is in the octant x > 1/2, y > 1/2, z < 1/2
    assert (idx[:, 0] > 0.5).all() and (idx[:, 1] > 0.5).all() and (idx[:, 2] < 0.5).all()


def test_a_voxel_projects_to_the_pixels_of_the_table():
    grid = torch.zeros(H, H, H, dtype=torch.bool)
    ix, iy, iz = 30, 5, 12  # x = 0.75, y = 0.125, z = 0.3
    grid[ix, iy, iz] = True
    expected = {"front": (H - 1 - iy, ix), "left": (H - 1 - iy, iz), "top": (iz, ix)}
    for view in VIEWS:
        image = project_grid(grid, view)
        assert image.shape == (H, W)
        assert torch.nonzero(image).tolist() == [list(expected[view.name])], view.name


def test_points_to_pixels_agrees_with_project_grid():
    point = torch.tensor([[0.75, 0.125, 0.3]], dtype=torch.float64)
    for view, rc in zip(VIEWS, [(35.0, 30.0), (35.0, 12.0), (12.0, 30.0)]):
        assert_close(points_to_pixels(point, view, H, W)[0], torch.tensor(rc, dtype=torch.float64), msg=str(view.name))


def test_mesh_projection_lands_where_the_solid_is():
    # a small ball around (0.8, 0.7, 0.2): its silhouettes centre on the table's pixels
    g = torch.linspace(0, 1, 33, dtype=torch.float64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    field = 0.12 - ((x - 0.8) ** 2 + (y - 0.7) ** 2 + (z - 0.2) ** 2).sqrt()
    mesh = isosurface(field, 0.0)
    for view, (r, c) in zip(VIEWS, [(0.3 * 40, 0.8 * 40), (0.3 * 40, 0.2 * 40), (0.2 * 40, 0.8 * 40)]):
        image = rasterize_projection(mesh, view, H, W)
        rows, cols = np.nonzero(image)
        assert abs(rows.mean() - r) < 0.6 and abs(cols.mean() - c) < 0.6, view.name


@pytest.mark.parametrize("view", VIEWS, ids=lambda v: v.name)
def test_image_plane_round_trip(view):
    image = torch.arange(6 * 7).reshape(6, 7)
    plane = image_to_plane(image, view)
    # the plane is indexed by the sorted cube axes; its sizes follow the image's
    sizes = {view.row_axis: 6, view.column_axis: 7}
    assert tuple(plane.shape) == tuple(sizes[a] for a in view.plane_axes)
    assert torch.equal(plane_to_image(plane, view), image)


def test_views_are_three_distinct_directions():
    assert sorted(v.axis for v in VIEWS) == [0, 1, 2]
    assert get_view("top") is TOP and get_view("front") is FRONT and get_view("left") is LEFT
    with pytest.raises(OptionError, match="view must be one of"):
        get_view("back")
