"""Drawings made by code: the paper's inconsistent set and silhouettes of known solids.

Used by the tests, the benchmark and ``examples/volume_drawings.py``, so that no binary
drawing has to live in the repository. Every function returns a float mask ``(H, W)``
(1 = shape) laid out as a drawing (row 0 at the top; see :mod:`nurbskit.volume.views`).
"""

from __future__ import annotations

from typing import Callable

import torch

from .views import VIEWS, project_grid

Tensor = torch.Tensor


def _image_coords(size: int) -> tuple[Tensor, Tensor]:
    """``(s, t)`` of every pixel: ``s`` = column / (W - 1) rightwards, ``t`` = 1 - row / (H - 1) upwards."""
    g = torch.linspace(0, 1, size, dtype=torch.float64)
    t, s = torch.meshgrid(1 - g, g, indexing="ij")
    return s, t


def square_drawing(size: int = 128, half: float = 0.3) -> Tensor:
    """An axis-aligned square of half-width ``half`` centred in the frame, ``(size, size)``."""
    s, t = _image_coords(size)
    return (((s - 0.5).abs() <= half) & ((t - 0.5).abs() <= half)).float()


def disc_drawing(size: int = 128, radius: float = 0.3) -> Tensor:
    """A centred disc, ``(size, size)``."""
    s, t = _image_coords(size)
    return (((s - 0.5) ** 2 + (t - 0.5) ** 2) <= radius**2).float()


def heart_drawing(size: int = 128, scale: float = 0.28) -> Tensor:
    """A heart, point down, centred: ``(x^2 + y^2 - 1)^3 - x^2 y^3 <= 0``, ``(size, size)``."""
    s, t = _image_coords(size)
    x = (s - 0.5) / scale
    y = (t - 0.45) / scale
    return (((x**2 + y**2 - 1) ** 3 - x**2 * y**3) <= 0).float()


def paper_drawings(size: int = 128) -> dict[str, Tensor]:
    """The paper's example (Fig. 2): square front, circle left, heart top. No solid matches all three."""
    return {"front": square_drawing(size), "left": disc_drawing(size), "top": heart_drawing(size)}


def sphere_and_box(x: Tensor, y: Tensor, z: Tensor) -> Tensor:
    """Occupancy of a sphere joined to a box, off-centre so that the three views differ."""
    sphere = (x - 0.33) ** 2 + (y - 0.55) ** 2 + (z - 0.5) ** 2 <= 0.2**2
    box = (x >= 0.4) & (x <= 0.8) & (y >= 0.3) & (y <= 0.62) & (z >= 0.32) & (z <= 0.68)
    return sphere | box


def solid_drawings(inside: Callable[[Tensor, Tensor, Tensor], Tensor], size: int = 128) -> dict[str, Tensor]:
    """The three drawings of a solid given by ``inside(x, y, z) -> bool`` on ``[0, 1]^3``.

    Sampled on a ``size^3`` grid and projected with the package's view convention, so the
    drawings are consistent by construction; each is ``(size, size)``.
    """
    g = torch.linspace(0, 1, size, dtype=torch.float64)
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    occupancy = inside(x, y, z)
    return {view.name: project_grid(occupancy, view).float() for view in VIEWS}
