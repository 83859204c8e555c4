"""The energy of a configuration of patches (NURBSFit, equations 1-4).

    U = l_fid * U_f + l_simp * U_s + l_cov * U_c
    U_f = (1 / n_in) sum over inliers of d(p, S) / eps   (mean inlier distance, in [0, 1])
    U_s = |S| / |S_0|                                     (patches over the initial count)
    U_c = 1 - n_in / n                                     (the outlier ratio)

An inlier is a point within ``eps`` of its own patch. The paper writes the fidelity as
a Chamfer distance normalised between 0 and 1; dividing the true point-to-surface
distance by ``eps`` does exactly that for inliers.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Contribution:
    """What one patch adds to the energy: its inlier count and summed distance / eps."""

    inliers: int
    distance: float


def energy(total: Contribution, patches: int, initial_patches: int, points: int, weights) -> tuple[float, dict]:
    """``U`` and its parts ``{"fidelity", "simplicity", "completeness"}`` (the last is ``1 - U_c``).

    Example:
        >>> u, parts = energy(Contribution(90, 45.0), 2, 4, 100, (0.3, 0.4, 0.3))
        >>> round(u, 6), parts["fidelity"], parts["simplicity"], parts["completeness"]
        (0.38, 0.5, 0.5, 0.9)
    """
    l_fid, l_simp, l_cov = weights
    u_f = total.distance / total.inliers if total.inliers else 1.0
    u_s = patches / max(initial_patches, 1)
    completeness = total.inliers / points if points else 0.0
    u = l_fid * u_f + l_simp * u_s + l_cov * (1.0 - completeness)
    return float(u), {"fidelity": float(u_f), "simplicity": float(u_s), "completeness": float(completeness)}
