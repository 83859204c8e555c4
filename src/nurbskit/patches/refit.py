"""One NURBS patch for a set of points, with the project's own fitting, and its inliers.

:func:`fit_patch` runs :func:`nurbskit.fit.fit_surface` (least-squares start on the best
plane or, where the points wrap around, cylinder parametrisation; then alternating
projection + least squares and the ``default`` refinement of control points, weights and
knots, shortened), on a seeded subset of the points. The control grid starts at
``min_ctrl`` and grows (x 1.5) while too few points lie within ``eps / 2`` of the patch, up
to ``max_ctrl``: a patch gets the control points its shape needs (the paper fixes 4 x 4).
Where the points wrap around (:func:`nurbskit.fit.looks_closed`) the patch is closed in v
with a periodic seam (the paper's patches are open only).

:func:`point_distances` gives TRUE point-to-surface distances by Newton projection
(:func:`nurbskit.core.project.project_points`), not distances to the nearest of a grid of
samples, and :func:`bend_radii` the smallest radius of curvature at given parameters (used
to refuse a patch that rounds a sharp crease).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from ..core import NURBSSurface
from ..core.project import project_points
from ..fit import (SurfaceParameters, Target, Topology, alternate, fit_surface, get_pipeline, initial_surface, looks_closed,
                   run_stage)
from ..fit.lstsq import solve_control_points
from ..fit.init import plane_sheet


@dataclass
class PatchFit:
    """A fitted patch and where the points it was fitted to fall on it."""

    surface: NURBSSurface
    closed: bool
    params: np.ndarray
    """``(M, 2)`` foot-point parameters of the points."""
    distance: np.ndarray
    """``(M,)`` point-to-surface distances (input units)."""
    ctrl: tuple[int, int]
    fits: int = 1
    topology: Topology = Topology()


#: Newton's stopping step in :func:`point_distances`, relative to the control net's size.
FOOT_TOL = 1e-8


def point_distances(surface: NURBSSurface, points: np.ndarray, closed_v: bool = False, *,
                    start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Foot-point parameters ``(M, 2)`` and true distances ``(M,)`` of ``points (M, 3)``.

    The core's projection (:func:`nurbskit.core.project.project_points`); on a patch closed
    in v its Newton steps cross the seam (``periodic=(False, True)``), so a point whose foot
    point lies just across the seam does not stop on it. ``start (M, 2)``: warm-start
    parameters (e.g. a nearby point's foot point): Newton starts there instead of at the
    samples of a grid.

    Newton stops once a step moves the foot point by less than ``FOOT_TOL`` times the
    size of the control net, and convergence is checked after every iteration (on the CPU
    a check is one cheap host read, and it drops the converged points from the work): the
    distances differ from the core's default (``eps ** 0.75``, checked every 4) by about
    1e-14 of the patch's size (Newton converges quadratically, and a distance is
    stationary in its foot point), and a warm start, which converges in one or two steps,
    no longer runs four.
    """
    if len(points) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    x = torch.as_tensor(points, dtype=surface.dtype, device=surface.device)
    warm = None if start is None else torch.as_tensor(start, dtype=surface.dtype, device=surface.device)
    with torch.no_grad():
        proj = project_points(surface.detach(), x, periodic=(False, bool(closed_v)), params=warm, tol=FOOT_TOL,
                              check_every=1)
    return proj.params.cpu().double().numpy(), proj.distance.cpu().double().numpy()


def bend_radii(surface: NURBSSurface, params: np.ndarray) -> np.ndarray:
    """Smallest radius of curvature ``1 / max |k_i|`` at ``params (M, 2)`` -> ``(M,)``."""
    return bend(surface, params)[0]


def bend(surface: NURBSSurface, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smallest radius of curvature ``(M,)`` and unit normal ``(M, 3)`` at ``params (M, 2)``.

    Principal curvatures from the first and second fundamental forms (do Carmo, section
    3-3): ``k`` solves ``det(II - k I) = 0``.
    """
    if len(params) == 0:
        return np.zeros(0), np.zeros((0, 3))
    with torch.no_grad():
        d = surface.detach().derivatives(torch.as_tensor(params, dtype=surface.dtype, device=surface.device), order=2)
    d = d.cpu().double().numpy()
    su, sv = d[:, 1, 0], d[:, 0, 1]
    suu, suv, svv = d[:, 2, 0], d[:, 1, 1], d[:, 0, 2]
    n = np.cross(su, sv)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    E, F, G = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
    L, M, N = (suu * n).sum(1), (suv * n).sum(1), (svv * n).sum(1)
    det = np.maximum(E * G - F * F, 1e-300)
    H = (E * N - 2 * F * M + G * L) / (2 * det)
    K = (L * N - M * M) / det
    kmax = np.abs(H) + np.sqrt(np.maximum(H * H - K, 0.0))
    return 1.0 / np.maximum(kmax, 1e-300), n


def surface_normals(surface: NURBSSurface, params: np.ndarray) -> np.ndarray:
    """Unit normals ``(M, 3)`` of ``surface`` at ``params (M, 2)`` (first derivatives only)."""
    if len(params) == 0:
        return np.zeros((0, 3))
    with torch.no_grad():
        d = surface.detach().derivatives(torch.as_tensor(params, dtype=surface.dtype, device=surface.device), order=1)
    d = d.cpu().double().numpy()
    n = np.cross(d[:, 1, 0], d[:, 0, 1])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def plane_patch(points, ctrl: int | tuple[int, int], degree: int) -> NURBSSurface:
    """A flat patch on the best-fitting plane of ``points (M, 3)``, over their bounding rectangle.

    The fit's open start sheet (knots clamped, uniform on [0, 1]). ``points``: an array
    (taken as float64) or a tensor (kept on its device); ``ctrl``: control points per
    direction, one number or ``(n_u, n_v)``.
    """
    x = points if torch.is_tensor(points) else torch.as_tensor(points, dtype=torch.float64)
    surface, _ = plane_sheet(x, (ctrl, ctrl) if isinstance(ctrl, int) else tuple(ctrl), (degree, degree))
    return surface


def _fit_lsq(points: np.ndarray, ctrl: tuple[int, int], closed: bool, cfg, warm: np.ndarray | None = None):
    """A candidate fit: the fit's own least-squares start and alternation, nothing else.

    The same steps as :func:`nurbskit.fit.fit_surface` with no refinement iterations
    (:func:`~nurbskit.fit.initial_surface`, then :func:`~nurbskit.fit.alternate`, in the
    fit's units: centred, unit diagonal), called directly because the alternation's last
    foot points give every fitted point's distance: no second projection of the subset.
    ``warm (M, 2)``: foot parameters of the same points on an earlier, smaller open fit (a
    grid that grows): the larger grid is solved at those parameters instead of the plane
    parametrisation, and its alternation starts from them (no projection from a grid).
    Returns ``(surface, topology, params (M, 2), distance (M,))`` in input units.
    """
    if cfg.fit_iters:  # candidates with refinement iterations: the whole fit, then one projection
        surface, topology = _fit_once(points, ctrl, closed, cfg)
        params, dist = point_distances(surface, points, closed)
        return surface, topology, params, dist
    base = get_pipeline("default")
    x = torch.as_tensor(points, dtype=torch.float64).to(cfg.device)
    lo, hi = x.min(0).values, x.max(0).values
    center, scale = (lo + hi) / 2, float((hi - lo).norm())
    xn = (x - center) / scale
    start = None
    if warm is not None and not closed:
        # the grid grows: the earlier fit's foot points are a parametrisation of these points
        # that the new grid (same domain, [0, 1]^2) can be solved at directly
        start = torch.as_tensor(warm, dtype=xn.dtype, device=xn.device)
        template = plane_patch(xn, ctrl, cfg.degree)
        topology = Topology()
        cp = solve_control_points(start, xn, template.knot_vectors, template.degrees, template.sizes, None, topology,
                                  base.init.smoothness)
        surface = template._replace(control_points=cp)
    else:
        surface, topology = initial_surface(xn, base.init.kind, ctrl, (cfg.degree, cfg.degree),
                                            "v" if closed else "open", base.init.smoothness)
    surface, params, _ = alternate(surface, xn, cfg.fit_rounds, topology, base.alternation.smoothness,
                                   base.alternation.tolerance, params=start)
    with torch.no_grad():
        if params is None:  # no rounds: project once
            params = project_points(surface, xn, periodic=(False, topology.closed_v)).params
        dist = (surface.evaluate(params) - xn).norm(dim=-1) * scale
        surface = NURBSSurface(surface.control_points * scale + center, surface.degrees, surface.knot_vectors,
                               surface.weights)
    return (surface.detach().to(device="cpu"), topology, params.cpu().double().numpy(), dist.cpu().double().numpy())


def _fit_once(points: np.ndarray, ctrl: tuple[int, int], closed: bool, cfg, iters: int | None = None):
    base = get_pipeline("default")
    fit_cfg = dataclasses.replace(
        base,
        ctrl=ctrl,
        degree=(cfg.degree, cfg.degree),
        init=dataclasses.replace(base.init, closed="v" if closed else "open"),
        alternation=dataclasses.replace(base.alternation, rounds=cfg.fit_rounds),
        max_points=0,
        seed=cfg.seed,
    ).with_iters(cfg.fit_iters if iters is None else iters)
    # the fit runs where its points are: cfg.device only moves them
    result = fit_surface(torch.as_tensor(points, dtype=torch.float64).to(cfg.device), fit_cfg)
    return result.surface.to(device="cpu"), result.topology


def wrap_axis(points: np.ndarray) -> np.ndarray:
    """The axis ``(3,)`` a wrapped-around cloud turns about: the direction least seen by its normals.

    On a surface of revolution every normal is orthogonal to the axis, so the axis is the
    eigenvector of the smallest eigenvalue of the normals' second moment. Normals from PCA
    on the cloud's own kNN graph (:mod:`.normals`).
    """
    from .normals import knn_graph, pca_normals

    _, nb = knn_graph(points, 10)
    n, _ = pca_normals(points, nb)
    _, v = np.linalg.eigh(n.T @ n)
    return v[:, 0]


def _fit_closed(points: np.ndarray, ctrl: tuple[int, int], cfg):
    """A patch closed in v around the cloud's own axis (:func:`wrap_axis`).

    The fit's cylinder start turns about the direction of largest spread, which is not
    the axis of a short, wide tube (a cap-less can): there the cloud is first stretched
    along its axis until that is the largest spread, fitted, and mapped back (NURBS are
    affine invariant, so the map moves control points only), then polished in true
    distances by alternating projection and least squares. Returns what :func:`_fit_lsq`
    returns.
    """
    axis = wrap_axis(points)
    c = points.mean(0)
    rel = points - c
    along = rel @ axis
    across = rel - along[:, None] * axis
    var_along, var_across = along.var(), np.linalg.eigvalsh(np.cov(across.T))[-1]
    stretch = max(1.0, 1.5 * np.sqrt(var_across / max(var_along, 1e-300)))
    if stretch == 1.0:
        return _fit_lsq(points, ctrl, True, cfg)
    mapped = c + across + (stretch * along)[:, None] * axis
    surface, topology, params, dist = _fit_lsq(mapped, ctrl, True, cfg)
    cp = surface.control_points.detach().double()
    a = torch.as_tensor(axis)
    c_t = torch.as_tensor(c)
    h = (cp - c_t) @ a
    cp = cp - ((1.0 - 1.0 / stretch) * h)[..., None] * a
    surface = NURBSSurface(cp, surface.degrees, surface.knot_vectors, surface.weights)
    x = torch.as_tensor(points, dtype=torch.float64)
    if cfg.fit_rounds:
        # the map back moves control points only, so the stretched cloud's foot parameters
        # are close to the cloud's own: the polish starts from them, not from a grid
        surface, p, _ = alternate(surface, x, cfg.fit_rounds, topology, 1e-3, 1e-3,
                                  params=torch.as_tensor(params, dtype=x.dtype))
    else:
        p = project_points(surface, x, periodic=(False, True)).params
    with torch.no_grad():
        dist = (surface.evaluate(p) - x).norm(dim=-1)
    return surface.detach(), topology, p.double().numpy(), dist.double().numpy()


def fit_patch(points: np.ndarray, eps: float, cfg, *, rng: np.random.Generator | None = None,
              start_ctrl: tuple[int, int] | None = None) -> PatchFit:
    """Fit one patch to ``points (M, 3)`` (input units; ``eps`` the inlier tolerance there).

    ``cfg`` is a :class:`~nurbskit.patches.config.PatchConfig`. The grid grows while
    fewer than 95 % of the fitted subset lie within ``eps / 2`` (decided on the subset, with
    the distances the alternation's last foot points give). Then every point is projected
    once, warm-started at the foot point of its nearest subset point (a fitted subset point
    keeps its own), so Newton starts in the right basin and needs a few steps instead of a
    search over a grid. ``start_ctrl``: the grid to start from (a union starts at its
    parts' largest grid: a patch that grows by accretion does not climb the ladder from
    ``min_ctrl`` again at every merge). Returns the patch with every point's foot
    parameters and true distance.
    """
    rng = rng or np.random.default_rng(cfg.seed)
    pick = None if len(points) <= cfg.fit_points else rng.choice(len(points), cfg.fit_points, replace=False)
    sub = points if pick is None else points[pick]
    q = cfg.degree
    closed = bool(looks_closed(torch.as_tensor(sub))) and 2 * q + 2 <= cfg.max_ctrl
    n_u = n_v = cfg.min_ctrl
    if start_ctrl is not None:
        n_u = min(cfg.max_ctrl, max(n_u, int(start_ctrl[0])))
        n_v = min(cfg.max_ctrl, max(n_v, int(start_ctrl[1])))
    if closed:
        n_v = max(n_v, 2 * q + 2)
    best = None
    fits = 0
    while True:
        # a grown open grid starts from the last grid's foot points (warm), not from scratch
        warm = None if best is None else best[4]
        surface, topology, sub_params, sub_dist = _fit_closed(sub, (n_u, n_v), cfg) if closed else _fit_lsq(
            sub, (n_u, n_v), False, cfg, warm=warm)
        fits += 1
        good = float(np.mean(sub_dist < eps / 2))
        if best is None or good > best[0] + 0.005:
            best = (good, surface, (n_u, n_v), topology, sub_params)
        else:
            break  # a larger grid no longer helps
        if good >= 0.95 or (n_u >= cfg.max_ctrl and n_v >= cfg.max_ctrl):
            break
        n_u = min(cfg.max_ctrl, int(np.ceil(n_u * 1.5)))
        n_v = min(cfg.max_ctrl, int(np.ceil(n_v * 1.5)))
    _, surface, ctrl, topology, sub_params = best
    if pick is None:
        start = sub_params
    else:
        from ..core.neighbors import kdtree

        _, near = kdtree(sub).query(points, k=1)
        start = sub_params[near]
    params, dist = point_distances(surface, points, closed, start=start)
    return PatchFit(surface, closed, params, dist, ctrl, fits, topology)


def refine_patch(surface: NURBSSurface, topology: Topology, points: np.ndarray, cfg, *,
                 rng: np.random.Generator | None = None) -> NURBSSurface:
    """The ``default`` pipeline's refinement stage, started from an accepted patch.

    Candidates are compared with least-squares fits (fast); a winner then gets the
    refinement of control points, weights and knots of :func:`nurbskit.fit.run_stage`
    (``final_iters`` iterations, on up to ``final_points`` of its inliers; without the
    coverage term, which trimming replaces), in the fit's normalised units (centred, unit
    diagonal) and mapped back.
    """
    rng = rng or np.random.default_rng(cfg.seed)
    sub = points if len(points) <= cfg.final_points else points[rng.choice(len(points), cfg.final_points, replace=False)]
    pipeline = get_pipeline("default")
    # The coverage term pulls an untrimmed surface's border towards the data; a patch is
    # trimmed to its data instead, so only point-to-surface distance and smoothness remain.
    first = pipeline.stages[0]
    stage = dataclasses.replace(first, iters=cfg.final_iters, loss=dataclasses.replace(first.loss, coverage=0.0))
    x = torch.as_tensor(sub, dtype=torch.float64)
    lo, hi = x.min(0).values, x.max(0).values
    center, scale = (lo + hi) / 2, float((hi - lo).norm())
    start = surface.detach().to(torch.float64)
    start = start._replace(control_points=(start.control_points - center) / scale)
    params = SurfaceParameters(start, topology)
    run_stage(params, stage, Target(points=(x - center) / scale), tuple(pipeline.resolution))
    with torch.no_grad():
        out = params.surface()
        return NURBSSurface(out.control_points * scale + center, out.degrees, out.knot_vectors, out.weights)


def crease_fraction(surface: NURBSSurface, params: np.ndarray, min_radius: float, limit: int = 4000) -> float:
    """Fraction of the given foot points where the patch bends tighter than ``min_radius``."""
    return crease_stats(surface, params, min_radius, limit=limit)[0]


def crease_stats(surface: NURBSSurface, params: np.ndarray, min_radius: float, *, limit: int = 4000,
                 model_normals: np.ndarray | None = None, max_angle: float = 90.0) -> tuple[float, float]:
    """``(tight, turned)``: how much of a patch bends tightly, and how much of that rounds a crease.

    ``tight`` is the fraction of the foot points ``params (M, 2)`` where the patch bends
    tighter than ``min_radius``; ``turned`` the fraction of those tight points where its
    normal turns more than ``max_angle`` degrees away from ``model_normals (M, 3)``, the
    normal each point had in the part it came from (a planar region's plane normal, a
    fitted part's surface normal); 0 without ``model_normals``. Across a sharp edge the
    parts are flat up to the edge, so a patch that rounds it turns away from both parts
    on much of its bend; a fillet cut into planar strips keeps each strip's normal within
    the strips' angular tolerance, so a patch that follows the fillet bends tightly while
    staying close to its parts' normals.
    """
    if len(params) == 0:
        return 0.0, 0.0
    if len(params) > limit:
        pick = np.linspace(0, len(params) - 1, limit).astype(int)
        params = params[pick]
        model_normals = None if model_normals is None else model_normals[pick]
    radii, normals = bend(surface, params)
    tight = radii < min_radius
    if model_normals is None or not tight.any():
        return float(np.mean(tight)), 0.0
    cos = np.abs((normals[tight] * model_normals[tight]).sum(1))
    return float(np.mean(tight)), float(np.mean(cos < np.cos(np.radians(max_angle))))
