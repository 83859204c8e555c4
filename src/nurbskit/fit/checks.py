"""Checks around one fit: before it starts (size) and before it is called a success (result).

* :func:`check_fit_size`: a control net with more control points than the fitted points
  can determine is refused, and so is work whose dominant allocations would not fit in
  memory (the dense least-squares matrices, the sampled grids, the UM cost matrix); the
  message says what would fit.
* :func:`check_result`: a fitted surface that is NaN or infinite, or far farther from
  the input than the surface the fit started from, raises :class:`FitFailed` naming
  what went wrong and a setting to try.
"""

from __future__ import annotations

import math

import torch

from .._budget import available_bytes, human_bytes, largest_fitting
from ..core import NURBSSurface
from ..errors import NurbskitError, OptionError
from .config import FitConfig
from .loop import Target, stage_resolution
from .lstsq import solves_sparse

Tensor = torch.Tensor

#: A result this many times farther from the input (mean squared distance to the
#: nearest surface sample) than its own initial surface is a failure.
WORSE_FACTOR = 10.0
#: Samples per direction of the grid on which results are compared.
CHECK_RESOLUTION = 64


class FitFailed(NurbskitError):
    """The fit ran but its result is unusable (non-finite, or far worse than its start)."""


def _uses_least_squares(cfg: FitConfig) -> bool:
    return (
        cfg.init.kind in ("auto", "lstsq", "plane", "cylinder", "cage")
        or cfg.alternation.rounds > 0
        or any(s.eliminate_control_points or s.relocate_knots for s in cfg.stages)
    )


def fit_bytes(cfg: FitConfig, target: Target, ctrl: tuple[int, int], resolution: tuple[int, int]) -> float:
    """An upper estimate of the bytes of the largest allocations of one fit.

    Terms: the least-squares solve (a dense design matrix ``(M, k)`` built in three
    copies, the normal and smoothness matrices ``(k, k)`` several times, ``k`` control
    points and ``M`` fitted points; where :func:`~nurbskit.fit.lstsq.solves_sparse`, its
    sparse form: the design matrix's non-zeros, the banded normal matrix
    and LU factors of about ``(p + 1) min(n_u, n_v)`` entries a row, with their indices); each stage's sampled grid with its autograd
    intermediates (about 30 values per sample and coordinate); the UM matching's cost
    matrix (samples x points, float64).
    """
    item = target.points.element_size()
    m = target.points.shape[0]
    k = ctrl[0] * ctrl[1]
    total = 0.0
    if _uses_least_squares(cfg):
        rows = m if not target.supervised else target.grid.shape[0] * target.grid.shape[1]
        sparse = solves_sparse(rows, k, target.points.device) and not any(s.eliminate_control_points for s in cfg.stages)
        if sparse:  # lstsq's sparse solve: (p+1)(q+1) entries a row, a banded normal matrix and its LU factors
            p, q = cfg.degree or (3, 3)
            total += 16.0 * (3 * rows * (p + 1) * (q + 1) + 4 * k * (2 * p + 1) * (2 * q + 1)
                             + 4 * k * (max(p, q) + 1) * min(ctrl))
        else:
            total += item * (3.0 * rows * k + 8.0 * k * k)
    grids = [tuple(resolution)] + [stage_resolution(s, target, tuple(resolution)) for s in cfg.stages]
    total += max(grid_bytes(g, item) for g in grids)
    for s in cfg.stages:
        if s.rematch_every and s.loss.l2 and not target.supervised:
            r, c = stage_resolution(s, target, tuple(resolution))
            total += 2 * 8.0 * r * c * m
    return total


def check_fit_size(cfg: FitConfig, target: Target, *, budget: float | None = None) -> None:
    """Refuse, before any work, a fit that cannot be determined or cannot fit in memory.

    Raises an OptionError with one line: the control net against the number of fitted
    points (at most one control point per point), or the memory the
    control net and the grids need against what is available, with the largest
    ``--ctrl`` and ``--resolution`` that fit. (Supervised: the fitted points are the
    target grid's.)
    """
    n_u, n_v = cfg.ctrl
    k = n_u * n_v
    m = target.points.shape[0]
    if k > m:
        raise OptionError(
            f"ctrl: {n_u}x{n_v} = {k} control points cannot be determined by {m} fitted points; "
            + fewer_controls_hint(m, tuple(cfg.degree or (3, 3)), closed_v=cfg.init.closed == "v")
        )
    budget = available_bytes() if budget is None else budget
    res = tuple(cfg.resolution)
    need = fit_bytes(cfg, target, (n_u, n_v), res)
    if need <= budget:
        return
    hints = []
    side = largest_fitting(lambda n: fit_bytes(cfg, target, (n, n), res), budget, 2, max(n_u, n_v))
    if side is not None and side < max(n_u, n_v):
        hints.append(f"--ctrl {side}x{side}")
    r = largest_fitting(lambda n: fit_bytes(cfg, target, (n_u, n_v), (n, n)), budget, 2, max(res))
    if r is not None and r < max(res):
        hints.append(f"--resolution {r}x{r}")
    fits = (" or ".join(hints) + " fits") if hints else "reduce --ctrl, --resolution and the input (--max-points)"
    raise OptionError(
        f"a fit with --ctrl {n_u}x{n_v} and --resolution {res[0]}x{res[1]} on {m} points needs about "
        f"{human_bytes(need)} of memory but about {human_bytes(budget)} is available; {fits}"
    )


def smallest_net(degree: tuple[int, int], closed_v: bool = False) -> tuple[int, int]:
    """The fewest control points along u and v that ``degree (p, q)`` allows: ``p + 1``, ``q + 1``
    (``2 q + 1`` along v for a surface closed in v), as :meth:`FitConfig.validate` requires."""
    p, q = degree
    return p + 1, (2 * q + 1 if closed_v else q + 1)


def determined_net(m: int, degree: tuple[int, int], closed_v: bool = False) -> tuple[int, int] | None:
    """The largest control net (as square as ``degree`` allows) that ``m`` fitted points determine
    (at most one control point per point), or None when even :func:`smallest_net` needs more.

    Example:
        >>> determined_net(40, (3, 3)), determined_net(10, (3, 3)), determined_net(10, (2, 2))
        ((6, 6), None, (3, 3))
    """
    lo_u, lo_v = smallest_net(degree, closed_v)
    if lo_u * lo_v > m:
        return None
    side = math.isqrt(m)
    if side >= lo_u and side >= lo_v:
        return side, side
    if lo_u > side:
        return lo_u, m // lo_u
    return m // lo_v, lo_v


def fewer_controls_hint(m: int, degree: tuple[int, int], closed_v: bool = False, *, prefix: str = "") -> str:
    """What to ask for instead when ``m`` fitted points cannot determine the control net: a
    ``--ctrl`` that they determine and ``degree`` allows, else a lower ``--degree`` with one, else
    that no surface is determined (``prefix`` goes before the options, e.g. a command).

    Example:
        >>> fewer_controls_hint(10, (3, 3))
        'degree 3x3 needs at least 4x4 = 16 control points; use a lower degree, e.g. --degree 2 --ctrl 3x3'
    """
    net = determined_net(m, degree, closed_v)
    if net is not None:
        return f"use at most {m} control points, e.g. {prefix}--ctrl {net[0]}x{net[1]}"
    lo_u, lo_v = smallest_net(degree, closed_v)
    need = f"degree {degree[0]}x{degree[1]} needs at least {lo_u}x{lo_v} = {lo_u * lo_v} control points"
    for d in range(max(degree) - 1, 0, -1):
        lower = (min(degree[0], d), min(degree[1], d))
        net = determined_net(m, lower, closed_v)
        if net is not None:
            shown = str(lower[0]) if lower[0] == lower[1] else f"{lower[0]}x{lower[1]}"
            return f"{need}; use a lower degree, e.g. {prefix}--degree {shown} --ctrl {net[0]}x{net[1]}"
    lo_u, lo_v = smallest_net((1, 1), closed_v)
    return f"{need}, and even degree 1 needs {lo_u * lo_v} points: {m} points are too few for a surface"


def grid_bytes(resolution: tuple[int, int], item: int) -> float:
    """Bytes of one sampled ``(R, S, 3)`` grid with the autograd intermediates of a loss on it."""
    return item * 90.0 * resolution[0] * resolution[1]


def check_resolution(resolution: tuple[int, int], item: int = 8, *, budget: float | None = None) -> None:
    """Refuse a sampling grid (``--resolution``) that cannot fit in memory, before sampling anything."""
    budget = available_bytes() if budget is None else budget
    need = grid_bytes(resolution, item)
    if need > budget:
        r = largest_fitting(lambda n: grid_bytes((n, n), item), budget, 2, max(resolution))
        raise OptionError(
            f"--resolution {resolution[0]}x{resolution[1]} needs about {human_bytes(need)} of memory but about "
            f"{human_bytes(budget)} is available; " + (f"--resolution {r}x{r} fits" if r else "nothing fits")
        )


def _distance_to(surface: NURBSSurface, points: Tensor) -> float:
    """Mean squared distance from ``points (N, 3)`` to the nearest sample of the surface."""
    from ..core.neighbors import nearest_neighbors

    with torch.no_grad():
        grid = surface.sample((CHECK_RESOLUTION, CHECK_RESOLUTION)).reshape(-1, points.shape[-1])
        if not torch.isfinite(grid).all():
            return math.inf
        sq, _ = nearest_neighbors(points, grid)
    return float(sq.mean())


def _lr(cfg: FitConfig) -> str:
    rates = sorted({s.lr for s in cfg.stages})
    return ", ".join(f"{r:g}" for r in rates) or "none"


def check_result(fitted: NURBSSurface, initial: NURBSSurface, target: Target, cfg: FitConfig) -> None:
    """Raise :class:`FitFailed` when the result (fit units) is unusable.

    Unusable: NaN or infinite control points or weights, or a mean squared distance from
    the input to the surface more than :data:`WORSE_FACTOR` times that of the initial
    surface (plus 1e-6 of the squared diagonal, so that exact starts do not count).
    """
    if not (torch.isfinite(fitted.control_points).all() and torch.isfinite(fitted.weights).all()):
        raise FitFailed(
            f"the fitted surface is NaN or infinite; lower the learning rate (--lr, now {_lr(cfg)})"
        )
    before = _distance_to(initial, target.points)
    after = _distance_to(fitted, target.points)
    if not math.isfinite(after) or after > WORSE_FACTOR * before + 1e-6:
        raise FitFailed(
            f"the fitted surface is {math.sqrt(after / max(before, 1e-300)):.3g} times farther from the input "
            f"than the surface it started from (RMS {math.sqrt(after):.3g} against {math.sqrt(before):.3g} of the "
            f"diagonal); lower the learning rate (--lr, now {_lr(cfg)}) or the iterations (--iters)"
        )
