"""nurbskit: differentiable NURBS in PyTorch, and NURBS geometry from what people have.

Example:
    >>> import torch, nurbskit
    >>> surface = nurbskit.NURBSSurface(torch.rand(6, 5, 3), degrees=(3, 2))
    >>> surface.sample((16, 16)).shape
    torch.Size([16, 16, 3])
"""

import importlib

__version__ = "0.1.0"

from .errors import InputError, NurbskitError, OptionError  # noqa: E402

# Everything that needs torch loads on first use, so `import nurbskit` (and with it the
# command line's start-up, where Ctrl-C must stay one line) imports no torch.
# name -> (module, attribute); attribute None means the module itself.
_LAZY = {
    "NURBSCurve": ("nurbskit.core", "NURBSCurve"),
    "NURBSSurface": ("nurbskit.core", "NURBSSurface"),
    "NURBSVolume": ("nurbskit.core", "NURBSVolume"),
    "from_geomdl": ("nurbskit.core", "from_geomdl"),
    "load": ("nurbskit.core", "load"),
    "save": ("nurbskit.core", "save"),
    "to_geomdl": ("nurbskit.core", "to_geomdl"),
    "project_points": ("nurbskit.core.project", "project_points"),
    "tessellate": ("nurbskit.core.tessellate", "tessellate"),
    "insert_knot": ("nurbskit.core.ops", "insert_knot"),
    "refine_knots": ("nurbskit.core.ops", "refine_knots"),
    "elevate_degree": ("nurbskit.core.ops", "elevate_degree"),
    "split": ("nurbskit.core.ops", "split"),
    "reverse": ("nurbskit.core.ops", "reverse"),
    "decompose_bezier": ("nurbskit.core.ops", "decompose_bezier"),
    "sample_mesh": ("nurbskit.geometry.sampling", "sample_mesh"),
    "fit_surface": ("nurbskit.fit", "fit_surface"),
    "revolve": ("nurbskit.core.construct", "revolve"),
    "extrude": ("nurbskit.core.construct", "extrude"),
    "fit_silhouettes": ("nurbskit.volume", "fit_silhouettes"),
    "fit_patches": ("nurbskit.patches", "fit_patches"),
    "curves_from_image": ("nurbskit.curves.api", "curves_from_image"),
    "revolve_image": ("nurbskit.shapes.image", "revolve_image"),
    "io": ("nurbskit.io", None),
    "losses": ("nurbskit.losses", None),
    "metrics": ("nurbskit.metrics", None),
}


def __getattr__(name: str):
    if name in _LAZY:
        module_name, attribute = _LAZY[name]
        module = importlib.import_module(module_name)
        return module if attribute is None else getattr(module, attribute)
    raise AttributeError(f"module 'nurbskit' has no attribute {name!r}")


__all__ = [
    "NurbskitError", "InputError", "OptionError",
    *_LAZY,
]
