"""Fit a scalar NURBS volume to three drawings (front, left, top) and extract its isosurface.

Method (W. Li, "Multi-view NURBS Volume"): a scalar field ``f = sum V B B B W / sum B B B W``
on ``[0, 1]^3`` is optimised with L-BFGS over its control values ``V`` and weights ``W``
(kept positive as ``W = exp(theta)``) to minimise
``shape_weight * C_shape + smooth_weight * C_smooth`` evaluated on a grid; the solid is
``{f >= isovalue}`` and its surface comes from marching cubes. The costs are described
in :mod:`nurbskit.volume.losses`, the axes and pixel mapping in :mod:`nurbskit.volume.views`.

The paper's defaults: order 3 (degree 2), 50^3 control values, a 20^3 grid, weights
0.1 / 0.9, isovalue 0.5, 100 iterations, control values starting at 0 and weights at 1.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Iterator, Sequence

import numpy as np
import torch

from ..core.knots import clamped_uniform
from ..core.volume import NURBSVolume
from ..errors import OptionError
from .drawings import DrawingLike, load_drawing, mask_on_plane, resample
from .field import GridField
from .losses import paper_shape_cost, silhouette_cost, smoothness_cost, visual_hull
from .mesh import Mesh, iou, isosurface, rasterize_projection
from .views import VIEW_NAMES, VIEWS, project_grid

Tensor = torch.Tensor
LOSSES = ("paper", "silhouette")
INITS = ("zeros", "hull")
SMOOTH_SAMPLES = ("auto", "grid")
#: ``callback(stage, done, total, cost)``: stage 'fit' after each L-BFGS iteration ``done``
#: of at most ``total`` (cost: the total cost), then 'mesh' once (cost None).
ProgressCallback = Callable[[str, int, int, "float | None"], None]


@dataclass
class VolumeFitConfig:
    """Settings of :func:`fit_silhouettes` (saved in every report)."""

    control_size: tuple[int, int, int] = (50, 50, 50)
    """Control values per axis (x, y, z); the paper uses 50."""
    grid: tuple[int, int, int] = (20, 20, 20)
    """Grid points per axis where the costs are evaluated (the paper's "cell size" 20)."""
    degree: int = 2
    """B-spline degree in every direction (the paper's order 3 = degree 2)."""
    iterations: int = 100
    """Maximum L-BFGS iterations; it stops earlier when the cost stops changing."""
    isovalue: float = 0.5
    """The solid is ``f >= isovalue``."""
    shape_weight: float = 0.1
    smooth_weight: float = 0.9
    loss: str = "paper"
    """'paper' (volume against the visual hull) or 'silhouette' (projections against the drawings)."""
    init: str = "zeros"
    """'zeros' (the paper: values 0, weights 1) or 'hull' (values from the visual hull)."""
    sharpness: float = 20.0
    """Silhouette loss: slope of the soft projection ``sigmoid(sharpness (max f - isovalue))``."""
    laplacian_unit: float = 0.01
    """Length unit of the smoothness cost's Laplacian (``unit^2 lap f``), as a fraction of the cube."""
    smooth_samples: str = "auto"
    """Where the smoothness cost is sampled: 'grid' (the fitting grid, as the paper) or 'auto'
    (the fitting grid, or the knot-span midpoints along an axis where the grid has more
    points than the control net has knot spans)."""
    tolerance: float = 1e-9
    """L-BFGS stops when the cost changes less than this between iterations (0: never)."""
    mesh_resolution: tuple[int, int, int] = (20, 20, 20)
    """Grid for marching cubes (defaults to ``grid``)."""
    iou_resolution: int = 256
    """Side of the square raster on which projections are compared with the drawings."""

    def validate(self) -> "VolumeFitConfig":
        def triple(name, value, least):
            if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
                value = (int(value),) * 3
            try:
                value = tuple(int(v) for v in value)
            except (TypeError, ValueError):
                raise OptionError(f"{name} must be an integer or three integers, got {value!r}") from None
            if len(value) != 3 or min(value) < least:
                raise OptionError(f"{name} must be one or three integers >= {least}, got {value!r}")
            return value

        if not isinstance(self.degree, (int, np.integer)) or isinstance(self.degree, bool) or self.degree < 1:
            raise OptionError(f"degree must be an integer >= 1, got {self.degree!r}")
        self.degree = int(self.degree)
        self.control_size = triple("control_size", self.control_size, self.degree + 1)
        self.grid = triple("grid", self.grid, 2)
        self.mesh_resolution = triple("mesh_resolution", self.mesh_resolution, 2)
        if not isinstance(self.iterations, (int, np.integer)) or isinstance(self.iterations, bool) or self.iterations < 0:
            raise OptionError(f"iterations must be an integer >= 0, got {self.iterations!r}")
        for name in ("isovalue", "shape_weight", "smooth_weight", "sharpness", "laplacian_unit", "tolerance"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise OptionError(f"{name} must be a finite number, got {value!r}")
        if self.shape_weight <= 0:
            raise OptionError(f"shape_weight must be > 0 (without it nothing ties the solid to the drawings), got {self.shape_weight}")
        if self.smooth_weight < 0:
            raise OptionError(f"smooth_weight must be >= 0, got {self.smooth_weight}")
        if self.sharpness <= 0:
            raise OptionError(f"sharpness must be > 0, got {self.sharpness}")
        if self.tolerance < 0:
            raise OptionError(f"tolerance must be >= 0, got {self.tolerance}")
        if self.laplacian_unit <= 0:
            raise OptionError(f"laplacian_unit must be > 0, got {self.laplacian_unit}")
        if self.smooth_samples not in SMOOTH_SAMPLES:
            raise OptionError(f"smooth_samples must be one of {list(SMOOTH_SAMPLES)}, got {self.smooth_samples!r}")
        if self.loss not in LOSSES:
            raise OptionError(f"loss must be one of {list(LOSSES)}, got {self.loss!r}")
        if self.init not in INITS:
            raise OptionError(f"init must be one of {list(INITS)}, got {self.init!r}")
        if not isinstance(self.iou_resolution, (int, np.integer)) or self.iou_resolution < 2:
            raise OptionError(f"iou_resolution must be an integer >= 2, got {self.iou_resolution!r}")
        return self


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
        cfg = asdict(self.config)
        return {
            "config": {k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
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


def _pick_device_dtype(inputs, device, dtype):
    tensors = [t for t in inputs if isinstance(t, Tensor)]
    if device is None:
        device = tensors[0].device if tensors else torch.device("cpu")
    if dtype is None:
        floats = [t.dtype for t in tensors if t.is_floating_point()]
        dtype = floats[0] if floats else torch.float32
    if not dtype.is_floating_point:
        raise OptionError(f"dtype must be a floating-point dtype, got {dtype}")
    return torch.device(device), dtype


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


def fit_silhouettes(
    front: DrawingLike,
    left: DrawingLike,
    top: DrawingLike,
    *,
    control_size: int | Sequence[int] = 50,
    grid: int | Sequence[int] = 20,
    degree: int = 2,
    iterations: int = 100,
    isovalue: float = 0.5,
    shape_weight: float = 0.1,
    smooth_weight: float = 0.9,
    loss: str = "paper",
    init: str | None = None,
    sharpness: float = 20.0,
    laplacian_unit: float = 0.01,
    smooth_samples: str = "auto",
    tolerance: float = 1e-9,
    mesh_resolution: int | Sequence[int] | None = None,
    iou_resolution: int = 256,
    device: torch.device | str | None = None,
    dtype: torch.dtype | None = None,
    callback: ProgressCallback | None = None,
) -> SilhouetteFit:
    """A scalar NURBS volume whose solid ``{f >= isovalue}`` matches three drawings.

    Args:
        front, left, top: image files (PNG, JPEG; polarity detected), Pillow images, or
            masks ``(H, W)`` with 1 inside the shape; any size. See
            :mod:`nurbskit.volume.views` for how pixels map onto the cube.
        control_size: control values per axis (one int or three).
        grid: grid points per axis where the costs are evaluated.
        degree: B-spline degree (paper: order 3 = degree 2).
        iterations: maximum L-BFGS iterations (0: keep the initial field).
        isovalue, shape_weight, smooth_weight: the paper's ``C``, ``w_shape``, ``w_smooth``.
        loss: 'paper' or 'silhouette' (see :mod:`nurbskit.volume.losses`).
        init: 'zeros' or 'hull'; default 'zeros' for the paper loss, 'hull' for silhouette.
        sharpness: slope of the silhouette loss's soft projection.
        laplacian_unit: length unit of the smoothness Laplacian (fraction of the cube).
        smooth_samples: 'auto' or 'grid' (see :class:`VolumeFitConfig`).
        tolerance: L-BFGS stops when the cost changes less than this (0: run all iterations).
        mesh_resolution: marching-cubes grid (default: ``grid``).
        iou_resolution: raster side for the reported IoU.
        device, dtype: default the device and dtype of tensor inputs, else CPU float32.
        callback: ``callback(stage, done, total, cost)`` for progress.

    Returns:
        :class:`SilhouetteFit` with ``volume`` (control points ``(n_u, n_v, n_w, 1)``),
        ``mesh``, costs, per-view IoU and timings.

    Example:
        >>> from nurbskit.volume.shapes import paper_drawings
        >>> d = paper_drawings(32)
        >>> volume, mesh = fit_silhouettes(d["front"], d["left"], d["top"], control_size=8, grid=12, iterations=5)
        >>> volume.control_points.shape
        torch.Size([8, 8, 8, 1])
    """
    t_start = time.perf_counter()
    cfg = VolumeFitConfig(
        control_size=control_size,
        grid=grid,
        degree=degree,
        iterations=iterations,
        isovalue=isovalue,
        shape_weight=shape_weight,
        smooth_weight=smooth_weight,
        loss=loss,
        init=init if init is not None else ("hull" if loss == "silhouette" else "zeros"),
        sharpness=sharpness,
        laplacian_unit=laplacian_unit,
        smooth_samples=smooth_samples,
        tolerance=tolerance,
        mesh_resolution=grid if mesh_resolution is None else mesh_resolution,
        iou_resolution=iou_resolution,
    ).validate()
    device, dtype = _pick_device_dtype((front, left, top), device, dtype)
    masks = {name: load_drawing(src, name=name) for name, src in zip(VIEW_NAMES, (front, left, top))}

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

    if cfg.init == "hull":
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

    # history[0]: the initial cost; history[k]: the cost after L-BFGS iteration k.
    history: list[float] = []
    evaluations = 0
    iterations_run = 0

    def report(done: int, cost: float) -> None:
        history.append(cost)
        if callback is not None:
            callback("fit", done, cfg.iterations, cost)

    if cfg.iterations > 0:
        optimizer = torch.optim.LBFGS(
            [values, log_weights],
            lr=1.0,
            max_iter=cfg.iterations,
            max_eval=3 * cfg.iterations,
            history_size=10,
            tolerance_change=cfg.tolerance,
            tolerance_grad=1e-7 if cfg.tolerance > 0 else 0.0,
            line_search_fn="strong_wolfe",
        )
        state = optimizer.state[values]
        last = [0.0]

        def closure():
            nonlocal evaluations
            # torch's L-BFGS increments n_iter before iteration n's line search, so when
            # it reads n, iterations up to n - 1 are finished; the line search ends on
            # the accepted point, whose cost was the previous evaluation.
            started = int(state.get("n_iter", 0))
            while started > 0 and len(history) < started:
                report(len(history), last[0])
            optimizer.zero_grad(set_to_none=True)
            total = costs()[0]
            total.backward()
            evaluations += 1
            last[0] = float(total.detach())
            if not history:
                history.append(last[0])  # the initial cost
            return total

        optimizer.step(closure)
        iterations_run = int(state.get("n_iter", 0))
    with torch.no_grad():
        total, shape, smooth, f = costs()
    if not history:
        history.append(float(total))
    while len(history) < iterations_run:
        report(len(history), last[0])
    if iterations_run > 0:
        report(iterations_run, float(total))
    t_fit = time.perf_counter()

    volume = NURBSVolume(
        values.detach().unsqueeze(-1), degrees, [k.clone() for k in knots], weights=torch.exp(log_weights.detach())
    )
    if cfg.mesh_resolution == cfg.grid:
        samples = f
    else:
        mesh_axes = [torch.linspace(0, 1, r, dtype=dtype, device=device) for r in cfg.mesh_resolution]
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
        evaluations=evaluations,
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
