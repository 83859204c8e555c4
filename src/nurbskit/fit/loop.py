"""The one generic fitting loop.

:func:`run_stage` runs one :class:`~nurbskit.fit.config.StageConfig`: it samples
the current surface, adds up the weighted loss terms of
:class:`~nurbskit.fit.config.LossWeights`, steps the optimiser (Adam, SGD or
L-BFGS) on the trainable tensors of a
:class:`~nurbskit.fit.params.SurfaceParameters`, reports progress through a
callback and stops at the stage's iteration count or loss threshold. Every thesis
pipeline and our default are sequences of such stages (:mod:`.pipelines`).

What a loss term compares (``X`` the input in fit units, ``Y`` the surface sampled on
the stage's grid):

=================  =========================================================
``l2``             ``Y`` against the ordered target: the supervised grid, the
                   first ``R*S`` input points (UB), or the points matched one to
                   one (UM, :mod:`.matching`)
``chamfer``        :func:`nurbskit.losses.chamfer_distance` (X, Y)
``hausdorff``      :func:`nurbskit.losses.hausdorff_distance` (X, Y)
``laplacian``      supervised: Laplacian difference to the true control net (or
                   target grid); otherwise the Laplacian energy of ``Y`` or of
                   the control net (``laplacian_on``)
``point_to_surface`` mean squared distance from ``X`` to its foot points
                   (true projection; envelope-theorem gradients)
``coverage``       mean squared distance from ``Y`` to its nearest input point
``smoothness``     Laplacian energy of the control net
=================  =========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import torch

from .. import losses as L
from .._cuda_graph import GraphedStep
from ..errors import OptionError
from ..core.neighbors import NeighborIndex
from .config import StageConfig
from ..core.knots import knots_to_logits
from ..core.project import project_points
from .lstsq import equidistributed_knots, solve_control_points
from .matching import one_to_one_matching
from .optim import LBFGS
from .params import SurfaceParameters

Tensor = torch.Tensor


@dataclass
class Target:
    """What a fit is compared with, in fit units.

    ``points (N, 3)`` always; supervised fits add the ordered ``grid (R, S, 3)`` (its
    parameters are the uniform grid of the fitted surface's domain) and, when known,
    the true control net ``control_points (n_u, n_v, 3)``.
    """

    points: Tensor
    grid: Tensor | None = None
    control_points: Tensor | None = None

    @property
    def supervised(self) -> bool:
        return self.grid is not None


@dataclass
class Progress:
    """One progress report: the loop calls ``callback(progress)`` after every iteration."""

    stage: str
    stage_index: int
    iteration: int
    stage_iters: int
    loss: float
    parts: dict[str, float] = field(default_factory=dict)


@dataclass
class _State:
    """What persists between iterations of a stage (matching, foot points, the search
    structure on the input points, built once per stage)."""

    matched: Tensor | None = None
    foot: Tensor | None = None
    index: NeighborIndex | None = None
    axes: list[Tensor] | None = None  # the sampling grid; the domain's ends stay fixed in a stage
    warm: GraphedStep | None = None  # the warm foot-point refresh (one CUDA graph on a GPU)


def _store(state: _State, name: str, value: Tensor) -> None:
    """Set ``state.<name>``, in place once it exists: a captured objective (a CUDA graph)
    reads the tensor it saw when it was captured, so the matching and the foot points
    must stay the same tensors for the whole stage."""
    old = getattr(state, name)
    if old is None or old.shape != value.shape or old.dtype != value.dtype:
        setattr(state, name, value)
    else:
        old.copy_(value)


def stage_resolution(stage: StageConfig, target: Target, default: tuple[int, int]) -> tuple[int, int]:
    """The sampling grid of a stage: explicit, same size as the input, or the default."""
    if stage.resolution is not None:
        return tuple(stage.resolution)
    if target.supervised:
        return tuple(target.grid.shape[:2])
    if stage.same_size_as_input:
        r = max(2, int(math.isqrt(target.points.shape[0])))
        return (r, r)
    return tuple(default)


def stage_loss(
    params: SurfaceParameters,
    stage: StageConfig,
    target: Target,
    resolution: tuple[int, int],
    state: _State,
    iteration: int,
) -> tuple[Tensor, dict[str, Tensor]]:
    """The weighted loss of a stage for the current parameters, and its parts (tensors).

    Reads nothing back to the host (no finiteness test, no ``float``): a non-finite
    surface shows as a non-finite loss, which the caller reads once per iteration.
    """
    w = stage.loss
    surface = params()
    closed_v = params.closed_v
    if stage.eliminate_control_points:
        surface = surface._replace(control_points=eliminated_control_points(surface, target, params.topology))
    needs_grid = any(
        getattr(w, k) for k in ("l2", "chamfer", "hausdorff", "coverage")
    ) or (w.laplacian and (target.supervised or w.laplacian_on == "grid"))
    parts: dict[str, Tensor] = {}
    grid = flat = None
    if needs_grid:
        if state.axes is None:
            state.axes = surface.grid_axes(resolution)  # reads the domain once per stage
        grid = surface.evaluate_grid(*state.axes)
        flat = grid.reshape(-1, grid.shape[-1])
    x = target.points
    if w.l2:
        if target.supervised:
            ordered = target.grid.reshape(-1, x.shape[-1])
        elif stage.rematch_every:
            ordered = x[state.matched]
        else:
            if x.shape[0] < flat.shape[0]:
                raise OptionError(
                    f"the L2 loss pairs the {flat.shape[0]} surface samples with the first input points, "
                    f"but the input has only {x.shape[0]}"
                )
            ordered = x[: flat.shape[0]]  # thesis UB: points in file order
        parts["l2"] = L.l2_loss(flat, ordered)
    if (w.chamfer or w.hausdorff or w.coverage) and state.index is None:
        state.index = NeighborIndex(x)  # the input's KD-tree, built once per stage
    # Chamfer and Hausdorff are symmetric: (samples, input) with the input's index is the
    # same loss as (input, samples) (its gradient summed in another order: 1e-16 apart
    # after 30 iterations of UC, UCDH and default on 2,000 points).
    if w.chamfer:
        parts["chamfer"] = L.chamfer_distance(flat, x, y_index=state.index)
    if w.hausdorff:
        parts["hausdorff"] = L.hausdorff_distance(flat, x, y_index=state.index)
    if w.laplacian:
        if target.supervised:
            if target.control_points is not None and target.control_points.shape == surface.control_points.shape:
                parts["laplacian"] = L.laplacian_supervised(surface.control_points, target.control_points)
            else:
                parts["laplacian"] = L.laplacian_supervised(grid, target.grid)
        elif w.laplacian_on == "grid":
            g = grid[:, :-1] if closed_v else grid  # the seam column repeats the first
            parts["laplacian"] = L.laplacian_grid(g, closed_v=closed_v, boundary=w.laplacian_boundary)
        else:
            cp = surface.control_points[:, : params.n_v - params.degrees[1]] if closed_v else surface.control_points
            parts["laplacian"] = L.laplacian_control(cp, closed_v=closed_v, boundary=w.laplacian_boundary)
    if w.point_to_surface:
        closest = surface.evaluate(state.foot)
        parts["point_to_surface"] = (closest - x).square().sum(-1).mean()
    if w.coverage:
        # a non-finite surface searches with zeros; its loss is non-finite all the same
        idx = state.index.indices(torch.nan_to_num(flat.detach(), 0.0, 0.0, 0.0))
        parts["coverage"] = (flat - x.index_select(0, idx)).square().sum(-1).mean()
    if w.smoothness:
        cp = surface.control_points[:, : params.n_v - params.degrees[1]] if closed_v else surface.control_points
        parts["smoothness"] = L.laplacian_control(cp, closed_v=closed_v)
    total = sum(getattr(w, k) * v for k, v in parts.items())
    return total, parts


def refresh_state(
    params: SurfaceParameters, stage: StageConfig, target: Target, resolution: tuple[int, int], state: _State, iteration: int
) -> None:
    """Update what a step holds fixed: the UM matching and the foot points of the inputs.

    Called before each optimiser step, so that every loss evaluation of that step (an
    L-BFGS line search makes several) sees the same objective. Foot points come from the
    one projection (:func:`nurbskit.core.project.project_points`): from the grid in the
    first iteration, then warm from the last ones with a fixed number of masked Newton
    iterations, which reads nothing back to the host.
    """
    w = stage.loss
    if not (w.point_to_surface or (w.l2 and stage.rematch_every and not target.supervised)):
        return
    with torch.no_grad():
        if w.l2 and stage.rematch_every and not target.supervised:
            if state.matched is None or iteration % stage.rematch_every == 0:
                flat = params().detach().sample(resolution).reshape(-1, target.points.shape[-1])
                _store(state, "matched", one_to_one_matching(flat, target.points))
        if w.point_to_surface:
            every = max(stage.reproject_every, 1)
            periodic = (False, params.closed_v)
            if state.foot is None:
                state.foot = project_points(params().detach(), target.points, periodic=periodic).params
            elif iteration % (20 * every) == 0:
                # Also restarted from the nearest grid sample every 20 refreshes (a foot
                # point can jump to another part of the surface); the closer result wins.
                _store(state, "foot", project_points(params().detach(), target.points, params=state.foot,
                                                     periodic=periodic, iterations=2, restart=True, check_every=0,
                                                     validate=False, second_order=False).params)
            elif iteration % every == 0:
                # Warm start from the last foot points (the surface moves little per step):
                # fixed shapes and no host read, so on a GPU this is one replayed graph.
                if state.warm is None:
                    def warm() -> Tensor:
                        return state.foot.copy_(project_points(
                            params().detach(), target.points, params=state.foot, periodic=periodic, iterations=2,
                            check_every=0, validate=False, second_order=False,
                        ).params)

                    state.warm = GraphedStep(warm, device=state.foot.device)
                state.warm()


def relocate_knots(params: SurfaceParameters, target: Target) -> None:
    """Move the interior knots by :func:`~nurbskit.fit.lstsq.equidistributed_knots` of the target grid.

    Along a closed v the knots stay uniform. The control points are then re-solved by
    least squares at the new knots, so the surface stays close to the target.
    """
    if not target.supervised:
        raise OptionError("relocate_knots needs a supervised (ordered grid) target")
    p, q = params.degrees
    with torch.no_grad():
        ku = equidistributed_knots(target.grid, 0, params.n_u, p)
        new = [ku, params.fixed_knots_v.clone()]
        if not params.closed_v:
            new[1] = equidistributed_knots(target.grid, 1, params.n_v, q)
        for kv, buf, logits, deg, n in (
            (new[0], params.fixed_knots_u, params.knot_logits_u, p, params.n_u),
            (new[1], params.fixed_knots_v, params.knot_logits_v, q, params.n_v),
        ):
            buf.copy_(kv.to(buf))
            logits.copy_(knots_to_logits(kv.to(buf), deg, n))
        surface = params()
        params.load_control_points(eliminated_control_points(surface, target, params.topology))


def grid_parameters(surface, resolution: tuple[int, int]) -> Tensor:
    """The ``(R * S, 2)`` parameters of the uniform grid, u slowest (``surface.sample`` order)."""
    gu, gv = surface.grid_axes(resolution)
    uu, vv = torch.meshgrid(gu, gv, indexing="ij")
    return torch.stack([uu.reshape(-1), vv.reshape(-1)], dim=-1)


def eliminated_control_points(surface, target: Target, topology) -> Tensor:
    """Least-squares control points for a supervised grid target at the surface's knots and weights."""
    if not target.supervised:
        raise OptionError("eliminate_control_points needs a supervised (ordered grid) target")
    uv = grid_parameters(surface, tuple(target.grid.shape[:2]))
    return solve_control_points(
        uv, target.grid.reshape(-1, target.grid.shape[-1]), surface.knot_vectors, surface.degrees,
        surface.sizes, surface.weights, topology,
    )


def make_optimizer(stage: StageConfig, tensors: list[Tensor]) -> torch.optim.Optimizer | LBFGS:
    """Adam, SGD (momentum 0.9) or L-BFGS (:class:`.optim.LBFGS`, strong Wolfe line search) over ``tensors``."""
    if stage.optimizer == "adam":
        return torch.optim.Adam(tensors, lr=stage.lr)
    if stage.optimizer == "sgd":
        return torch.optim.SGD(tensors, lr=stage.lr, momentum=0.9)
    if stage.optimizer == "lbfgs":
        # One L-BFGS iteration per loop iteration; its curvature pairs come from its own
        # line search, so refreshing the foot points between steps does not spoil them.
        return LBFGS(tensors, lr=stage.lr, history_size=20, max_eval=25, tolerance_change=1e-16)
    raise OptionError(f"optimizer must be adam, sgd or lbfgs, got {stage.optimizer!r}")


def run_stage(
    params: SurfaceParameters,
    stage: StageConfig,
    target: Target,
    default_resolution: tuple[int, int],
    *,
    stage_index: int = 0,
    callback: Callable[[Progress], None] | None = None,
) -> list[dict]:
    """Run one stage of the generic loop; returns one history record per iteration.

    Each record is ``{"stage", "iteration", "loss", "parts", "evaluations"}`` with the loss
    *before* that iteration's step and the loss evaluations the step made; the stage's
    last record also says how they ran, ``"cuda_graph"``: ``"captured"`` (replayed CUDA
    graphs) or why they ran eagerly. ``params`` is updated in place.
    """
    if stage.relocate_knots:
        relocate_knots(params, target)
    params.set_trainable(stage.train_control_points, stage.train_weights, stage.train_knots)
    tensors = params.trainable()
    history: list[dict] = []
    if stage.iters == 0 or not tensors:
        return history
    resolution = stage_resolution(stage, target, default_resolution)
    opt = make_optimizer(stage, tensors)
    state = _State()

    def objective() -> tuple[Tensor, dict[str, Tensor]]:
        loss, parts = stage_loss(params, stage, target, resolution, state, 0)
        loss.backward()
        return loss.detach(), {k: v.detach() for k, v in parts.items()}

    # The loss and its gradient: eager on the first call (it builds the grid axes and the
    # neighbour index), then on a GPU one replayed CUDA graph, which writes the same loss,
    # parts and .grad tensors every time (nurbskit._cuda_graph).
    evaluate = GraphedStep(objective, tensors, device=tensors[0].device)
    for it in range(stage.iters):
        record: dict = {}
        refresh_state(params, stage, target, resolution, state, it)

        def closure():
            loss, parts = evaluate()
            record["evaluations"] = record.get("evaluations", 0) + 1
            if "loss" not in record:
                # The one read of the iteration: the loss and its parts together.
                values = torch.stack([loss, *parts.values()]).tolist()
                value, part_values = values[0], dict(zip(parts, values[1:]))
            else:
                value = float(loss)  # an L-BFGS line search: torch reads it anyway
            if not math.isfinite(value):
                if stage.optimizer != "lbfgs" or "loss" not in record:
                    raise OptionError(
                        f"stage {stage.name}: the surface became NaN or infinite at iteration {it}; "
                        f"lower the learning rate (lr={stage.lr})"
                    )
                # Inside an L-BFGS line search: a huge loss with zero gradient makes the
                # search shorten its step instead of failing (in place: a replayed graph
                # writes these same gradient tensors).
                for t in tensors:
                    if t.grad is None:
                        t.grad = torch.zeros_like(t)
                    else:
                        t.grad.zero_()
                return torch.full((), 1e30, dtype=tensors[0].dtype, device=tensors[0].device)
            if "loss" not in record:
                record.update(loss=value, parts=part_values)
            return loss

        opt.step(closure)
        history.append({"stage": stage.name, "iteration": it, **record})
        if callback is not None:
            callback(Progress(stage.name, stage_index, it, stage.iters, record["loss"], record["parts"]))
        if stage.loss_threshold and record["loss"] < stage.loss_threshold:
            break
        if stage.plateau and it >= 10:
            before = history[-11]["loss"]
            if before - record["loss"] < stage.plateau * abs(before):
                break
    # how the stage's evaluations ran: "captured" (replayed graphs) or why they ran eagerly
    history[-1]["cuda_graph"] = "captured" if evaluate.captured else evaluate.reason
    evaluate.release()
    if state.warm is not None:
        state.warm.release()
    if stage.eliminate_control_points:
        with torch.no_grad():
            surface = params()
            params.load_control_points(eliminated_control_points(surface, target, params.topology))
    if stage.train_knots:
        params.freeze_knots()
    return history
