"""One-to-one matching of two point sets (the thesis's UM pipeline).

The UM pipeline (thesis section 5.1.4) aligns the surface samples with the input by
Chamfer distance, then gives every surface sample its own input point so that the
total distance is smallest, and continues with the L2 loss on those pairs. The
assignment is the linear sum assignment problem, solved exactly by
``scipy.optimize.linear_sum_assignment`` (a shortest augmenting path method).
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from ..errors import NurbskitError

Tensor = torch.Tensor


def one_to_one_matching(pred: Tensor, target: Tensor, squared: bool = True) -> Tensor:
    """Index of the input point assigned to each predicted point (no gradient).

    Shapes: ``pred (M, D)``, ``target (N, D)`` with ``M <= N`` -> ``index (M,)`` int64,
    all distinct, minimising ``sum_m cost(pred[m], target[index[m]])`` where the cost is
    the squared (default) or plain Euclidean distance.

    Example:
        >>> import torch
        >>> one_to_one_matching(torch.tensor([[0.0], [1.0]]), torch.tensor([[1.1], [0.1], [5.0]])).tolist()
        [1, 0]
    """
    from scipy.optimize import linear_sum_assignment

    if pred.ndim != 2 or target.ndim != 2 or pred.shape[-1] != target.shape[-1]:
        raise NurbskitError(f"matching needs (M, D) and (N, D) point sets, got {tuple(pred.shape)} and {tuple(target.shape)}")
    if pred.shape[0] > target.shape[0]:
        raise NurbskitError(
            f"one-to-one matching needs at least as many input points ({target.shape[0]}) as surface samples ({pred.shape[0]})"
        )
    a = pred.detach().cpu().double().numpy()
    b = target.detach().cpu().double().numpy()
    cost = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    if not squared:
        cost = np.sqrt(cost)
    rows, cols = linear_sum_assignment(cost)
    index = np.empty(a.shape[0], dtype=np.int64)
    index[rows] = cols
    return torch.as_tensor(index, device=pred.device)


def one_to_one_matching_naive(pred: Tensor, target: Tensor, squared: bool = True) -> Tensor:
    """Brute-force oracle for :func:`one_to_one_matching` (tries every injection; tiny inputs only)."""
    a = pred.detach().double()
    b = target.detach().double()
    cost = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    if not squared:
        cost = cost.sqrt()
    best, best_perm = None, None
    for perm in itertools.permutations(range(b.shape[0]), a.shape[0]):
        total = float(sum(cost[i, j] for i, j in enumerate(perm)))
        if best is None or total < best - 1e-12:
            best, best_perm = total, perm
    return torch.tensor(best_perm, dtype=torch.int64)


def matching_cost(pred: Tensor, target: Tensor, index: Tensor, squared: bool = True) -> float:
    """Total cost of a matching (squared distances by default)."""
    d = (pred.detach().double() - target.detach().double()[index]).square().sum(-1)
    return float(d.sum() if squared else d.sqrt().sum())
