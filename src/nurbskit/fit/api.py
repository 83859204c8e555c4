"""``fit_surface``: one fit from data and a configuration.

Flow (docs/architecture.md, "Flow of one fit"), one function per stage:
:func:`prepare_target` (the input as tensors) -> :func:`normalise` (fit units) ->
:func:`~nurbskit.fit.checks.check_fit_size` -> :func:`initial_state` (the initial
surface of :mod:`.init`, then alternating projection and least squares of
:mod:`.lstsq` when configured) -> :func:`run_stages` (the gradient stages of the one
loop, :mod:`.loop`) -> :func:`denormalise` (the surface back in input units) ->
:func:`~nurbskit.fit.checks.check_result`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..core import NURBSSurface
from ..errors import InputError, OptionError
from .config import FitConfig
from .init import initial_surface
from .lstsq import alternate
from .loop import Progress, Target, eliminated_control_points, run_stage
from .params import SurfaceParameters, Topology, new_surface
from .pipelines import get_pipeline, supervised_default

Tensor = torch.Tensor
DEFAULT_CTRL = (15, 15)
DEFAULT_DEGREE = (3, 3)


@dataclass
class FitResult:
    """The outcome of :func:`fit_surface`.

    ``surface`` is in the input's units. ``history`` holds one record per loop
    iteration (``stage``, ``iteration``, ``loss`` and ``parts``, in fit units: the
    input scaled to a unit bounding-box diagonal; ``evaluations``; each stage's last
    record ``cuda_graph``, see :func:`~nurbskit.fit.loop.run_stage`); ``alternation`` the mean squared
    distance after each projection + least-squares round.
    """

    surface: NURBSSurface
    config: FitConfig
    points: Tensor
    topology: Topology
    history: list[dict] = field(default_factory=list)
    alternation: list[float] = field(default_factory=list)
    seconds: float = 0.0
    loop_seconds: float = 0.0
    iterations: int = 0
    center: Tensor | None = None
    scale: float = 1.0
    target_grid: Tensor | None = None
    initial_surface: NURBSSurface | None = None

    @property
    def closed_v(self) -> bool:
        return self.topology.closed_v

    @property
    def seconds_per_iteration(self) -> float:
        return self.loop_seconds / self.iterations if self.iterations else 0.0


def _as_points(x, name: str) -> Tensor:
    """A floating tensor on the input's own device and dtype (arrays: their dtype, else float64)."""
    if isinstance(x, Tensor):
        t = x.detach()
        if not t.is_floating_point():
            t = t.to(torch.float64)
    else:
        a = np.asarray(x)
        if a.dtype not in (np.float32, np.float64):
            try:
                a = a.astype(np.float64)
            except (TypeError, ValueError):
                raise InputError(f"{name}: expected numbers, got an array of {a.dtype}") from None
        t = torch.from_numpy(np.ascontiguousarray(a))
    if not torch.isfinite(t).all():
        raise InputError(f"{name}: expected finite numbers, found NaN or infinite values")
    return t


def _normalised_knots(kv: Tensor, degree: int, n: int) -> Tensor:
    a, b = kv[degree], kv[n]
    return (kv - a) / (b - a)


def resolve_config(config: FitConfig | str | None, supervised_input: bool) -> FitConfig:
    """A validated copy of ``config`` (a name, a FitConfig or None for ``default``)."""
    if config is None or isinstance(config, str):
        name = config or "default"
        if supervised_input and name.lower() == "default":
            cfg = supervised_default()
        else:
            cfg = get_pipeline(name)
    else:
        cfg = dataclasses.replace(config)
    return cfg.validate()


@dataclass
class Prepared:
    """The input of one fit, on its own device and dtype, before normalisation.

    ``points (N, 3)`` every input point (the report measures them all); ``grid (R, S, 3)``
    the ordered supervised target or None; ``control_points`` the true control net of a
    supervised NURBS target or None.
    """

    points: Tensor
    grid: Tensor | None = None
    control_points: Tensor | None = None


def prepare_target(
    points, cfg: FitConfig, target_grid=None, target_surface: NURBSSurface | None = None
) -> Prepared:
    """Stage 1: the input as tensors; dtype and device follow the input (the surface's, the grid's, the points')."""
    supervised_input = target_grid is not None or target_surface is not None
    if cfg.supervised and not supervised_input:
        raise OptionError(
            f"pipeline {cfg.pipeline} is supervised: give a NURBS surface or an ordered (R, S, 3) grid, not a point cloud"
        )
    from .checks import check_resolution

    true_cp = None
    if target_surface is not None:
        check_resolution(tuple(cfg.resolution), target_surface.control_points.element_size())
        target_grid = target_surface.sample(cfg.resolution).detach()
        true_cp = target_surface.control_points.detach()
    if target_grid is not None:
        grid = _as_points(target_grid, "target grid")
        if grid.ndim != 3 or grid.shape[-1] != 3 or min(grid.shape[:2]) < 2:
            raise InputError(f"a supervised target must be an ordered grid (R, S, 3) with R, S >= 2, got {tuple(grid.shape)}")
        pts = grid.reshape(-1, 3)
    else:
        if points is None:
            raise OptionError("fit_surface needs points, a target_grid or a target_surface")
        grid = None
        pts = _as_points(points, "points")
        if pts.ndim != 2 or pts.shape[-1] != 3:
            raise InputError(f"points must have shape (N, 3), got {tuple(pts.shape)}")
    if pts.shape[0] < 4:
        raise InputError(f"a surface fit needs at least 4 points, got {pts.shape[0]}")
    return Prepared(pts, grid, true_cp)


def normalise(prepared: Prepared, cfg: FitConfig) -> tuple[Target, Tensor, float]:
    """Stage 2: the target in fit units, and the ``(center, scale)`` that map them back.

    Fit units: the centre of the bounding box at the origin, the diagonal 1 (unless
    ``cfg.normalize`` is off). Large unordered inputs are reduced to a seeded random
    subset of ``cfg.max_points``. Raises an InputError when the points do not determine
    a surface (they coincide or lie on one line).
    """
    pts, grid = prepared.points, prepared.grid
    lo, hi = pts.min(0).values, pts.max(0).values
    diagonal = bounding_diagonal(lo, hi)
    if not diagonal > 0:
        raise InputError(f"all {pts.shape[0]} input points coincide; there is no surface to fit")
    if not 1e-150 < diagonal < 1e150:  # squares of 1e-300 and 1e300: the limits of float64
        raise InputError(
            f"the input points span {diagonal:.3g} (their bounding-box diagonal): squared distances, which the fit "
            f"and its report measure in float64, would {'overflow' if diagonal > 1 else 'underflow'}; rescale the coordinates"
        )
    check_spread((pts - (lo + hi) / 2) / diagonal)  # in unit size: no square over- or underflows
    if cfg.normalize:
        center = (lo + hi) / 2
        scale = diagonal
    else:
        center, scale = torch.zeros(3, dtype=pts.dtype, device=pts.device), 1.0
    xn = (pts - center) / scale
    if grid is None and cfg.max_points > 0 and xn.shape[0] > cfg.max_points:
        # Every step projects every fitted point, so the cost grows with the scan; a seeded
        # random subset bounds it (a 189k-point Kinect scan: 147 s -> 16 s of fitting). The
        # report still measures all input points (FitResult.points).
        pick = torch.randperm(xn.shape[0], generator=torch.Generator().manual_seed(int(cfg.seed)))
        xn = xn[pick[: int(cfg.max_points)].to(xn.device)]
    target = Target(
        points=xn,
        grid=None if grid is None or not cfg.supervised else (grid - center) / scale,
        control_points=None if prepared.control_points is None else (prepared.control_points - center) / scale,
    )
    return target, center, scale


def bounding_diagonal(lo: Tensor, hi: Tensor) -> float:
    """The length of the box ``[lo, hi]``'s diagonal, also where its square over- or
    underflows the dtype (coordinates of 1e200, or extents of 1e-300); an InputError when
    the extent itself is not finite."""
    extent = hi - lo
    if not bool(torch.isfinite(extent).all()):
        raise InputError(f"the input points span more than {str(lo.dtype).replace('torch.', '')} holds "
                         f"(from {lo.tolist()} to {hi.tolist()}); rescale them")
    diagonal = float(extent.norm())
    if math.isfinite(diagonal) and diagonal > 1e-150:
        return diagonal
    largest = float(extent.abs().max())
    return largest * float((extent / largest).norm()) if largest > 0 else 0.0


def check_spread(points: Tensor, ratio: float = 1e-9) -> None:
    """Raise an InputError when ``points (N, 3)`` lie on one line: no surface is determined.

    The test: the second singular value of the centred points is below ``ratio`` times
    the first (the points' extent across the line is a ``ratio`` of their length).
    """
    x = points.detach().to(torch.float64)
    s = torch.linalg.svdvals(x - x.mean(0))
    if float(s[1]) <= ratio * float(s[0]):
        raise InputError(
            f"the {points.shape[0]} input points lie on a line (their spread across it is "
            f"{float(s[1] / s[0]):.1e} of their length): a surface is not determined by them"
        )


def initial_state(
    target: Target, cfg: FitConfig, target_surface: NURBSSurface | None = None,
    callback: Callable[[Progress], None] | None = None,
) -> tuple[NURBSSurface, Topology, list[float], NURBSSurface]:
    """Stage 3: the initial surface, then the alternation rounds when configured.

    Returns ``(surface, topology, alternation history, initial surface)`` in fit units.
    ``callback`` hears of every alternation round as a :class:`~nurbskit.fit.loop.Progress`
    of the stage ``"alternation"`` (a round of a large net solves a large system: seconds).
    """
    xn = target.points
    dtype, device = xn.dtype, xn.device
    ctrl, degree = cfg.ctrl, cfg.degree
    gen = torch.Generator().manual_seed(int(cfg.seed))
    if cfg.supervised and cfg.init.kind in ("target", "lstsq"):
        # The target's knots and weights when its net matches the requested one.
        if target_surface is not None and tuple(target_surface.sizes) == tuple(ctrl) and tuple(target_surface.degrees) == tuple(degree):
            ts = target_surface.to(dtype=dtype, device=device)
            kvs = [_normalised_knots(k, p, n) for k, p, n in zip(ts.knot_vectors, ts.degrees, ts.sizes)]
            weights = ts.weights
        else:
            kvs, weights = None, None
        lo_n, hi_n = xn.min(0).values, xn.max(0).values
        r = torch.rand(ctrl[0], ctrl[1], 3, generator=gen, dtype=dtype).to(device)
        surface = new_surface(lo_n + (hi_n - lo_n) * r, degree, False, kvs, weights)
        if cfg.init.kind == "lstsq":
            # The exact minimiser of the supervised L2 loss at these knots and weights.
            surface = surface._replace(control_points=eliminated_control_points(surface, target, Topology()))
        topology = Topology()
    else:
        if cfg.init.kind == "target":
            raise OptionError(
                "init 'target' (the target's knots and weights) needs a supervised pipeline and a NURBS or grid target"
            )
        surface, topology = initial_surface(
            xn, cfg.init.kind, ctrl, degree, cfg.init.closed, cfg.init.smoothness, generator=gen
        )
    init = surface
    alternation: list[float] = []
    if cfg.alternation.rounds and not cfg.supervised:
        rounds = cfg.alternation.rounds
        report = None if callback is None else (
            lambda k, err: callback(Progress("alternation", -1, k + 1, rounds, err)))
        surface, _, alternation = alternate(
            surface, xn, rounds, topology, cfg.alternation.smoothness, cfg.alternation.tolerance, callback=report
        )
    return surface, topology, alternation, init


def run_stages(
    surface: NURBSSurface, topology: Topology, target: Target, cfg: FitConfig,
    callback: Callable[[Progress], None] | None = None,
) -> tuple[NURBSSurface, list[dict]]:
    """Stage 4: the gradient stages of the one loop; returns the fitted surface (fit units) and the history."""
    params = SurfaceParameters(surface, topology).to(target.points.device)
    history: list[dict] = []
    for i, stage in enumerate(cfg.stages):
        history += run_stage(params, stage, target, cfg.resolution, stage_index=i, callback=callback)
    fitted = params.surface()
    return NURBSSurface(
        fitted.control_points.detach(), fitted.degrees, [k.detach() for k in fitted.knot_vectors], fitted.weights.detach()
    ), history


def denormalise(surface: NURBSSurface, center: Tensor, scale: float) -> NURBSSurface:
    """Stage 5: a surface in fit units back in the input's units."""
    return surface._replace(control_points=surface.control_points.detach() * scale + center)


def _resolved_sizes(cfg: FitConfig, target_surface: NURBSSurface | None) -> FitConfig:
    own = target_surface is not None and cfg.supervised
    ctrl = cfg.ctrl or (tuple(target_surface.sizes) if own else DEFAULT_CTRL)
    degree = cfg.degree or (tuple(target_surface.degrees) if own else DEFAULT_DEGREE)
    return dataclasses.replace(cfg, ctrl=tuple(ctrl), degree=tuple(degree)).validate()


def fit_surface(
    points=None,
    config: FitConfig | str | None = None,
    *,
    target_grid=None,
    target_surface: NURBSSurface | None = None,
    callback: Callable[[Progress], None] | None = None,
) -> FitResult:
    """Fit a NURBS surface to points (unsupervised) or to an ordered target (supervised).

    The stages, each a function of this module: :func:`prepare_target`,
    :func:`normalise`, :func:`~nurbskit.fit.checks.check_fit_size` (refuses what cannot
    be determined or cannot fit in memory), :func:`initial_state`, :func:`run_stages`,
    :func:`denormalise`, then :func:`~nurbskit.fit.checks.check_result` (a non-finite
    result, or one far worse than its own start, raises a
    :class:`~nurbskit.fit.checks.FitFailed`).

    Args:
        points: ``(N, 3)`` unordered input points (tensor or array).
        config: a pipeline name (``"UCDL"``), a :class:`FitConfig`, or None for
            ``default``.
        target_grid: ``(R, S, 3)`` ordered points sampled on a uniform parametric grid
            (supervised pipelines).
        target_surface: a known surface; sampled on ``config.resolution`` for the
            supervised target; its knots and weights serve ``init="target"`` (SC).
        callback: called with a :class:`~nurbskit.fit.loop.Progress` after every
            alternation round and every iteration (``config.progress_steps`` calls at
            most).

    Returns:
        a :class:`FitResult`. Convention: dtype and device follow the input (a tensor's
        own; an array's floating dtype on the CPU; other arrays become float64); move the
        input to fit on another device.

    Example:
        >>> import torch
        >>> g = torch.rand(400, 2, dtype=torch.float64)
        >>> pts = torch.stack([g[:, 0], g[:, 1], 0.2 * torch.sin(3 * g[:, 0])], -1)
        >>> result = fit_surface(pts, "default")
        >>> result.surface.sizes, result.surface.dtype
        ((15, 15), torch.float64)
    """
    from .checks import check_fit_size, check_result

    supervised_input = target_grid is not None or target_surface is not None
    cfg = resolve_config(config, supervised_input)
    t0 = time.perf_counter()
    prepared = prepare_target(points, cfg, target_grid, target_surface)
    cfg = _resolved_sizes(cfg, target_surface)
    target, center, scale = normalise(prepared, cfg)
    check_fit_size(cfg, target)
    surface, topology, alternation, init = initial_state(target, cfg, target_surface, callback)
    t_loop = time.perf_counter()
    fitted, history = run_stages(surface, topology, target, cfg, callback)
    loop_seconds = time.perf_counter() - t_loop
    check_result(fitted, init, target, cfg)
    return FitResult(
        surface=denormalise(fitted, center, scale),
        config=cfg,
        points=prepared.points,
        topology=topology,
        history=history,
        alternation=alternation,
        seconds=time.perf_counter() - t0,
        loop_seconds=loop_seconds,
        iterations=len(history),
        center=center,
        scale=scale,
        target_grid=prepared.grid,
        initial_surface=denormalise(init, center, scale),
    )
