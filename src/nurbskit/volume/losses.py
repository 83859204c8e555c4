"""What the silhouette fit minimises: the paper's costs and a projection (silhouette) cost.

All costs are means over the grid, i.e. the integrals over the unit cube of the paper
(eqs. 2, 3) approximated on the grid; all inputs are ``(R, S, T)`` tensors laid out
``[x, y, z]`` (see :mod:`nurbskit.volume.views`).

* ``paper`` shape cost (eq. 2): ``mean (g - f)^2`` with ``g`` the product of the three
  extruded drawings, i.e. the visual hull's indicator ``x(u, v) y(w, u) z(w, v)``.
* smoothness cost (eq. 3): ``mean (lap f)^2``. The paper writes the integral of the
  Laplacian itself; that is a boundary flux, linear in the control values and
  unbounded below, so what can be minimised is its square (a thin-plate energy). The
  Laplacian is measured with lengths in a fixed unit (``laplacian_unit``, default
  1/100 of the cube: ``unit^2 lap f``), so the cost does not change with the grid
  resolution or the control size and the 0.1 / 0.9 weights keep their balance.
* ``silhouette`` shape cost: the field's projection along each view, softened as
  ``P = sigmoid(s (max_ray f - C))``, compared with each drawing: ``mean_views mean (P - D)^2``. It
  scores what a user sees, so drawings that no solid matches exactly still pull the
  solid towards the closest one instead of towards their (possibly tiny) intersection.
"""

from __future__ import annotations

from typing import Mapping

import torch

from .views import VIEWS, View, extrude

Tensor = torch.Tensor


def visual_hull(planes: Mapping[str, Tensor]) -> Tensor:
    """The paper's ``g``: product of the extruded drawings, ``(N_x, N_y, N_z)``.

    ``planes[name]`` is a drawing resampled onto its view plane (``drawings.mask_on_plane``).
    """
    g = None
    for view in VIEWS:
        e = extrude(planes[view.name], view)
        g = e if g is None else g * e
    return g


def paper_shape_cost(field: Tensor, hull: Tensor) -> Tensor:
    """Eq. 2: ``mean (g - f)^2`` over the grid; ``(R, S, T)``, ``(R, S, T)`` -> scalar."""
    return torch.mean((hull - field) ** 2)


def smoothness_cost(laplacian: Tensor) -> Tensor:
    """Eq. 3 squared: ``mean (lap f)^2`` over the grid; ``(R, S, T)`` -> scalar."""
    return torch.mean(laplacian**2)


def soft_projection(field: Tensor, view: View, isovalue: float, sharpness: float) -> Tensor:
    """Soft silhouette of ``{f >= isovalue}`` along ``view``: ``(N_x, N_y, N_z)`` -> plane ``(N_a, N_b)``.

    ``sigmoid(s (max_ray f - C))``: a pixel is seen exactly when the largest value on its
    ray reaches the isovalue, which is what the marching-cubes solid shows. (A soft OR
    of per-sample occupancies would let many samples just below ``C`` add up to a
    pixel that the extracted surface does not cover.) The gradient reaches the
    largest sample of each ray.
    """
    return torch.sigmoid(sharpness * (field.amax(dim=view.axis) - isovalue))


def silhouette_cost(
    field: Tensor, planes: Mapping[str, Tensor], isovalue: float, sharpness: float
) -> Tensor:
    """Mean over the three views of ``mean (P_view - D_view)^2``; ``(R, S, T)`` -> scalar."""
    total = field.new_zeros(())
    for view in VIEWS:
        total = total + torch.mean((soft_projection(field, view, isovalue, sharpness) - planes[view.name]) ** 2)
    return total / len(VIEWS)
