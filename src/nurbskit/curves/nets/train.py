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

import functools

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from ...errors import OptionError
from ..synthetic import Batch, curve_samples, make_torch_batch, mode_config
from .models import MIN_POINTS, build

STOP_WEIGHT = 0.1  # the paper's lambda: positions matter more than counts
DEFAULT_SIZE = 64  # network input in pixels (the paper's 128 costs 4x more per step on a CPU)
# Curve samples at most this many pixels apart when rendering training drawings: the
# reference render's (``synthetic.render`` of ``dense_samples``). At 0.5 px (until the ninth
# session) the strokes were a little fainter and lumpier, and the networks noticed: V's MSE
# on held-out drawings was 0.018 drawn at 0.5 px and 0.023 drawn at 0.25 px.
TRAIN_SPACING = 0.25
RENDER_SIZE = 128  # training drawings are drawn at the recipe's size, then area-averaged to the network's


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
    from scipy.optimize import linear_sum_assignment  # 0.3 s to import: only when matching

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


def loss_v(model, data, stop_weight: float = STOP_WEIGHT) -> tuple[Tensor, dict]:
    ink, unit, counts, _ = data
    steps = int(counts.max())
    pred, stops = model(ink, steps)
    n = counts[:, 0]
    valid = (torch.arange(steps) < n[:, None]).float()
    mse = _mse(pred, unit[:, 0, :steps], valid)
    ce = _stop_ce(stops, n - 1, valid)
    acc = (predicted_count(stops, MIN_POINTS) == n).float().mean()
    return mse + stop_weight * ce, {"mse": mse, "stop_ce": ce, "point_acc": acc}


def loss_m(model, data, stop_weight: float = STOP_WEIGHT) -> tuple[Tensor, dict]:
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
    return mse + stop_weight * ce, {"mse": mse, "stop_ce": ce, "curve_acc": acc}


def sketch_targets(points: Tensor, counts: Tensor, n: int, degree: int = 3) -> Tensor:
    """The curves at ``n`` evenly spaced parameters: ``points (..., P, 2)``, ``counts (...)`` -> ``(..., n, 2)``.

    Clamped uniform B-splines of ``counts`` control points (the generator's); a count of 0
    gives zeros.
    """
    table = _sketch_basis(points.shape[-2], n, degree).to(points)
    return torch.einsum("...sp,...pd->...sd", table[counts], points)


@functools.lru_cache(maxsize=None)
def _sketch_basis(p_max: int, n: int, degree: int) -> Tensor:
    """``(p_max + 1, n, p_max)`` float64: per count, the basis at ``n`` evenly spaced parameters, zero-padded."""
    from ...core.basis import basis_matrix
    from ...core.knots import clamped_uniform

    u = torch.linspace(0, 1, n, dtype=torch.float64)
    table = torch.zeros(p_max + 1, n, p_max, dtype=torch.float64)
    for c in range(degree + 1, p_max + 1):
        table[c, :, :c] = basis_matrix(clamped_uniform(c, degree, dtype=torch.float64), degree, c, u)
    return table


# The weight of the sketch's MSE (an MV with ``sketch > 0``; not in the paper): as the control points'.
SKETCH_WEIGHT = 1.0


def loss_mv(model, data, stop_weight: float = STOP_WEIGHT) -> tuple[Tensor, dict]:
    ink, unit, counts, n_curves = data
    k, p = int(n_curves.max()), int(counts.max())
    tokens, codes, curve_stops = model.curve_codes(ink, k)
    pred, point_stops = model.decode_points(tokens, codes, p)  # (B, k, p, 2), (B, k, p, 2); stops (B, k, 2)
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
    loss = mse + stop_weight * (ce_pt + ce_cv)
    logs = {"mse": mse, "point_ce": ce_pt, "curve_ce": ce_cv, "curve_acc": right_curves.float().mean(),
            "point_acc": (right_points * valid_curve).sum() / valid_curve.sum()}
    sketch = model.sketch_points(codes)
    if sketch is not None:
        logs["sketch_mse"] = _mse(sketch, sketch_targets(matched, mcnt, sketch.shape[-2]),
                                  valid_curve[..., None].expand(sketch.shape[:-1]))
        loss = loss + SKETCH_WEIGHT * logs["sketch_mse"]
    return loss, logs


LOSSES = {"V": loss_v, "M": loss_m, "MV": loss_mv}


def batch_maker(mode: str, size: int = DEFAULT_SIZE):
    """``(generator, batch_size) -> (ink, unit points, counts, n_curves)``: the training loop's ``make_batch``.

    The drawings are the recipe's, 128 px with 2 px strokes, area-averaged to the
    network's ``size`` (:func:`network_inputs`): what the benchmark and the ``network``
    method hand the network. (Until the ninth session they were drawn at ``size`` with
    strokes scaled alike, 1 px at 64, which the networks then never saw again: MV counted
    curves right 92.5 % on such drawings and 85.3 % on the recipe's.)
    """
    config = mode_config(mode, RENDER_SIZE)

    def make(generator: torch.Generator, batch_size: int):
        batch = make_torch_batch(generator, batch_size, config, spacing=TRAIN_SPACING)
        ink, unit = network_inputs(batch, size)
        return ink, unit, batch.counts, batch.n_curves

    return make


# Redrawn drawings (``--input redrawn``): stroke widths drawn per batch from this range
# (the benchmark's 1, 2 and 3 px), and the share of drawings seen as large ones are (over
# 128 px across, :func:`.predict.skeleton_points` thins the skeleton again in the training
# frame; here the true curves' dense samples stand for that skeleton).
REDRAWN_WIDTHS = (1.0, 3.0)
REDRAWN_LARGE_SHARE = 0.25


def redrawn_batch_maker(mode: str, size: int = DEFAULT_SIZE, large_share: float = REDRAWN_LARGE_SHARE):
    """``(generator, batch_size) -> (ink, unit points, counts, n_curves)``: drawings as the hybrid method reads them.

    The recipe's drawings (128 px, strokes 1 to 3 px) go the way a drawing goes through
    the hybrid method: the classical path's ink mask and skeleton
    (:func:`nurbskit.curves.classic.ink_mask`, ``skeletonize`` after ``_fill_slivers``),
    redrawn at the training width (:func:`.predict.redrawn_points`), then
    :func:`.predict.network_ink`. So the network that votes on the count and draws the
    curves of the hybrid method is trained on what it will read.
    """
    from skimage.morphology import skeletonize

    from ..classic import _fill_slivers, ink_mask
    from .predict import network_ink, redrawn_points, skeleton_points, thinned

    def make(generator: torch.Generator, batch_size: int):
        lo, hi = REDRAWN_WIDTHS
        width = lo + (hi - lo) * float(torch.rand((), generator=generator, dtype=torch.float64))
        large = (torch.rand(batch_size, generator=generator) < large_share).tolist()
        config = mode_config(mode, RENDER_SIZE, width=width)
        batch = make_torch_batch(generator, batch_size, config, spacing=TRAIN_SPACING)
        dense, owner = curve_samples(batch.points, batch.counts, config.degree, TRAIN_SPACING)
        owner = owner // batch.points.shape[1]
        points = []
        for b in range(batch_size):
            if large[b]:
                points.append(thinned(dense[owner == b].numpy()))
            else:
                ink, _ = ink_mask(batch.image[b].double().numpy())
                points.append(skeleton_points(skeletonize(_fill_slivers(ink))))
        ink = torch.cat([network_ink(g, size) for g in redrawn_points(points)])
        unit = batch.points / float(RENDER_SIZE)
        return ink, unit.float(), batch.counts, batch.n_curves

    return make


# ---------------------------------------------------------------------------------------
# nurbskit train curves


def register_train(subparsers) -> None:
    from ...cli._options import number_in
    from ...cli.train_command import add_training_options
    from ...learn import TrainConfig

    p = subparsers.add_parser(
        "curves", help="the DeepSpline curve networks (V, M, MV) on generated drawings",
        description="Train a curve network on synthetic drawings of cubic B-splines (DeepSpline, seed 002): "
                    "V one curve of 4-6 control points, M 1-3 curves of 5, MV 1-3 curves of 4-6.",
    )
    p.add_argument("--mode", choices=("V", "M", "MV"), required=True, help="which network")
    p.add_argument("--input", choices=("image", "redrawn"), default="image",
                   help="image: the drawings themselves (default); redrawn: the drawings' skeletons redrawn at "
                        "2 px, as the default hybrid method of `nurbskit curves` hands them to MV "
                        "(weights curves_<mode>_redrawn)")
    p.add_argument("--sketch", type=int, choices=range(0, 9), default=0, metavar="S",
                   help="MV only: each curve step also sketches its curve at S points, read by S attention heads "
                        "(0, the default: the paper's one attention)")
    p.add_argument("--size", type=int, choices=(32, 64, 128), default=DEFAULT_SIZE,
                   help=f"network input in pixels (default {DEFAULT_SIZE}; the paper's is 128)")
    p.add_argument("--stop-weight", type=number_in(0, 100, low_open=True), default=STOP_WEIGHT, metavar="W",
                   help=f"weight of the STOP cross-entropies against the control-point MSE (default {STOP_WEIGHT}, "
                        "the paper's)")
    add_training_options(p, TrainConfig(steps=3000, batch_size=32, lr=2e-3, checkpoint_every=200))
    p.set_defaults(run=run_train_curves)


def run_train_curves(args) -> int:
    from ...cli.train_command import run_training, training_config
    from ...learn import TrainConfig

    config = training_config(args, TrainConfig(steps=3000, batch_size=32, lr=2e-3, checkpoint_every=200))
    arch = {"sketch": args.sketch} if args.sketch else {}
    if args.sketch and args.mode != "MV":
        raise OptionError(f"--sketch: an option of MV, not of {args.mode}")
    redrawn = args.input == "redrawn"
    meta = {"name": f"curves_{args.mode.lower()}" + ("_redrawn" if redrawn else ""), "mode": args.mode,
            "input": args.input, "size": args.size, "arch": arch,
            "units": "control points in the unit square (x / W, y / H)", "stop_weight": args.stop_weight}
    make = (redrawn_batch_maker if redrawn else batch_maker)(args.mode, args.size)
    loss = functools.partial(LOSSES[args.mode], stop_weight=args.stop_weight)
    run_training(args, lambda: build(args.mode, arch), make, loss, config, meta)
    return 0
