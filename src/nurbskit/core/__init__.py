"""Pure-torch NURBS math: knots, basis, tensor-product evaluation, curve/surface/volume."""

from .basis import basis_function_derivatives, basis_functions, basis_matrix
from .curve import NURBSCurve
from .knots import clamped_uniform, find_spans, knots_to_logits, logits_to_knots
from .ops import decompose_bezier, elevate_degree, insert_knot, refine_knots, reverse, split
from .serialize import from_dict, from_geomdl, load, save, to_dict, to_geomdl
from .spline import TensorSpline
from .surface import NURBSSurface
from .volume import NURBSVolume

__all__ = [
    "NURBSCurve", "NURBSSurface", "NURBSVolume", "TensorSpline",
    "basis_functions", "basis_function_derivatives", "basis_matrix",
    "clamped_uniform", "find_spans", "knots_to_logits", "logits_to_knots",
    "insert_knot", "refine_knots", "elevate_degree", "split", "reverse", "decompose_bezier",
    "save", "load", "to_dict", "from_dict", "to_geomdl", "from_geomdl",
]
