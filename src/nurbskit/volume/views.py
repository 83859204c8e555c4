"""The one place that knows how drawings, the unit cube and the parameter grid line up.

Convention:
    The solid lies in the unit cube ``[0, 1]^3`` and the scalar field's parameters
    are its coordinates: ``(x, y, z) = (u, v, w)``, so a field sampled on a grid is an
    array ``F[i_x, i_y, i_z]`` (x on the first axis), exactly as
    :meth:`NURBSVolume.evaluate_grid` lays it out. Pixel ``(row r, column c)`` of an
    ``H x W`` drawing maps to

    ========  ======================  ======================  ==============
    view      column c ->             row r ->                projected along
    ========  ======================  ======================  ==============
    front     ``x = c / (W - 1)``     ``y = 1 - r / (H - 1)`` z
    left      ``z = c / (W - 1)``     ``y = 1 - r / (H - 1)`` x
    top       ``x = c / (W - 1)``     ``z = r / (H - 1)``     y
    ========  ======================  ======================  ==============

    so pixel centres sit on the grid points ``i / (N - 1)``, ends included (the
    ``align_corners=True`` convention of PyTorch). A drawing that is not square is
    stretched onto the unit square.

Everything that converts between an image ``(H, W)`` (row 0 at the top) and a plane of
the grid ``(N_a, N_b)`` in axis order goes through :func:`image_to_plane` and
:func:`plane_to_image`; nothing else in the package transposes or flips.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..errors import OptionError

Tensor = torch.Tensor

AXES = ("x", "y", "z")


@dataclass(frozen=True)
class View:
    """How one drawing relates to the cube.

    ``column_axis`` / ``row_axis`` are the cube axes (0 = x, 1 = y, 2 = z) that image
    columns and rows run along; ``row_flipped`` says that row 0 is the far end of
    ``row_axis`` (value 1). ``axis`` is the projection direction.
    """

    name: str
    axis: int
    column_axis: int
    row_axis: int
    row_flipped: bool

    @property
    def plane_axes(self) -> tuple[int, int]:
        """The two cube axes of the view plane in increasing order (the plane's array layout)."""
        return tuple(sorted((self.column_axis, self.row_axis)))  # type: ignore[return-value]


FRONT = View("front", axis=2, column_axis=0, row_axis=1, row_flipped=True)
LEFT = View("left", axis=0, column_axis=2, row_axis=1, row_flipped=True)
TOP = View("top", axis=1, column_axis=0, row_axis=2, row_flipped=False)
VIEWS: tuple[View, ...] = (FRONT, LEFT, TOP)
VIEW_NAMES = tuple(v.name for v in VIEWS)


def get_view(name: str) -> View:
    """The :class:`View` called ``name`` ('front', 'left' or 'top')."""
    for view in VIEWS:
        if view.name == name:
            return view
    raise OptionError(f"view must be one of {list(VIEW_NAMES)}, got {name!r}")


def image_to_plane(image: Tensor, view: View) -> Tensor:
    """Re-index an image ``(..., H, W)`` as a plane ``(..., N_a, N_b)`` over ``view.plane_axes``.

    Example: for the front view (plane axes x, y) ``plane[i_x, i_y] = image[H - 1 - i_y, i_x]``.
    """
    rows_flipped = image.flip(-2) if view.row_flipped else image
    # rows_flipped[..., i_row_axis, i_column_axis]; the plane wants the smaller axis first.
    if view.row_axis < view.column_axis:
        return rows_flipped
    return rows_flipped.transpose(-1, -2)


def plane_to_image(plane: Tensor, view: View) -> Tensor:
    """Inverse of :func:`image_to_plane`: ``(..., N_a, N_b)`` -> ``(..., H, W)``."""
    rows_first = plane if view.row_axis < view.column_axis else plane.transpose(-1, -2)
    return rows_first.flip(-2) if view.row_flipped else rows_first


def project_grid(grid: Tensor, view: View, reduce: str = "any") -> Tensor:
    """Project a grid ``(N_x, N_y, N_z)`` along the view direction into an image ``(H, W)``.

    ``reduce='any'`` is for boolean occupancy (a pixel is set when any cell on its ray
    is); ``'max'`` and ``'sum'`` work on real values. The image is laid out as the
    drawing of that view (see the module docstring).
    """
    if reduce == "any":
        plane = grid.any(dim=view.axis)
    elif reduce == "max":
        plane = grid.amax(dim=view.axis)
    elif reduce == "sum":
        plane = grid.sum(dim=view.axis)
    else:
        raise OptionError(f"reduce must be 'any', 'max' or 'sum', got {reduce!r}")
    return plane_to_image(plane, view)


def extrude(plane: Tensor, view: View) -> Tensor:
    """A plane ``(N_a, N_b)`` over ``view.plane_axes`` as a broadcastable 3-D tensor.

    Shapes: ``(N_a, N_b)`` -> the same values with a size-1 axis inserted at
    ``view.axis``, e.g. front ``(N_x, N_y)`` -> ``(N_x, N_y, 1)``.
    """
    return plane.unsqueeze(view.axis)


def points_to_pixels(points: Tensor, view: View, height: int, width: int) -> Tensor:
    """Continuous pixel coordinates ``(..., 2)`` as ``(row, column)`` of cube points ``(..., 3)``.

    The inverse of the pixel mapping in the module docstring: for the front view
    ``column = x (W - 1)`` and ``row = (1 - y) (H - 1)``.
    """
    col = points[..., view.column_axis] * (width - 1)
    t = points[..., view.row_axis]
    row = ((1 - t) if view.row_flipped else t) * (height - 1)
    return torch.stack([row, col], dim=-1)
