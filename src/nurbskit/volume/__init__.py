"""NURBS volumes from three drawings (front, left, top): W. Li, "Multi-view NURBS Volume".

Public API:

* :func:`fit_silhouettes` -> :class:`SilhouetteFit` (``volume, mesh = fit_silhouettes(drawings, config)``)
* :class:`VolumeFitConfig` and its presets ``default`` and ``paper`` (:func:`get_preset`)
* :func:`load_drawing`: files / images / arrays -> masks ``(H, W)``
* :mod:`.views`: the axis and pixel convention (the one place that defines it)
* :mod:`.losses`: the paper's costs and the silhouette cost
* :mod:`.mesh`: isosurface, projections, IoU (meshes are written by :func:`nurbskit.io.write_mesh`)
* :mod:`.shapes`: drawings made by code (the paper's set, silhouettes of known solids)
"""

from .drawings import load_drawing
from .field import GridField
from .config import LOSSES, PRESETS, VolumeFitConfig, get_preset
from .fit import SilhouetteFit, VolumeFitFailed, fit_silhouettes, projection_iou, visual_hull_iou
from .mesh import Mesh, isosurface, rasterize_projection
from .views import VIEWS, View, get_view

__all__ = [
    "fit_silhouettes",
    "SilhouetteFit",
    "VolumeFitConfig",
    "VolumeFitFailed",
    "PRESETS",
    "get_preset",
    "LOSSES",
    "load_drawing",
    "GridField",
    "Mesh",
    "isosurface",
    "rasterize_projection",
    "projection_iou",
    "visual_hull_iou",
    "VIEWS",
    "View",
    "get_view",
]
