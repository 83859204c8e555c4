"""Pure-torch NURBS math: knots, basis, tensor-product evaluation, curve/surface/volume.

The knot operations (:mod:`nurbskit.core.ops`, which imports scipy) and file
serialisation load lazily, on first use of one of their names.
"""

from importlib import import_module

from .basis import basis_function_derivatives, basis_functions, basis_matrix
from .curve import NURBSCurve
from .knots import clamped_uniform, find_spans, knot_tolerance, knots_to_logits, logits_to_knots
from .spline import TensorSpline
from .surface import NURBSSurface
from .volume import NURBSVolume

_LAZY = {
    "insert_knot": "ops", "refine_knots": "ops", "elevate_degree": "ops", "split": "ops",
    "reverse": "ops", "decompose_bezier": "ops",
    "save": "serialize", "load": "serialize", "to_dict": "serialize", "from_dict": "serialize",
    "to_geomdl": "serialize", "from_geomdl": "serialize",
}

__all__ = [
    "NURBSCurve", "NURBSSurface", "NURBSVolume", "TensorSpline",
    "basis_functions", "basis_function_derivatives", "basis_matrix",
    "clamped_uniform", "find_spans", "knot_tolerance", "knots_to_logits", "logits_to_knots",
    "insert_knot", "refine_knots", "elevate_degree", "split", "reverse", "decompose_bezier",
    "save", "load", "to_dict", "from_dict", "to_geomdl", "from_geomdl",
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
