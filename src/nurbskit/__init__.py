"""nurbskit: differentiable NURBS in PyTorch, and NURBS geometry from what people have.

Example:
    >>> import torch, nurbskit
    >>> surface = nurbskit.NURBSSurface(torch.rand(6, 5, 3), degrees=(3, 2))
    >>> surface.sample((16, 16)).shape
    torch.Size([16, 16, 3])
"""

import importlib

__version__ = "0.1.0"

from .core import (  # noqa: E402
    NURBSCurve,
    NURBSSurface,
    NURBSVolume,
    from_geomdl,
    load,
    save,
    to_geomdl,
)
from .errors import InputError, NurbskitError, OptionError  # noqa: E402

# Heavier parts load on first use, so `import nurbskit` stays light.
_LAZY = {
    "project_points": "nurbskit.core.project",
    "tessellate": "nurbskit.core.tessellate",
    "insert_knot": "nurbskit.core.ops",
    "refine_knots": "nurbskit.core.ops",
    "elevate_degree": "nurbskit.core.ops",
    "split": "nurbskit.core.ops",
    "reverse": "nurbskit.core.ops",
    "decompose_bezier": "nurbskit.core.ops",
    "sample_mesh": "nurbskit.geometry.sampling",
    "fit_surface": "nurbskit.fit",
    "fit_silhouettes": "nurbskit.volume",
    "io": "nurbskit.io",
    "losses": "nurbskit.losses",
    "metrics": "nurbskit.metrics",
}


def __getattr__(name: str):
    if name in _LAZY:
        module = importlib.import_module(_LAZY[name])
        return module if module.__name__.endswith("." + name) else getattr(module, name)
    raise AttributeError(f"module 'nurbskit' has no attribute {name!r}")


__all__ = [
    "NURBSCurve", "NURBSSurface", "NURBSVolume",
    "save", "load", "to_geomdl", "from_geomdl",
    "NurbskitError", "InputError", "OptionError",
    *_LAZY,
]
