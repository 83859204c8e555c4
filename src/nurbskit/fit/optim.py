"""L-BFGS for objectives that change between steps, with no host read in its direction.

The fitting loop refreshes what a step holds fixed before every step: the foot points
of the inputs (``point_to_surface``) or the one-to-one matching (``l2`` with
``rematch_every``). ``torch.optim.LBFGS`` stepped once per iteration pairs the gradient
at the start of this step with the one at the start of the last step, that is two
gradients of two different objectives, so its curvature pairs mix the change of the
parameters with the change of the objective; on the default fit its unit step
overshot in every iteration and the line search needed a third evaluation to come
back. :class:`LBFGS` takes its pair ``(s, y)`` from the two ends of its own line
search instead (Nocedal and Wright, *Numerical Optimization*, 2nd ed., algorithm
7.5: ``s = x_new - x``, ``y = g(x_new) - g(x)``, one objective), and the unit step is
then accepted as a rule: on the default fit of 20,000 points, 2.1 evaluations per
iteration instead of 3.1 (``benchmarks/results/fit_scale.md``). Where the objective does not change between
steps the two pairings are the same.

The two-loop recursion (algorithm 7.4) runs on 0-dimensional tensors: a pair whose
curvature ``y . s`` is not positive gets ``rho = 0`` and drops out of it, instead of
being tested on the host, so the direction reads nothing back (``torch.optim.LBFGS``
reads two scalars per stored pair). The line search is torch's strong Wolfe search
(``c1 = 1e-4``, ``c2 = 0.9``), which reads its comparisons.

:meth:`LBFGS.run` is the other use: up to ``max_iter`` iterations on one fixed
objective, each starting where its predecessor's line search ended, as one step of
``torch.optim.LBFGS(max_iter=...)`` does; its iterates are torch's to the last bit (a
test checks), and the curves' Chamfer refinement, the revolution and extrusion fits and
the volume fit run on it. So the project has one L-BFGS.

:class:`LBFGS` is a plain class with the methods its users call (``zero_grad``,
``step``, ``run``), not a ``torch.optim.Optimizer``: that base class's constructor
imports ``torch._dynamo`` on its first use in a process (0.75 s with torch 2.13 on the
2-core machine), which was 40 % of a 3,000-point default fit run from the command line
(1.9 s) and half of ``nurbskit curves --refine`` on a small drawing.
"""

from __future__ import annotations

from typing import Callable

import torch
from torch.optim.lbfgs import _strong_wolfe  # private, but the search stays torch's own

Tensor = torch.Tensor


class LBFGS:
    """One L-BFGS iteration per :meth:`step`, curvature pairs from one objective.

    Args:
        params: the tensors to optimise (one parameter group).
        lr: the first trial step of each line search (after the first iteration, whose
            trial is ``min(1, 1 / |g|_1) * lr``, as in ``torch.optim.LBFGS``).
        history_size: how many curvature pairs are kept.
        max_eval: evaluations per step at most, the first one's included (as in
            ``torch.optim.LBFGS``).
        tolerance_change: the step ends without moving when the directional derivative
            is above ``-tolerance_change`` (a stationary point).

    ``step(closure)`` calls ``closure()`` first at the current parameters (its loss is
    the one returned, as for torch's optimisers), then during the line search.
    """

    def __init__(self, params, lr: float = 1.0, history_size: int = 20, max_eval: int = 25,
                 tolerance_change: float = 1e-16):
        params = list(params)
        if not params:
            raise ValueError("LBFGS got an empty parameter list")
        if not all(isinstance(p, Tensor) for p in params):
            raise ValueError("LBFGS takes one parameter group: a list of tensors")
        self._params = params
        self.param_groups = [{"params": params, "lr": lr}]  # as torch's optimisers hold them
        self.history_size = history_size
        self.max_eval = max_eval
        self.tolerance_change = tolerance_change
        self._s: list[Tensor] = []
        self._y: list[Tensor] = []
        self._rho: list[Tensor] = []
        self._gamma: Tensor | None = None  # scale of the initial inverse Hessian, y.s / y.y
        self._pending: tuple[Tensor, Tensor] | None = None
        self._steps = 0

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Clear the gradients (as ``torch.optim.Optimizer.zero_grad``)."""
        for p in self._params:
            if set_to_none:
                p.grad = None
            elif p.grad is not None:
                p.grad.detach_()
                p.grad.zero_()

    def _flat_grad(self) -> Tensor:
        return torch.cat([(p.grad if p.grad is not None else torch.zeros_like(p)).reshape(-1) for p in self._params])

    def _set(self, x: Tensor) -> None:
        offset = 0
        for p in self._params:
            p.copy_(x[offset : offset + p.numel()].view_as(p))
            offset += p.numel()

    def _remember(self, s: Tensor, y: Tensor) -> None:
        ys = y.dot(s)
        ok = ys > 1e-10
        self._s.append(s)
        self._y.append(y)
        self._rho.append(torch.where(ok, ys.reciprocal(), torch.zeros_like(ys)))
        gamma = ys / y.dot(y)
        self._gamma = torch.where(ok, gamma, self._gamma if self._gamma is not None else torch.ones_like(ys))
        if len(self._s) > self.history_size:
            del self._s[0], self._y[0], self._rho[0]

    def _direction(self, g: Tensor) -> Tensor:
        """``-H g`` by the two-loop recursion, on tensors."""
        q = g.neg()
        alphas = [None] * len(self._s)
        for i in range(len(self._s) - 1, -1, -1):
            alphas[i] = self._s[i].dot(q) * self._rho[i]
            q.addcmul_(self._y[i], alphas[i], value=-1)
        if self._gamma is not None:
            q.mul_(self._gamma)
        for i in range(len(self._s)):
            beta = self._y[i].dot(q) * self._rho[i]
            q.addcmul_(self._s[i], alphas[i] - beta)
        return q

    def _iterate(self, closure: Callable[[], Tensor], loss: float, g: Tensor, max_ls: int,
                 tolerance_change: float, drop_on_host: bool = False) -> tuple[float, Tensor, Tensor, int] | None:
        """One iteration from the loss and gradient ``g`` at the current parameters: the
        direction, the strong Wolfe search (at most ``max_ls`` evaluations), the move.
        Returns the loss and gradient where the search ended, the step taken and the
        evaluations used; None when the direction does not descend (nothing moves).

        ``drop_on_host``: a pair without positive curvature is left out of the history
        after a host read of ``y . s``, as torch leaves it out, instead of taking a slot
        with ``rho = 0``; the iterates are then torch's where the history is full."""
        if self._pending is not None:
            s, y = self._pending
            self._pending = None
            if not drop_on_host or float(y.dot(s)) > 1e-10:
                self._remember(s, y)
        x = torch.cat([p.detach().reshape(-1) for p in self._params])
        d = self._direction(g)
        lr = self.param_groups[0]["lr"]
        if self._steps == 0:  # torch's first step, 1 / |g|_1 at most; a zero gradient takes lr
            g1 = float(g.abs().sum())
            t = min(1.0, 1.0 / g1) * lr if g1 > 0 else lr
        else:
            t = lr
        self._steps += 1
        gtd = g.dot(d)
        if gtd > -tolerance_change:
            return None

        # x + t d as torch's L-BFGS forms it (one fused multiply-add per entry), so that the
        # iterates are torch's to the last bit where the recursion's are
        def evaluate(x0: Tensor, step: float, direction: Tensor) -> tuple[float, Tensor]:
            self._set(torch.add(x0, direction, alpha=step))
            return float(closure()), self._flat_grad()

        loss_new, g_new, t, evals = _strong_wolfe(evaluate, x, t, d, loss, g, gtd, max_ls=max_ls)
        self._set(torch.add(x, d, alpha=t))
        self._pending = (t * d, g_new - g)
        return loss_new, g_new, t * d, evals

    @torch.no_grad()
    def step(self, closure: Callable[[], Tensor]) -> Tensor:
        """One iteration, from a fresh evaluation of ``closure`` (the loop refreshes the
        objective between steps); returns that first loss."""
        closure = torch.enable_grad()(closure)
        loss = closure()
        self._iterate(closure, float(loss), self._flat_grad(), self.max_eval - 1, self.tolerance_change)
        return loss

    @torch.no_grad()
    def run(self, closure: Callable[[], Tensor], max_iter: int, max_eval: int | None = None,
            tolerance_grad: float = 1e-7, tolerance_change: float = 1e-9) -> Tensor:
        """Up to ``max_iter`` iterations on one objective: what one ``step`` of
        ``torch.optim.LBFGS(max_iter=..., line_search_fn="strong_wolfe")`` does, with its
        defaults. Each iteration starts from the loss and gradient its predecessor's line
        search ended with; at most ``max_eval`` evaluations in all (default ``max_iter * 5
        // 4``); it stops early when no gradient entry exceeds ``tolerance_grad``, or the
        step or the change of the loss is within ``tolerance_change``. Returns the first
        loss. (``max_eval`` of the constructor bounds :meth:`step` only.)"""
        closure = torch.enable_grad()(closure)
        max_eval = max_iter * 5 // 4 if max_eval is None else max_eval
        first = closure()
        loss, evals = float(first), 1
        g = self._flat_grad()
        if g.abs().max() <= tolerance_grad:
            return first
        for n in range(1, max_iter + 1):
            out = self._iterate(closure, loss, g, max_eval - evals, tolerance_change, drop_on_host=True)
            if out is None:
                break
            previous = loss
            loss, g, step, used = out
            evals += used
            if n == max_iter or evals >= max_eval or g.abs().max() <= tolerance_grad:
                break
            if step.abs().max() <= tolerance_change or abs(loss - previous) < tolerance_change:
                break
        return first
