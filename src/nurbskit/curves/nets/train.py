"""Training the curve networks: batches, Hungarian matching, the paper's loss, ``nurbskit train curves``.

Loss (paper eq. 1-2, 9-10, 15-17): the mean squared error of the control points in the
unit square (over the coordinates of the targets' points) plus ``0.1`` times the mean
cross-entropy of every stop decision (points for V and MV, curves for M and MV). For M
and MV the predicted curves are first matched to the unordered true curves by the
Hungarian algorithm (``scipy.optimize.linear_sum_assignment``) on the mean squared
distance between their control points (paper eq. 5-8); for MV every predicted curve is
decoded for the batch's largest number of points and the cost with a true curve reads
that curve's points only.

Every model trains through :func:`nurbskit.learn.train` (``nurbskit train curves``).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment
from torch import Tensor
from torch.nn import functional as F

from ..synthetic import Batch, make_torch_batch, mode_config
from .models import MIN_POINTS, build

STOP_WEIGHT = 0.1  # the paper's lambda: positions matter more than counts
DEFAULT_SIZE = 64  # network input in pixels (the paper's 128 costs 4x more per step on a CPU)
TRAIN_SPACING = 0.5  # curve samples per pixel when rendering training images (0.25: the reference render)


def network_inputs(batch: Batch, size: int) -> tuple[Tensor, Tensor]:
    """A synthetic batch -> ink ``(B, 1, S, S)`` float32 and control points in the unit square ``(B, K, P, 2)``."""
    h, w = batch.image.shape[1:]
    ink = (1.0 - batch.image)[:, None]
    if (h, w) != (size, size):
        ink = F.interpolate(ink, size=(size, size), mode="area")
    unit = batch.points / torch.tensor([w, h], dtype=batch.points.dtype)
    return ink.float(), unit.float()


def hungarian(cost: Tensor, n: Tensor) -> Tensor:
    """The best matching of predictions to targets per example.

    ``cost (B, K, K)`` (prediction i, target j), ``n (B,)`` the true counts -> ``perm (B, K)``
    long with ``perm[b, i]`` the target matched to prediction ``i < n[b]`` (identity
    beyond), minimising ``sum_i cost[b, i, perm[b, i]]``.
    """
    c = cost.detach().cpu().numpy()
    perm = np.tile(np.arange(cost.shape[1]), (cost.shape[0], 1))
    for b, k in enumerate(n.tolist()):
        rows, cols = linear_sum_assignment(c[b, :k, :k])
        perm[b, rows] = cols
    return torch.as_tensor(perm, dtype=torch.long, device=cost.device)


def _stop_ce(logits: Tensor, last: Tensor, valid: Tensor) -> Tensor:
    """Mean cross-entropy of stop logits ``(..., T, 2)`` against STOP at step ``last (...)``, over ``valid (..., T)``."""
    t = torch.arange(logits.shape[-2], device=logits.device)
    target = (t == last[..., None]).long()
    ce = F.cross_entropy(logits.reshape(-1, 2), target.reshape(-1), reduction="none").view(target.shape)
    return (ce * valid).sum() / valid.sum().clamp(min=1)


def _mse(pred: Tensor, target: Tensor, valid: Tensor) -> Tensor:
    """Mean over the valid points' coordinates: ``pred, target (..., 2)``, ``valid (...)``."""
    return (((pred - target) ** 2).sum(-1) * valid).sum() / (2 * valid.sum().clamp(min=1))


def predicted_count(stop_logits: Tensor, minimum: int = 1) -> Tensor:
    """The number of steps to keep: the first step (from ``minimum``) whose STOP probability exceeds 1/2.

    ``stop_logits (..., T, 2)`` -> ``(...)`` long in ``[minimum, T]`` (``T`` when none stops).
    """
    stop = stop_logits.softmax(-1)[..., 1] > 0.5
    stop[..., : minimum - 1] = False
    stop[..., -1] = True
    return stop.float().argmax(-1) + 1


def loss_v(model, data) -> tuple[Tensor, dict]:
    ink, unit, counts, _ = data
    steps = int(counts.max())
    pred, stops = model(ink, steps)
    n = counts[:, 0]
    valid = (torch.arange(steps) < n[:, None]).float()
    mse = _mse(pred, unit[:, 0, :steps], valid)
    ce = _stop_ce(stops, n - 1, valid)
    acc = (predicted_count(stops, MIN_POINTS) == n).float().mean()
    return mse + STOP_WEIGHT * ce, {"mse": mse, "stop_ce": ce, "point_acc": acc}


def loss_m(model, data) -> tuple[Tensor, dict]:
    ink, unit, counts, n_curves = data
    k = int(n_curves.max())
    pred, stops = model(ink, k)  # (B, k, P, 2)
    target = unit[:, :k]
    cost = ((pred[:, :, None] - target[:, None]) ** 2).sum(-1).mean(-1)  # (B, k, k)
    perm = hungarian(cost, n_curves)
    matched = target.gather(1, perm[..., None, None].expand_as(target))
    valid_curve = (torch.arange(k) < n_curves[:, None]).float()
    mse = _mse(pred, matched, valid_curve[..., None].expand(pred.shape[:-1]))
    ce = _stop_ce(stops, n_curves - 1, valid_curve)
    acc = (predicted_count(stops) == n_curves).float().mean()
    return mse + STOP_WEIGHT * ce, {"mse": mse, "stop_ce": ce, "curve_acc": acc}


def loss_mv(model, data) -> tuple[Tensor, dict]:
    ink, unit, counts, n_curves = data
    k, p = int(n_curves.max()), int(counts.max())
    pred, point_stops, curve_stops = model(ink, k, p)  # (B, k, p, 2), (B, k, p, 2), (B, k, 2)
    target, cnt = unit[:, :k, :p], counts[:, :k]
    tmask = (torch.arange(p) < cnt[..., None]).float()  # (B, k, p) target points
    d = ((pred[:, :, None] - target[:, None]) ** 2).sum(-1)  # (B, i, j, p)
    cost = (d * tmask[:, None]).sum(-1) / tmask.sum(-1).clamp(min=1)[:, None]
    perm = hungarian(cost, n_curves)
    matched = target.gather(1, perm[..., None, None].expand_as(target))
    mcnt = cnt.gather(1, perm)
    valid_curve = (torch.arange(k) < n_curves[:, None]).float()
    valid_pt = (torch.arange(p) < mcnt[..., None]).float() * valid_curve[..., None]
    mse = _mse(pred, matched, valid_pt)
    ce_pt = _stop_ce(point_stops, mcnt - 1, valid_pt)
    ce_cv = _stop_ce(curve_stops, n_curves - 1, valid_curve)
    right_curves = predicted_count(curve_stops) == n_curves
    right_points = (predicted_count(point_stops, MIN_POINTS) == mcnt).float()
    return mse + STOP_WEIGHT * (ce_pt + ce_cv), {
        "mse": mse, "point_ce": ce_pt, "curve_ce": ce_cv, "curve_acc": right_curves.float().mean(),
        "point_acc": (right_points * valid_curve).sum() / valid_curve.sum()}


LOSSES = {"V": loss_v, "M": loss_m, "MV": loss_mv}


def batch_maker(mode: str, size: int = DEFAULT_SIZE):
    """``(generator, batch_size) -> (ink, unit points, counts, n_curves)``: the training loop's ``make_batch``."""
    config = mode_config(mode, size)

    def make(generator: torch.Generator, batch_size: int):
        batch = make_torch_batch(generator, batch_size, config, spacing=TRAIN_SPACING)
        ink, unit = network_inputs(batch, size)
        return ink, unit, batch.counts, batch.n_curves

    return make


# ---------------------------------------------------------------------------------------
# nurbskit train curves


def register_train(subparsers) -> None:
    from ...cli.train_command import add_training_options
    from ...learn import TrainConfig

    p = subparsers.add_parser(
        "curves", help="the DeepSpline curve networks (V, M, MV) on generated drawings",
        description="Train a curve network on synthetic drawings of cubic B-splines (DeepSpline, seed 002): "
                    "V one curve of 4-6 control points, M 1-3 curves of 5, MV 1-3 curves of 4-6.",
    )
    p.add_argument("--mode", choices=("V", "M", "MV"), required=True, help="which network")
    p.add_argument("--size", type=int, choices=(32, 64, 128), default=DEFAULT_SIZE,
                   help=f"network input in pixels (default {DEFAULT_SIZE}; the paper's is 128)")
    add_training_options(p, TrainConfig(steps=3000, batch_size=32, lr=2e-3, checkpoint_every=200))
    p.set_defaults(run=run_train_curves)


def run_train_curves(args) -> int:
    from ...cli.train_command import run_training, training_config
    from ...learn import TrainConfig

    config = training_config(args, TrainConfig(steps=3000, batch_size=32, lr=2e-3, checkpoint_every=200))
    arch = {}
    meta = {"name": f"curves_{args.mode.lower()}", "mode": args.mode, "size": args.size, "arch": arch,
            "units": "control points in the unit square (x / W, y / H)"}
    run_training(args, lambda: build(args.mode, arch), batch_maker(args.mode, args.size), LOSSES[args.mode],
                 config, meta)
    return 0
