"""Fit a scalar NURBS volume to three drawings (front, left, top) and extract its isosurface.

Method (W. Li, "Multi-view NURBS Volume"): a scalar field ``f = sum V B B B W / sum B B B W``
on ``[0, 1]^3`` is optimised with L-BFGS over its control values ``V`` and weights ``W``
(kept positive as ``W = exp(theta)``) to minimise
``shape_weight * C_shape + smooth_weight * C_smooth`` evaluated on a grid; the solid is
``{f >= isovalue}`` and its surface comes from marching cubes. The costs are described
in :mod:`nurbskit.volume.losses`, the axes and pixel mapping in :mod:`nurbskit.volume.views`.

Configured by one :class:`~nurbskit.volume.config.VolumeFitConfig`. The paper's setting
(order 3 = degree 2, 50^3 control values, a 20^3 grid, weights 0.1 / 0.9, isovalue 0.5,
100 iterations, control values starting at 0 and weights at 1) is the preset ``paper``;
the default (an 80^3 grid, the field started from the visual hull, 30 iterations) is
the best that runs in seconds: the paper's 20^3 grid bounds the IoU of consistent
drawings to about 0.8, see :mod:`nurbskit.volume.config`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, Mapping, Sequence

import numpy as np
import torch

from ..core.knots import clamped_uniform
from ..core.volume import NURBSVolume
from ..errors import InputError, NurbskitError
from ..fit.optim import LBFGS
from .config import VolumeFitConfig, check_fit_size, config_to_dict, default_config
from .drawings import load_drawing, mask_on_plane, resample
from .field import GridField
from .losses import paper_shape_cost, silhouette_cost, smoothness_cost, visual_hull
from .mesh import Mesh, iou, isosurface, rasterize_projection
from .views import VIEW_NAMES, VIEWS, project_grid

Tensor = torch.Tensor
#: ``callback(stage, done, total, cost)``: stage 'fit' after each L-BFGS iteration ``done``
#: of at most ``total`` (cost: the total cost after it), then 'mesh' once (cost None).
ProgressCallback = Callable[[str, int, int, "float | None"], None]
#: A fit whose final cost exceeds its initial cost by this factor has failed.
WORSE_FACTOR = 10.0


class VolumeFitFailed(NurbskitError):
    """The fit ran but its result is unusable (a non-finite field, or a cost far above its start)."""


@dataclass
class SilhouetteFit:
    """What :func:`fit_silhouettes` returns; unpacks as ``volume, mesh = fit_silhouettes(...)``.

    ``volume``: the fitted scalar :class:`NURBSVolume` (dim 1) on ``[0, 1]^3``;
    ``mesh``: its isosurface in unit-cube coordinates (empty when no sample reaches the
    isovalue, see ``message``); ``iou`` / ``hull_iou``: per view, the IoU of the mesh's
    (and of the visual hull's) projection against the drawing; ``projections``: the
    mesh's silhouettes, bool ``(N, N)`` images laid out as the drawings.
    """

    volume: NURBSVolume
    mesh: Mesh
    config: VolumeFitConfig
    costs: dict
    history: list
    iterations: int
    evaluations: int
    iou: dict
    hull_iou: dict
    seconds: dict
    drawings: dict = field(repr=False)
    projections: dict = field(repr=False)
    message: str | None = None

    def __iter__(self) -> Iterator:
        yield self.volume
        yield self.mesh

    def report(self) -> dict:
        """JSON-ready summary: configuration, costs, IoU per view, timings, mesh size."""
        return {
            "config": config_to_dict(self.config),
            "costs": self.costs,
            "cost_history": self.history,
            "iterations": self.iterations,
            "evaluations": self.evaluations,
            "iou": self.iou,
            "mean_iou": float(np.mean(list(self.iou.values()))),
            "visual_hull_iou": self.hull_iou,
            "seconds": self.seconds,
            "mesh": {"vertices": int(len(self.mesh.vertices)), "faces": int(len(self.mesh.faces))},
            "empty": self.mesh.is_empty,
            "message": self.message,
        }


def _as_drawings(drawings) -> dict:
    """``{"front", "left", "top"}`` from a mapping with those keys or a sequence of three."""
    if isinstance(drawings, Mapping):
        missing = [n for n in VIEW_NAMES if n not in drawings]
        if missing:
            raise InputError(f"drawings: expected the views {', '.join(VIEW_NAMES)}, missing {', '.join(missing)}")
        return {n: drawings[n] for n in VIEW_NAMES}
    if isinstance(drawings, (str, bytes)) or not isinstance(drawings, Sequence) or len(drawings) != 3:
        raise InputError("drawings: expected a mapping {front, left, top} or a sequence of three drawings")
    return dict(zip(VIEW_NAMES, drawings))


def _device_dtype(sources) -> tuple[torch.device, torch.dtype]:
    """The first floating tensor's device and dtype; CPU float32 for files, images and arrays."""
    for t in sources:
        if isinstance(t, Tensor) and t.is_floating_point():
            return t.device, t.dtype
    return torch.device("cpu"), torch.float32


def _smoothness_axis(knots: Tensor, degree: int, n_ctrl: int, grid_axis: Tensor) -> Tensor:
    """Smoothness samples along one axis: the grid, or the knot-span midpoints when finer.

    One sample per knot span already reaches every control value (each basis function
    covers ``degree + 1`` spans); more samples cost time and add no regularisation.
    Returns ``grid_axis`` itself when it is kept.
    """
    inner = torch.unique_consecutive(knots[degree : n_ctrl + 1])
    if len(grid_axis) <= len(inner) - 1:
        return grid_axis
    return (inner[1:] + inner[:-1]) / 2


def projection_iou(mesh: Mesh, drawings: dict, resolution: int) -> tuple[dict, dict]:
    """IoU per view of the mesh's projection against each drawing on a ``resolution^2`` raster.

    Returns ``(iou, projections)``: floats and bool images ``(resolution, resolution)``.
    """
    scores, images = {}, {}
    for view in VIEWS:
        target = resample(drawings[view.name].float().cpu(), resolution, resolution).numpy() >= 0.5
        image = rasterize_projection(mesh, view, resolution, resolution)
        scores[view.name] = iou(image, target)
        images[view.name] = image
    return scores, images


def visual_hull_iou(drawings: dict, resolution: int) -> dict:
    """IoU per view of the visual hull's projection (intersection of the extruded drawings).

    The best that a solid inside all three extrusions can do; the reference for
    inconsistent drawings. Computed on a ``resolution^3`` grid.
    """
    sizes = (resolution,) * 3
    planes = {v.name: mask_on_plane(drawings[v.name].float().cpu(), v, sizes) >= 0.5 for v in VIEWS}
    hull = visual_hull({k: p.to(torch.uint8) for k, p in planes.items()}).bool()
    out = {}
    for view in VIEWS:
        target = resample(drawings[view.name].float().cpu(), resolution, resolution).numpy() >= 0.5
        out[view.name] = iou(project_grid(hull, view).numpy(), target)
    return out


class _Recorder:
    """Wraps the objective: counts evaluations and records the cost at each iterate.

    ``objective()`` returns ``(cost, evaluated)``, ``evaluated`` False when the cost was
    remembered rather than computed. :meth:`mark` is called before each L-BFGS
    iteration; the first call after it gives the cost at the current iterate (after
    ``k`` iterations), recorded and reported to the callback. Progress is thus read
    from the objective itself, not from the optimiser's internal state.
    """

    def __init__(self, objective: Callable[[], tuple[Tensor, bool]], total: int, callback: ProgressCallback | None):
        self.objective = objective
        self.total = total
        self.callback = callback
        self.history: list[float] = []
        self.evaluations = 0
        self._marked = True

    def mark(self) -> None:
        self._marked = True

    def __call__(self) -> Tensor:
        cost, evaluated = self.objective()
        self.evaluations += int(evaluated)
        if self._marked:
            self._marked = False
            self.record(float(cost.detach()))
        return cost

    def record(self, cost: float) -> None:
        self.history.append(cost)
        done = len(self.history) - 1
        if done > 0 and self.callback is not None:
            self.callback("fit", done, self.total, cost)


def fit_silhouettes(
    drawings,
    config: VolumeFitConfig | None = None,
    *,
    callback: ProgressCallback | None = None,
) -> SilhouetteFit:
    """A scalar NURBS volume whose solid ``{f >= isovalue}`` matches three drawings.

    Args:
        drawings: ``{"front": ..., "left": ..., "top": ...}`` or a sequence of three in
            that order: image files (PNG, JPEG; polarity detected), Pillow images, or
            masks ``(H, W)`` with 1 inside the shape; any size. See
            :mod:`nurbskit.volume.views` for how pixels map onto the cube.
        config: a :class:`~nurbskit.volume.config.VolumeFitConfig` (None: the
            ``default`` preset; ``get_preset("paper")`` is the paper's setting).
        callback: ``callback(stage, done, total, cost)`` for progress.

    Returns:
        :class:`SilhouetteFit` with ``volume`` (control points ``(n_u, n_v, n_w, 1)``),
        ``mesh``, costs, per-view IoU and timings. Convention: device and dtype follow
        the first floating tensor among the drawings (else CPU float32); move the
        drawings to fit elsewhere.

    Raises:
        OptionError: a setting out of its range, or sizes that would not fit in memory
            (checked before any work).
        VolumeFitFailed: the fitted field is non-finite or its cost ended far above its start.

    Example:
        >>> from nurbskit.volume.shapes import paper_drawings
        >>> cfg = VolumeFitConfig(control_size=8, grid=12, iterations=5)
        >>> volume, mesh = fit_silhouettes(paper_drawings(32), cfg)
        >>> volume.control_points.shape
        torch.Size([8, 8, 8, 1])
    """
    t_start = time.perf_counter()
    cfg = dataclasses.replace(config).validate() if config is not None else default_config()
    sources = _as_drawings(drawings)
    device, dtype = _device_dtype(sources.values())
    check_fit_size(cfg, torch.finfo(dtype).bits // 8)
    masks = {name: load_drawing(src, name=name) for name, src in sources.items()}

    sizes = cfg.control_size
    degrees = (cfg.degree,) * 3
    knots = [clamped_uniform(n, cfg.degree, dtype=dtype, device=device) for n in sizes]
    axes = [torch.linspace(0, 1, r, dtype=dtype, device=device) for r in cfg.grid]
    planes = {v.name: mask_on_plane(masks[v.name].to(device, dtype), v, cfg.grid) for v in VIEWS}
    hull = visual_hull(planes)
    use_smooth = cfg.smooth_weight > 0
    smooth_axes = [
        _smoothness_axis(kv, cfg.degree, n, ax) if cfg.smooth_samples == "auto" else ax
        for kv, n, ax in zip(knots, sizes, axes)
    ]
    shared = all(s is a for s, a in zip(smooth_axes, axes))
    field_grid = GridField(knots, degrees, sizes, axes, second_derivatives=use_smooth and shared)
    smooth_grid = GridField(knots, degrees, sizes, smooth_axes) if use_smooth and not shared else None
    scale = (cfg.laplacian_unit,) * 3

    if cfg.resolved_init == "hull":
        init_planes = {v.name: mask_on_plane(masks[v.name].to(device, dtype), v, sizes) for v in VIEWS}
        values = visual_hull(init_planes).clone(memory_format=torch.contiguous_format)
    else:
        values = torch.zeros(sizes, dtype=dtype, device=device)
    values.requires_grad_(True)
    log_weights = torch.zeros(sizes, dtype=dtype, device=device, requires_grad=True)

    def costs() -> tuple[Tensor, Tensor, Tensor, Tensor]:
        weights = torch.exp(log_weights)
        if use_smooth and smooth_grid is None:
            f, lap = field_grid.evaluate_with_laplacian(values, weights, scale)
            smooth = smoothness_cost(lap)
        elif use_smooth:
            f = field_grid.evaluate(values, weights)
            smooth = smoothness_cost(smooth_grid.evaluate_with_laplacian(values, weights, scale)[1])
        else:
            f = field_grid.evaluate(values, weights)
            smooth = f.new_zeros(())
        if cfg.loss == "paper":
            shape = paper_shape_cost(f, hull)
        else:
            shape = silhouette_cost(f, planes, cfg.isovalue, cfg.sharpness)
        return cfg.shape_weight * shape + cfg.smooth_weight * smooth, shape, smooth, f

    trained = (values, log_weights)
    memo: list = []

    def cost_with_gradient() -> tuple[Tensor, bool]:
        # Each L-BFGS step starts by evaluating the point its previous line search
        # accepted, which that search has usually just evaluated: remembered, it is not
        # computed twice (bit-identical parameters, so the same cost and gradient).
        point = [t.detach() for t in trained]
        if memo and all(torch.equal(a, b) for a, b in zip(point, memo[0])):
            for t, g in zip(trained, memo[2]):
                t.grad = g.clone()
            return memo[1], False
        for t in trained:
            t.grad = None
        total = costs()[0]
        total.backward()
        memo[:] = [[p.clone() for p in point], total.detach(), [t.grad.clone() for t in trained]]
        return total.detach(), True

    # history[0]: the initial cost; history[k]: the cost after L-BFGS iteration k.
    recorder = _Recorder(cost_with_gradient, cfg.iterations, callback)
    iterations_run = 0
    if cfg.iterations > 0:
        # One L-BFGS iteration per step (its curvature pairs persist between steps); the
        # strong Wolfe line search may evaluate the cost up to 25 times per iteration.
        # (The fitting loop's L-BFGS: torch's iterations, without torch.optim.Optimizer's
        # import of torch._dynamo.)
        optimizer = LBFGS(list(trained), lr=1.0, history_size=10)
        grad_tolerance = 1e-7 if cfg.tolerance > 0 else 0.0

        def closure():
            return recorder()

        for _ in range(cfg.iterations):
            recorder.mark()
            optimizer.run(closure, max_iter=1, max_eval=25, tolerance_grad=0.0, tolerance_change=0.0)
            iterations_run += 1
            if grad_tolerance and _max_grad(trained) <= grad_tolerance:
                break
            if len(recorder.history) >= 2 and cfg.tolerance and abs(recorder.history[-1] - recorder.history[-2]) < cfg.tolerance:
                break
    with torch.no_grad():
        total, shape, smooth, f = costs()
    if iterations_run > 0 or not recorder.history:
        recorder.record(float(total))
    history = recorder.history
    _check_result(float(total), history[0], values, log_weights)
    t_fit = time.perf_counter()

    volume = NURBSVolume(
        values.detach().unsqueeze(-1), degrees, [k.clone() for k in knots], weights=torch.exp(log_weights.detach())
    )
    if cfg.resolved_mesh_resolution == cfg.grid:
        samples = f
    else:
        mesh_axes = [torch.linspace(0, 1, r, dtype=dtype, device=device) for r in cfg.resolved_mesh_resolution]
        with torch.no_grad():
            samples = GridField(knots, degrees, sizes, mesh_axes, second_derivatives=False).evaluate(
                values.detach(), torch.exp(log_weights.detach())
            )
    mesh = isosurface(samples, cfg.isovalue)
    message = None
    if mesh.is_empty:
        lo, hi = float(samples.min()), float(samples.max())
        message = (
            f"no surface at isovalue {cfg.isovalue}: the fitted field ranges over [{lo:.4g}, {hi:.4g}] "
            "on the mesh grid; try a lower isovalue, more iterations or a smaller smooth_weight"
        )
    t_mesh = time.perf_counter()
    if callback is not None:
        callback("mesh", 1, 1, None)

    scores, images = projection_iou(mesh, masks, cfg.iou_resolution)
    hull_scores = visual_hull_iou(masks, cfg.iou_resolution)
    t_end = time.perf_counter()
    return SilhouetteFit(
        volume=volume,
        mesh=mesh,
        config=cfg,
        costs={
            "total": float(total),
            "shape": float(shape),
            "smooth": float(smooth),
            "initial_total": history[0],
        },
        history=history,
        iterations=iterations_run,
        evaluations=recorder.evaluations,
        iou=scores,
        hull_iou=hull_scores,
        seconds={
            "fit": t_fit - t_start,
            "mesh": t_mesh - t_fit,
            "report": t_end - t_mesh,
            "total": t_end - t_start,
        },
        drawings=masks,
        projections=images,
        message=message,
    )


def _max_grad(tensors) -> float:
    return max(float(t.grad.abs().max()) if t.grad is not None else 0.0 for t in tensors)


def _check_result(final: float, initial: float, values: Tensor, log_weights: Tensor) -> None:
    """Raise :class:`VolumeFitFailed` for a non-finite field or a cost far above its start."""
    if not (math.isfinite(final) and torch.isfinite(values).all() and torch.isfinite(log_weights).all()):
        raise VolumeFitFailed(
            "the fitted field is NaN or infinite; try a smaller --shape-weight / --smooth-weight or fewer --iters"
        )
    if final > WORSE_FACTOR * initial + 1e-12:
        raise VolumeFitFailed(
            f"the fit's cost rose from {initial:.3g} to {final:.3g}; try fewer --iters or the default weights"
        )
