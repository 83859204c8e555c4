"""Point sets: sampling meshes and NURBS, neighbours, normalisation.

Submodules load on first use (``nurbskit.geometry.neighbors`` belongs to the fitting
side and pulls in more than sampling needs).
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
