"""Multi-patch fitting: a point cloud as a few trimmed NURBS patches (after NURBSFit).

Fuentes Perez, Lafarge and Pajarola, "NURBSFit: robust fitting of NURBS surfaces to point
clouds": start from planar regions, merge neighbouring regions into NURBS patches in the
order a quadric error suggests, keep a merge only when an energy of fidelity, simplicity
and completeness improves, and trim each patch in its (u, v) domain. One module per step;
:func:`fit_patches` is the driver (see :mod:`.driver` for the flow).

Example:
    >>> import numpy as np
    >>> from nurbskit.patches import fit_patches
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.random((400, 2))
    >>> len(fit_patches(np.c_[xy, np.zeros(400)]))
    1
"""

from .config import PatchConfig, config_from_dict, config_to_dict
from .driver import Patch, PatchSet, fit_patches

__all__ = ["fit_patches", "PatchSet", "Patch", "PatchConfig", "config_to_dict", "config_from_dict"]
