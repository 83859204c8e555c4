"""Surfaces of revolution and extrusions fitted to point clouds, exactly.

Pipeline (``fit_shape``):

1. normals, estimated by local PCA when the cloud has none (:mod:`.normals`);
2. the axis (:func:`.axis.revolution_axis`, line geometry) or the direction
   (:func:`.axis.extrusion_direction`);
3. the profile: (distance to the axis, height) pairs for a revolution, the projection
   onto the plane orthogonal to the direction for an extrusion, ordered and fitted as a
   B-spline (:mod:`.profile`); the sweep's extent from the data (the angular gap of a
   partial revolution, the height range of an extrusion);
4. the exact NURBS (:func:`nurbskit.core.construct.revolve` / ``extrude``);
5. refinement: profile control points, weights, and the axis (or direction and extent)
   minimise the mean squared point-to-surface distance, the distances coming from the
   core's projection (:func:`nurbskit.core.project.project_points`, warm-started, with
   gradients by the envelope theorem), by L-BFGS (strong Wolfe line search).

``kind="auto"`` fits both and keeps the one with the smaller mean distance; when neither
is within ``auto_tolerance`` of the bounding-box diagonal it fits a free-form surface
(:func:`nurbskit.fit_surface`). ``ShapeFit.reason`` says which and why.

Convention: work is done in float64 on the CPU; ``points (N, 3)``; distances in reports
are divided by the bounding-box diagonal of the points.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from ..core.construct import extrude, revolve
from ..core.curve import NURBSCurve
from ..core.project import project_points
from ..core.surface import NURBSSurface
from ..errors import InputError, OptionError
from ..fit.optim import LBFGS
from .axis import extrusion_direction, revolution_axis
from .init import INITS, network_guess, plane_basis
from .normals import estimate_normals
from .profile import closing_matrix, fit_profile

Tensor = torch.Tensor
F64 = torch.float64

__all__ = ["ShapeFit", "fit_shape", "fit_revolution", "fit_extrusion", "KINDS", "PLANE_THICKNESS", "MAX_ITERATIONS"]

KINDS = ("revolution", "extrusion", "auto")
PLANE_THICKNESS = 1e-3
"""A cloud thinner than this fraction of its extent is a plane: it has no axis."""
AUTO_TIE = 1e-4
"""``auto``: mean distances (over the diagonal) closer than this are a tie (revolution wins)."""
MAX_ITERATIONS = 100_000
"""The most refinement iterations (L-BFGS) a fit takes, as ``nurbskit volume --iters``; ``shape --iters``'s range."""


@dataclass
class ShapeFit:
    """A fitted shape.

    ``kind``: 'revolution', 'extrusion' or 'freeform'; ``surface``: the exact NURBS;
    ``axis``: ``{"point", "direction"}`` (the extrusion direction for extrusions, None for
    free-form); ``profile``: the profile curve in its plane, ``(n, 2)`` control points
    ((radius, height) about the axis, or the two in-plane coordinates of an extrusion);
    ``profile_frame``: origin and the two 3-D unit vectors of that plane; ``angle``
    (revolution) or ``extent`` (extrusion); ``init``: where the fit started ('geometric' or
    'network'); ``distance_mean`` / ``distance_p95``: point to
    surface over the diagonal; ``seconds``; ``reason``; ``candidates``: the other kinds'
    mean distances (auto).
    """

    kind: str
    surface: NURBSSurface
    axis: dict | None
    profile: NURBSCurve | None
    profile_frame: dict | None
    distance_mean: float
    distance_p95: float
    diagonal: float
    seconds: float = 0.0
    reason: str = ""
    angle: float | None = None
    extent: tuple[float, float] | None = None
    iterations: int = 0
    candidates: dict = field(default_factory=dict)
    profile_points: np.ndarray | None = None
    init: str = "geometric"
    closed: bool = False
    """The profile closes (a torus, a tube): a periodic curve, its last ``degree`` control points
    (and weights) its first ones, C^{degree-1} across the seam (or, for a contract profile
    given closed and clamped, its last control point its first)."""
    distances: Tensor | None = None
    """Each input point's distance to the surface over the diagonal ``(N,)`` (the error map)."""
    start_direction: list | None = None
    """The axis (or extrusion) direction the refinement started from (geometric or network)."""


def _cloud(points) -> Tensor:
    p = torch.as_tensor(np.asarray(points) if not isinstance(points, Tensor) else points).detach().to(F64).cpu()
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {tuple(p.shape)}")
    if p.shape[0] < 30:
        raise InputError(f"need at least 30 points to fit a shape, got {p.shape[0]}")
    if not torch.isfinite(p).all():
        raise InputError("points contain NaN or infinite values")
    from ..fit.api import bounding_diagonal, check_spread  # the surface fit's own tests, one message each

    lo, hi = p.min(0).values, p.max(0).values
    diagonal = bounding_diagonal(lo, hi)
    if not diagonal > 0:
        raise InputError(f"all {p.shape[0]} input points coincide; there is no shape to fit")
    check_spread((p - (lo + hi) / 2) / diagonal)
    return p


def planarity(points: Tensor) -> float:
    """Thickness of the cloud: smallest over largest principal standard deviation."""
    s = torch.linalg.svdvals(points - points.mean(0))
    return float(s[-1] / s[0].clamp_min(1e-300))


def _check_not_plane(points: Tensor, kind: str) -> None:
    t = planarity(points)
    if t < PLANE_THICKNESS:
        raise InputError(
            f"the points lie on a single plane (thickness {t:.1e} of their extent): "
            f"a plane has no {'axis of revolution' if kind == 'revolution' else 'extrusion direction'}"
        )


def _perpendicular(a: Tensor, reference: Tensor | None = None) -> Tensor:
    """A unit vector orthogonal to unit ``a``; the projection of ``reference`` when given
    (else :func:`.init.plane_basis`'s ``e1``, the frame of the network contract)."""
    if reference is None:
        return plane_basis(a)[0]
    e = reference - (reference @ a) * a
    return e / e.norm()


def _distances(surface, points, warm=None):
    # the default grid (4 samples per control point and direction): a coarse grid starts
    # Newton in the wrong basin near a wiggly profile and overstates the distance; with the
    # refinement's last foot points (``warm``) too, each point keeps the closer of the two
    # (measured: on an L profile the grid alone overstated the mean squared distance by 4 %)
    return project_points(surface, points, params=warm, restart=warm is not None)


def _summary(distance: Tensor, diag: float) -> tuple[float, float]:
    d = distance.detach().numpy() / diag
    return float(d.mean()), float(np.percentile(d, 95))


REFINE_POINTS = 2000
"""The refinement runs on at most this many points (a fixed-seed subset): the unknowns
number a few dozen, and the projection's cost grows with the points."""

RESTART_EVERY = 12
"""The refinement's projections restart from the grid every this many evaluations (a foot
point stuck in a wrong basin biases the gradient); the final distances restart too."""
WARM_NEWTON = 2
"""Gauss-Newton iterations of a warm-started projection inside the refinement: between two
evaluations the surface moves little, and the foot points with it (measured on 10 + 10
held-out clouds: 2 give the same axis errors and mean distances as 16 full-Newton
iterations with a restart every 4 evaluations, at 40 % of the time)."""
SECOND_ORDER = False
"""Full-Hessian Newton in the warm projections (the grid restarts always use it)."""
PLATEAU_WINDOW = 5
PLATEAU_TOL = 5e-4
"""The refinement stops once its best loss fell by less than this fraction over the last
``PLATEAU_WINDOW`` evaluations (the mean squared distance has reached the noise; measured on
the benchmark's clouds, the axis no longer moves by a measurable amount)."""
DIRECTION_NEIGHBOURS = 64
"""Neighbours of the PCA normals that estimate an extrusion's direction."""


def _neighbours(k: int, points: Tensor) -> int:
    """``k`` for the PCA normals, at most an eighth of the cloud: on a sparse cloud (a mesh's
    vertices) a wide neighbourhood spans the whole shape and its PCA plane is no tangent plane."""
    return max(6, min(k, points.shape[0] // 8))


class _Plateau(Exception):
    """Raised from the refinement's closure to end L-BFGS on a plateau."""


def _lbfgs(params: list[Tensor], build, points: Tensor, iterations: int):
    """Minimise the mean squared distance of ``points`` to ``build()`` over ``params``.

    Returns the number of evaluations (each one projection of the points) and the last
    foot points ``(N, 2)`` (None when the refinement ran on a subset)."""
    subset = points.shape[0] > REFINE_POINTS
    if subset:
        g = torch.Generator().manual_seed(0)
        points = points[torch.randperm(points.shape[0], generator=g)[:REFINE_POINTS]]
    state = {"uv": None, "evals": 0, "best": [], "best_params": None}
    opt = LBFGS(params, lr=1.0, history_size=10)  # the fitting loop's; run() is torch's L-BFGS step
    scale = float((points.amax(0) - points.amin(0)).norm()) ** 2

    def closure():
        opt.zero_grad()
        surface = build()
        # warm start from the last foot points, and a restart from the grid every few
        # evaluations: a foot point stuck in a wrong basin biases the gradient (the axis
        # tilts to meet it)
        restart = state["evals"] % RESTART_EVERY == 0
        proj = project_points(surface, points, params=state["uv"], iterations=16 if restart else WARM_NEWTON,
                              restart=restart, check_every=4, second_order=restart or SECOND_ORDER)
        state["uv"] = proj.params
        state["evals"] += 1
        loss = (proj.distance ** 2).mean() / scale
        value = float(loss.detach())
        best = state["best"]
        if not best or value < best[-1]:
            state["best_params"] = [q.detach().clone() for q in params]
        best.append(min(value, best[-1]) if best else value)
        if len(best) > PLATEAU_WINDOW and best[-1] > (1 - PLATEAU_TOL) * best[-1 - PLATEAU_WINDOW]:
            raise _Plateau
        loss.backward()
        return loss

    try:
        opt.run(closure, max_iter=iterations, tolerance_grad=1e-12, tolerance_change=1e-15)
    except (torch.linalg.LinAlgError, _Plateau):
        # a degenerate trial surface, or a plateau reached inside a line search: the
        # parameters may hold a trial point; go back to the best evaluated one
        if state["best_params"] is not None:
            with torch.no_grad():
                for q, b in zip(params, state["best_params"]):
                    q.copy_(b)
    return state["evals"], None if subset else state["uv"]


# ---------------------------------------------------------------------------------------
# revolution
# ---------------------------------------------------------------------------------------
def _angular_extent(phi: np.ndarray, min_gap: float = math.radians(20)) -> tuple[float, float]:
    """(start, angle) of the arc the angles cover; a full turn unless a gap > min_gap."""
    s = np.sort(np.mod(phi, 2 * math.pi))
    gaps = np.diff(np.concatenate([s, [s[0] + 2 * math.pi]]))
    i = int(np.argmax(gaps))
    if gaps[i] <= min_gap:
        return 0.0, 2 * math.pi
    start = float(s[(i + 1) % s.size])
    return start, float(2 * math.pi - gaps[i])


def _revolution_surface(o, a, e1, rz, weights, knots, degree, angle, validate: bool = True):
    # validate=False inside the refinement: the profile's knots and (exponentiated) weights are
    # valid by construction, and the checks read the host on every evaluation
    a = a / a.norm()
    e1 = _perpendicular(a, e1)
    prof = NURBSCurve(o + rz[:, :1] * e1 + rz[:, 1:2] * a, degree=degree, knot_vector=knots, weights=weights,
                      validate=False)
    return revolve(prof, o, a, angle, validate=validate), e1


def _closing(curve: NURBSCurve) -> int:
    """How many of the profile's last control points repeat its first ones (with their weights):
    ``degree`` for a periodic profile (:func:`.profile.fit_profile`'s closed curves: unclamped
    knots, C^{p-1} at the seam), 1 for a clamped profile whose ends meet (C0: a contract
    profile may be one), 0 for an open one."""
    P, w = curve.control_points.detach(), curve.weights.detach()
    size = float((P.amax(0) - P.amin(0)).norm()) or 1.0

    def repeats(count: int) -> bool:
        return bool(float((P[:count] - P[-count:]).norm(dim=-1).max()) <= 1e-9 * size
                    and float((w[:count] - w[-count:]).abs().max()) <= 1e-12)

    k, p = curve.knot_vector.detach(), curve.degree
    clamped = bool((k[: p + 1] == k[0]).all())
    if not clamped and p < P.shape[0] and repeats(p):
        return p
    return 1 if repeats(1) else 0


def _free_profile(curve: NURBSCurve, wrap: int, refine: bool):
    """``(E, free control points, free log-weights)``: the refined unknowns, and the matrix
    that expands them to the profile's (a closed profile keeps its last ``wrap`` points tied
    to its first, so it stays closed, and periodic, whatever the refinement does)."""
    E = closing_matrix(curve.control_points.shape[0], wrap > 0, max(wrap, 1))
    m = E.shape[1]
    free = curve.control_points.detach()[:m].contiguous().clone().requires_grad_(refine)
    logw = curve.weights.detach()[:m].log().contiguous().clone().requires_grad_(refine)
    return E, free, logw


def _check_init(init: str) -> None:
    if init not in INITS:
        raise OptionError(f"init must be one of {', '.join(INITS)}, got {init!r}")


def _check_iterations(iterations) -> None:
    if isinstance(iterations, bool) or int(iterations) != iterations or not 0 <= iterations <= MAX_ITERATIONS:
        raise OptionError(f"iterations must be an integer in [0, {MAX_ITERATIONS:,}], got {iterations!r}")


def fit_revolution(points, normals=None, *, refine: bool = True, iterations: int = 30, k: int = 24,
                   init: str = "geometric") -> ShapeFit:
    """Fit an exact surface of revolution to ``points (N, 3)`` (module docstring).

    ``normals (N, 3)`` are estimated when None; ``iterations``: L-BFGS iterations of the
    refinement (0 or ``refine=False``: the starting estimate alone). ``init``:
    ``"geometric"`` (line geometry, then the profile fitted to the (r, z) pairs) or
    ``"network"`` (axis and profile from :func:`nurbskit.shapes.nets.initial_guess`, the
    contract in :mod:`nurbskit.shapes.init`); the refinement is the same.
    """
    _check_init(init)
    _check_iterations(iterations)
    t0 = time.perf_counter()
    p = _cloud(points)
    _check_not_plane(p, "revolution")
    guess = network_guess(p, "revolution") if init == "network" else None
    if guess is None:
        n = estimate_normals(p, _neighbours(k, p)) if normals is None else torch.as_tensor(normals, dtype=F64)
        ax = revolution_axis(p, n)
        a, o = ax.direction, ax.point
    else:
        a, o = guess["axis_direction"], guess["axis_point"]
    rel = p - o
    z = rel @ a
    radial = rel - z[:, None] * a
    r = radial.norm(dim=-1)
    e1 = _perpendicular(a)
    e2 = torch.linalg.cross(a, e1, dim=-1)
    phi = torch.atan2(radial @ e2, radial @ e1).numpy()
    start, angle = _angular_extent(phi)
    if guess is not None and guess["angle"] is not None:
        angle = guess["angle"]
    e1 = math.cos(start) * e1 + math.sin(start) * e2
    rz = torch.stack([r, z], -1)
    curve = fit_profile(rz.numpy()).curve if guess is None else guess["profile"]
    wrap = _closing(curve)
    closed = wrap > 0
    knots, degree = curve.knot_vector, curve.degree
    diag = float((p.amax(0) - p.amin(0)).norm())

    o_t = o.detach().contiguous().clone().requires_grad_(refine)
    a_t = a.detach().contiguous().clone().requires_grad_(refine)
    E, rz_free, logw = _free_profile(curve, wrap, refine)

    def build():
        s, _ = _revolution_surface(o_t, a_t, e1, E @ rz_free, torch.exp(E @ logw), knots, degree, angle,
                                   validate=False)
        return s

    evals, warm = (_lbfgs([o_t, a_t, rz_free, logw], build, p, iterations) if refine and iterations > 0
                   else (0, None))
    with torch.no_grad():
        a_f = a_t / a_t.norm()
        rz_t = E @ rz_free
        surface, e1_f = _revolution_surface(o_t, a_t, e1, rz_t, torch.exp(E @ logw), knots, degree, angle)
        surface = surface.detach()
        dist = _distances(surface, p, warm).distance
    mean, p95 = _summary(dist, diag)
    # axis point: the foot of the points' centroid, so the report is independent of the start
    o_f = o_t.detach() + ((p.mean(0) - o_t.detach()) @ a_f) * a_f
    profile = NURBSCurve(rz_t.detach().clone(), degree=degree, knot_vector=knots, weights=torch.exp(E @ logw).detach())
    profile_frame = {"origin": o_t.detach().tolist(), "radial": e1_f.detach().tolist(), "axial": a_f.tolist()}
    return ShapeFit(
        "revolution", surface, {"point": o_f.tolist(), "direction": a_f.tolist()}, profile, profile_frame,
        mean, p95, diag, time.perf_counter() - t0, angle=angle, iterations=evals,
        profile_points=rz.numpy(), init=init, distances=dist.detach() / diag, closed=closed,
        start_direction=(a / a.norm()).tolist(),
    )


# ---------------------------------------------------------------------------------------
# extrusion
# ---------------------------------------------------------------------------------------
def _extrusion_surface(c, d, e1, xy, weights, knots, degree, t0, t1, validate: bool = True):
    d = d / d.norm()
    e1 = _perpendicular(d, e1)
    e2 = torch.linalg.cross(d, e1, dim=-1)
    prof = NURBSCurve(c + xy[:, :1] * e1 + xy[:, 1:2] * e2 + t0 * d, degree=degree, knot_vector=knots,
                      weights=weights, validate=False)
    return extrude(prof, d, t1 - t0, validate=validate), e1, e2


def fit_extrusion(points, normals=None, *, refine: bool = True, iterations: int = 30, k: int = 24,
                  init: str = "geometric") -> ShapeFit:
    """Fit an exact extrusion (a general cylinder) to ``points (N, 3)`` (module docstring).

    Arguments as :func:`fit_revolution`; for ``init="network"`` the guess's
    ``axis_direction`` is the extrusion direction and its profile lives in the plane
    through ``axis_point`` with the basis :func:`nurbskit.shapes.init.plane_basis`.
    """
    _check_init(init)
    _check_iterations(iterations)
    t_start = time.perf_counter()
    p = _cloud(points)
    _check_not_plane(p, "extrusion")
    guess = network_guess(p, "extrusion") if init == "network" else None
    if guess is None:
        # wide neighbourhoods: the direction only needs the normals to lie in the section's
        # plane, which stays true across a bend or a corner, and their noise falls as 1 / k
        n = (estimate_normals(p, _neighbours(max(k, DIRECTION_NEIGHBOURS), p)) if normals is None
             else torch.as_tensor(normals, dtype=F64))
        d, _ = extrusion_direction(n)
        c = p.mean(0)
    else:
        d, c = guess["axis_direction"], guess["axis_point"]
    e1 = _perpendicular(d)
    e2 = torch.linalg.cross(d, e1, dim=-1)
    rel = p - c
    xy = torch.stack([rel @ e1, rel @ e2], -1)
    t = rel @ d
    curve = fit_profile(xy.numpy()).curve if guess is None else guess["profile"]
    wrap = _closing(curve)
    closed = wrap > 0
    knots, degree = curve.knot_vector, curve.degree
    diag = float((p.amax(0) - p.amin(0)).norm())
    t_lo, t_hi = (t.min(), t.max()) if guess is None or guess["extent"] is None else \
        (torch.tensor(guess["extent"][0], dtype=F64), torch.tensor(guess["extent"][1], dtype=F64))

    d_t = d.detach().contiguous().clone().requires_grad_(refine)
    E, xy_free, logw = _free_profile(curve, wrap, refine)
    t0 = t_lo.detach().clone().requires_grad_(refine)
    t1 = t_hi.detach().clone().requires_grad_(refine)

    def build():
        s, _, _ = _extrusion_surface(c, d_t, e1, E @ xy_free, torch.exp(E @ logw), knots, degree, t0, t1,
                                     validate=False)
        return s

    evals, warm = (_lbfgs([d_t, xy_free, logw, t0, t1], build, p, iterations) if refine and iterations > 0
                   else (0, None))
    with torch.no_grad():
        d_f = d_t / d_t.norm()
        xy_t = E @ xy_free
        surface, e1_f, e2_f = _extrusion_surface(c, d_t, e1, xy_t, torch.exp(E @ logw), knots, degree, t0, t1)
        surface = surface.detach()
        dist = _distances(surface, p, warm).distance
    mean, p95 = _summary(dist, diag)
    profile = NURBSCurve(xy_t.detach().clone(), degree=degree, knot_vector=knots, weights=torch.exp(E @ logw).detach())
    frame = {"origin": c.tolist(), "x": e1_f.tolist(), "y": e2_f.tolist()}
    return ShapeFit(
        "extrusion", surface, {"point": c.tolist(), "direction": d_f.tolist()}, profile, frame,
        mean, p95, diag, time.perf_counter() - t_start, extent=(float(t0.detach()), float(t1.detach())), iterations=evals,
        profile_points=xy.numpy(), init=init, distances=dist.detach() / diag, closed=closed,
        start_direction=(d / d.norm()).tolist(),
    )


# ---------------------------------------------------------------------------------------
# choice
# ---------------------------------------------------------------------------------------
def _freeform(p: Tensor, reason: str, t_start: float, candidates: dict, progress=None) -> ShapeFit:
    from ..fit import fit_surface
    from ..fit.api import DEFAULT_CTRL, DEFAULT_DEGREE, resolve_config
    from ..fit.checks import fewer_controls_hint

    # The fallback's control net must be determined by the points; say so here, in the
    # terms of a shape fit (an exact shape instead, or `nurbskit fit` with a coarser net),
    # not with the fitter's --ctrl, which `shape` does not have.
    cfg = resolve_config("default", False)
    (n_u, n_v), degree = cfg.ctrl or DEFAULT_CTRL, cfg.degree or DEFAULT_DEGREE
    m = min(len(p), cfg.max_points) if cfg.max_points else len(p)
    if n_u * n_v > m:
        exact = "" if not candidates else "ask for an exact shape (--kind revolution or --kind extrusion), or "
        raise InputError(
            f"{reason.rsplit(';', 1)[0]}; the free-form fallback's {n_u}x{n_v} = {n_u * n_v} control points "
            f"cannot be determined by {m} points: {exact}fit a free-form surface with a coarser net: "
            + fewer_controls_hint(m, tuple(degree), prefix="nurbskit fit INPUT ")
        )
    steps, done = cfg.progress_steps, [0]

    def step(_report) -> None:
        done[0] += 1
        progress("free-form surface", done[0], steps)

    result = fit_surface(p, "default", callback=None if progress is None else step)
    surface = result.surface.detach().to(F64)
    diag = float((p.amax(0) - p.amin(0)).norm())
    dist = _distances(surface, p).distance.detach()
    mean, p95 = _summary(dist, diag)
    return ShapeFit("freeform", surface, None, None, None, mean, p95, diag, time.perf_counter() - t_start,
                    reason=reason, candidates=candidates, distances=dist / diag)


def fit_shape(points, kind: str = "auto", normals=None, *, refine: bool = True, iterations: int = 30,
              auto_tolerance: float = 5e-3, freeform: bool = True, init: str = "geometric",
              progress=None) -> ShapeFit:
    """Fit a surface of revolution, an extrusion, or (``auto``) the better of the two.

    Args:
        points: ``(N, 3)``.
        kind: 'revolution', 'extrusion' or 'auto'.
        normals: ``(N, 3)`` or None (estimated).
        refine, iterations: the refinement (see :func:`fit_revolution`).
        init: ``"geometric"`` or ``"network"`` (the trained initialiser of
            :mod:`nurbskit.shapes.nets`; contract in :mod:`nurbskit.shapes.init`).
        auto_tolerance: ``auto`` accepts an exact shape whose mean point-to-surface distance
            is at most this fraction of the diagonal; otherwise free-form.
        freeform: ``auto`` may fall back to :func:`nurbskit.fit_surface` (else it keeps the
            better exact shape and says it is poor).
        progress: None, or called as ``progress(stage, done, total)`` ("revolution",
            "extrusion", "free-form surface": one report per fitting iteration of that one).

    Example:
        >>> from nurbskit.shapes.synthetic import vase_cloud
        >>> fit = fit_shape(vase_cloud(600, seed=1).points, "revolution", iterations=10)
        >>> fit.kind, fit.distance_mean < 1e-3
        ('revolution', True)
    """
    if kind not in KINDS:
        raise OptionError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    _check_init(init)
    _check_iterations(iterations)
    report = progress or (lambda stage, done, total: None)

    def staged(name, fn, *args, **kw):
        report(name, 0, 1)
        out = fn(*args, **kw)
        report(name, 1, 1)
        return out

    opts = dict(refine=refine, iterations=iterations, init=init)
    if kind == "revolution":
        fit = staged("revolution", fit_revolution, points, normals, **opts)
        fit.reason = "asked for a surface of revolution"
        return fit
    if kind == "extrusion":
        fit = staged("extrusion", fit_extrusion, points, normals, **opts)
        fit.reason = "asked for an extrusion"
        return fit
    t_start = time.perf_counter()
    p = _cloud(points)
    if planarity(p) < PLANE_THICKNESS:
        reason = f"the points lie on a plane (thickness {planarity(p):.1e}): no axis or direction; free-form"
        if not freeform:
            raise InputError(reason.rsplit(";", 1)[0])
        return _freeform(p, reason, t_start, {}, progress)
    fits = {}
    for name, fn in (("revolution", fit_revolution), ("extrusion", fit_extrusion)):
        try:
            fits[name] = staged(name, fn, p, normals, **opts)
        except InputError:
            continue
    candidates = {name: f.distance_mean for name, f in fits.items()}
    if not fits:
        return _freeform(p, "neither a revolution nor an extrusion could be fitted; free-form", t_start, candidates,
                         progress)
    # ties (a circular cylinder is both) go to the revolution: its circle is exact either way;
    # a tie is within 5 %, or within AUTO_TIE of the diagonal (two near-exact fits of clean
    # data, e.g. a mesh's vertices, whose residuals differ by rounding)
    best = min(fits.values(), key=lambda f: f.distance_mean if f.kind == "revolution"
               else f.distance_mean * 1.05 + AUTO_TIE)
    others = ", ".join(f"{k} {v:.2e}" for k, v in candidates.items())
    if best.distance_mean <= auto_tolerance or not freeform:
        best.reason = (f"{best.kind}: smallest mean point-to-surface distance over the diagonal ({others}); "
                       f"tolerance {auto_tolerance:.1e}")
        best.candidates = candidates
        best.seconds = time.perf_counter() - t_start
        return best
    return _freeform(p, f"no exact shape within {auto_tolerance:.1e} of the diagonal ({others}); free-form",
                     t_start, candidates, progress)
