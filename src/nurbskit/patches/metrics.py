"""Quality of a set of trimmed patches (NURBSFit, section 4, and its supplementary material).

All distances are normalised by the input's bounding-box diagonal and compared with
``eps`` (1 % of the diagonal unless set):

* ``E_fid``: mean distance of the inliers to their patch, in percent of ``eps``;
* ``completeness``: percentage of input points that are inliers of their patch;
* ``P_cov_i``: percentage of input points within ``eps`` of the trimmed output;
* ``P_cov_o``: percentage of area-uniform samples of the trimmed output within ``eps``
  of the input;
* ``N``: the number of patches;
* ``iou`` (labelled input only): mean over the true segments of the IoU with the patch
  matched to it by the Hungarian method (unmatched segments count 0).

P_cov^i and P_cov^o use area-uniform samples of the trimmed meshes, spaced about
``eps / 5`` apart (:func:`nurbskit.geometry.sampling.sample_mesh`). An input point's
distance to the output is the smaller of its distance to the nearest sample and, for an
inlier, its true distance to its own patch (its foot point lies inside the trim): the
sample distance over-estimates by at most about half the spacing, so P_cov^i is, if
anything, under-reported.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from ..geometry.sampling import sample_mesh


def segmentation_iou(predicted: np.ndarray, truth: np.ndarray) -> float:
    """Hungarian-matched mean IoU in [0, 1] of ``predicted (N,)`` (-1: no patch) against ``truth (N,)``.

    Example:
        >>> round(segmentation_iou(np.array([0, 0, 1, 1]), np.array([5, 5, 5, 7])), 4)
        0.5833
    """
    predicted = np.asarray(predicted)
    truth = np.asarray(truth)
    t_ids, t_idx = np.unique(truth, return_inverse=True)
    has = predicted >= 0
    p_ids, p_idx = np.unique(predicted[has], return_inverse=True)
    if len(t_ids) == 0:
        return 0.0
    if len(p_ids) == 0:
        return 0.0
    inter = np.zeros((len(t_ids), len(p_ids)))
    np.add.at(inter, (t_idx[has], p_idx), 1.0)
    t_size = np.bincount(t_idx, minlength=len(t_ids)).astype(float)
    p_size = np.bincount(p_idx, minlength=len(p_ids)).astype(float)
    union = t_size[:, None] + p_size[None, :] - inter
    iou = inter / np.maximum(union, 1.0)
    rows, cols = linear_sum_assignment(-iou)
    return float(iou[rows, cols].sum() / len(t_ids))


def output_samples(meshes: list[tuple[np.ndarray, np.ndarray]], spacing: float, seed: int = 0,
                   cap: int = 400_000) -> np.ndarray:
    """Area-uniform samples ``(S, 3)`` of the trimmed meshes, about ``spacing`` apart (at most ``cap``)."""
    meshes = [(v, f) for v, f in meshes if len(f)]
    if not meshes:
        return np.zeros((0, 3))
    offset, vs, fs = 0, [], []
    for v, f in meshes:
        vs.append(v)
        fs.append(f + offset)
        offset += len(v)
    v, f = np.concatenate(vs), np.concatenate(fs)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()
    n = int(np.clip(area / spacing**2, 1000, cap))
    keep = np.flatnonzero(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1) > 0)
    return sample_mesh(v, f[keep], n, method="uniform", seed=seed)


def patch_metrics(
    points: np.ndarray,
    labels: np.ndarray,
    inlier_distance: np.ndarray,
    meshes: list[tuple[np.ndarray, np.ndarray]],
    eps: float,
    *,
    truth: np.ndarray | None = None,
    seed: int = 0,
) -> dict:
    """Every metric of the module docstring, as percentages (``N`` a count).

    Shapes: ``points (N, 3)``; ``labels (N,)`` patch per point, -1 for outliers;
    ``inlier_distance (N,)`` each inlier's distance to its patch (ignored for outliers);
    ``meshes`` the trimmed mesh of every patch (``vertices (V, 3)``, ``faces (F, 3)``);
    ``eps`` in the points' units; ``truth (N,)`` optional true segment labels.
    """
    n = len(points)
    inl = labels >= 0
    diag = float(np.linalg.norm(points.max(0) - points.min(0))) if n else 1.0
    out = {
        "E_fid": float(100.0 * inlier_distance[inl].mean() / eps) if inl.any() else 0.0,
        "completeness": float(100.0 * inl.mean()) if n else 0.0,
        "N": int(len(np.unique(labels[inl]))),
        "eps": float(eps / diag) if diag else 0.0,
    }
    samples = output_samples(meshes, eps / 5, seed)
    if len(samples) and n:
        d_in, _ = cKDTree(samples).query(points, k=1)
        # an inlier's true distance to its patch is exact (its foot point lies in the trim)
        d_in = np.where(inl, np.minimum(d_in, inlier_distance), d_in)
        d_out, _ = cKDTree(points).query(samples, k=1)
        out["P_cov_i"] = float(100.0 * np.mean(d_in < eps))
        out["P_cov_o"] = float(100.0 * np.mean(d_out < eps))
        out["input_to_output_mean"] = float(d_in.mean() / diag)
    else:
        out["P_cov_i"] = out["P_cov_o"] = 0.0
        out["input_to_output_mean"] = float("nan")
    out["output_samples"] = int(len(samples))
    if truth is not None:
        out["iou"] = float(100.0 * segmentation_iou(labels, truth))
    return out


def pcov_o_ceiling(points: np.ndarray, eps: float, k: int = 8) -> float:
    """What P_cov^o a perfect answer reaches at this cloud's sampling density (percent), estimated.

    A perfect answer is the sampled surface itself; a point of it counts when an input point
    lies within ``eps``. If the input is a Poisson sample of local density ``rho`` (points
    per area, from the distance to the k-th neighbour: ``rho = k / (pi r_k^2)``), that
    happens with probability ``1 - exp(-rho pi eps^2)``; averaged over the surface (each
    input point standing for ``1 / rho`` of area). Blue-noise or grid sampling covers more,
    so this is a lower estimate of the ceiling for them.
    """
    d, _ = cKDTree(points).query(points, k=k + 1)
    rho = k / (np.pi * np.maximum(d[:, -1], 1e-300) ** 2)
    area = 1.0 / rho
    return float(100.0 * np.sum(area * (1.0 - np.exp(-rho * np.pi * eps * eps))) / np.sum(area))
