"""NURBS volumes from three drawings (front, left, top): W. Li, "Multi-view NURBS Volume".

Public API:

* :func:`fit_silhouettes` -> :class:`SilhouetteFit` (``volume, mesh = fit_silhouettes(f, l, t)``)
* :func:`load_drawing`: files / images / arrays -> masks ``(H, W)``
* :mod:`.views`: the axis and pixel convention (the one place that defines it)
* :mod:`.losses`: the paper's costs and the silhouette cost
* :mod:`.mesh`: isosurface, projections, IoU, OBJ / PLY writers
* :mod:`.shapes`: drawings made by code (the paper's set, silhouettes of known solids)
"""

from .drawings import load_drawing
from .field import GridField
from .fit import LOSSES, SilhouetteFit, VolumeFitConfig, fit_silhouettes, projection_iou, visual_hull_iou
from .mesh import Mesh, isosurface, rasterize_projection, write_mesh
from .views import VIEWS, View, get_view

__all__ = [
    "fit_silhouettes",
    "SilhouetteFit",
    "VolumeFitConfig",
    "LOSSES",
    "load_drawing",
    "GridField",
    "Mesh",
    "isosurface",
    "rasterize_projection",
    "write_mesh",
    "projection_iou",
    "visual_hull_iou",
    "VIEWS",
    "View",
    "get_view",
]
