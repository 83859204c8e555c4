"""``fit_surface``: one fit from data and a configuration.

Flow (docs/architecture.md, "Flow of one fit"): normalise the input -> initial
surface (:mod:`.init`) -> alternating projection and least squares
(:mod:`.lstsq`, when configured) -> the gradient stages of the one loop
(:mod:`.loop`) -> the surface back in input units.
"""

from __future__ import annotations

import dataclasses
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
    input scaled to a unit bounding-box diagonal); ``alternation`` the mean squared
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


def _as_points(x, name: str, dtype, device) -> Tensor:
    t = torch.as_tensor(np.asarray(x.detach().cpu() if isinstance(x, Tensor) else x, dtype=np.float64))
    if not torch.isfinite(t).all():
        raise InputError(f"{name} contains NaN or infinite values")
    return t.to(dtype=dtype, device=device)


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


def fit_surface(
    points=None,
    config: FitConfig | str | None = None,
    *,
    target_grid=None,
    target_surface: NURBSSurface | None = None,
    callback: Callable[[Progress], None] | None = None,
) -> FitResult:
    """Fit a NURBS surface to points (unsupervised) or to an ordered target (supervised).

    Args:
        points: ``(N, 3)`` unordered input points (tensor or array).
        config: a pipeline name (``"UCDL"``), a :class:`FitConfig`, or None for
            ``default``.
        target_grid: ``(R, S, 3)`` ordered points sampled on a uniform parametric grid
            (supervised pipelines).
        target_surface: a known surface; sampled on ``config.resolution`` for the
            supervised target; its knots and weights serve ``init="target"`` (SC).
        callback: called with a :class:`~nurbskit.fit.loop.Progress` after every
            iteration.

    Returns:
        a :class:`FitResult`; dtype and device follow ``config.dtype`` / ``config.device``.

    Example:
        >>> import torch
        >>> g = torch.rand(400, 2, dtype=torch.float64)
        >>> pts = torch.stack([g[:, 0], g[:, 1], 0.2 * torch.sin(3 * g[:, 0])], -1)
        >>> result = fit_surface(pts, "default")
        >>> result.surface.sizes
        (15, 15)
    """
    supervised_input = target_grid is not None or target_surface is not None
    cfg = resolve_config(config, supervised_input)
    t0 = time.perf_counter()
    dtype = torch.float64 if cfg.dtype == "float64" else torch.float32
    device = torch.device(cfg.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise OptionError("device cuda was requested but torch sees no CUDA device")
    if cfg.supervised and not supervised_input:
        raise OptionError(
            f"pipeline {cfg.pipeline} is supervised: give a NURBS surface or an ordered (R, S, 3) grid, not a point cloud"
        )

    true_cp = None
    if target_surface is not None:
        ts = target_surface.to(dtype=dtype, device=device)
        target_grid = ts.sample(cfg.resolution)
        true_cp = ts.control_points
    if target_grid is not None:
        grid = _as_points(target_grid, "target grid", dtype, device)
        if grid.ndim != 3 or grid.shape[-1] != 3 or min(grid.shape[:2]) < 2:
            raise InputError(f"a supervised target must be an ordered grid (R, S, 3) with R, S >= 2, got {tuple(grid.shape)}")
        pts = grid.reshape(-1, 3)
    else:
        if points is None:
            raise OptionError("fit_surface needs points, a target_grid or a target_surface")
        grid = None
        pts = _as_points(points, "points", dtype, device)
        if pts.ndim != 2 or pts.shape[-1] != 3:
            raise InputError(f"points must have shape (N, 3), got {tuple(pts.shape)}")
    if pts.shape[0] < 4:
        raise InputError(f"a surface fit needs at least 4 points, got {pts.shape[0]}")

    # Normalise: centre of the bounding box to the origin, diagonal to 1.
    lo, hi = pts.min(0).values, pts.max(0).values
    if not float((hi - lo).norm()) > 0:
        raise InputError(f"all {pts.shape[0]} input points coincide; there is no surface to fit")
    if cfg.normalize:
        center = (lo + hi) / 2
        scale = float((hi - lo).norm())
    else:
        center, scale = torch.zeros(3, dtype=dtype, device=device), 1.0
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
        control_points=None if true_cp is None else (true_cp - center) / scale,
    )

    ctrl = cfg.ctrl or (tuple(target_surface.sizes) if target_surface is not None and cfg.supervised else DEFAULT_CTRL)
    degree = cfg.degree or (tuple(target_surface.degrees) if target_surface is not None and cfg.supervised else DEFAULT_DEGREE)
    cfg = dataclasses.replace(cfg, ctrl=tuple(ctrl), degree=tuple(degree))
    cfg.validate()
    gen = torch.Generator().manual_seed(int(cfg.seed))

    # Initial surface.
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
        surface, _, alternation = alternate(
            surface, xn, cfg.alternation.rounds, topology, cfg.alternation.smoothness, cfg.alternation.tolerance
        )

    params = SurfaceParameters(surface, topology).to(device)
    history: list[dict] = []
    t_loop = time.perf_counter()
    for i, stage in enumerate(cfg.stages):
        history += run_stage(params, stage, target, cfg.resolution, stage_index=i, callback=callback)
    loop_seconds = time.perf_counter() - t_loop

    fitted = params.surface()
    out = fitted._replace(control_points=fitted.control_points * scale + center)
    out = NURBSSurface(out.control_points, out.degrees, out.knot_vectors, out.weights)
    init_out = init._replace(control_points=init.control_points.detach() * scale + center)
    return FitResult(
        surface=out,
        config=cfg,
        points=pts,
        topology=topology,
        history=history,
        alternation=alternation,
        seconds=time.perf_counter() - t0,
        loop_seconds=loop_seconds,
        iterations=len(history),
        center=center,
        scale=scale,
        target_grid=grid,
        initial_surface=init_out,
    )
