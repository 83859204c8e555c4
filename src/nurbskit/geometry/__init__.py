"""Point sets: sampling meshes and NURBS, normalisation.

Submodules load on first use. Nearest neighbours live in :mod:`nurbskit.core.neighbors`
(one kernel for the core's projection, the losses and the fit).
"""

import importlib

_LAZY = {
    "sample_mesh": "nurbskit.geometry.sampling",
    "sample_parametric": "nurbskit.geometry.sampling",
    "nearest_neighbor_distances": "nurbskit.geometry.sampling",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'nurbskit.geometry' has no attribute {name!r}")


__all__ = list(_LAZY)
