"""Surfaces of revolution and extrusions from point clouds, as exact rational NURBS.

Geometric path of issue 11 (DeepSpline, section 5, without the network): normals by
PCA, the axis by line geometry, the profile by ordering and least squares, then a
refinement by point-to-surface distance. See :mod:`.fit` and ``docs/shapes.md``.
"""

from .axis import Axis, axis_angle_degrees, extrusion_direction, revolution_axis
from .fit import KINDS, ShapeFit, fit_extrusion, fit_revolution, fit_shape
from .init import INITS, plane_basis
from .normals import estimate_normals
from .profile import fit_curve_lsq, fit_profile, order_points

__all__ = [
    "Axis", "axis_angle_degrees", "extrusion_direction", "revolution_axis",
    "KINDS", "ShapeFit", "fit_extrusion", "fit_revolution", "fit_shape",
    "INITS", "plane_basis", "estimate_normals", "fit_curve_lsq", "fit_profile", "order_points",
]
