"""Training the learned path: the Chamfer loss without ground truth, and ``nurbskit train revolve``.

DeepSpline, section 5.1, eq. 20: the loss is the Chamfer distance between the input cloud
and points of the surface generated from the predicted profile
(:func:`nurbskit.losses.chamfer_distance`, squared nearest distances, each direction
averaged). The generating profile is never shown to the network. Batches come from
:func:`.data.make_batch`; the loop is :func:`nurbskit.learn.train`.
"""

from __future__ import annotations

from functools import partial

import torch

from ...learn import TrainConfig
from ...losses import chamfer_distance
from .data import make_batch
from .models import build_model

__all__ = ["DEFAULTS", "N_POINTS", "model_name", "loss_fn", "batch_fn", "validation", "register_train"]

DEFAULTS = TrainConfig(steps=3000, batch_size=16, lr=1e-3, log_every=50, checkpoint_every=250)
N_POINTS = 512  # points per training cloud (the max pool makes the count free at inference)
VAL_SEED = 999_331  # the validation batch's seed: never a training step's (seeds there are < 2**31 steps apart)


def model_name(kind: str, input: str) -> str:
    """``shapes_<kind>_<input>``: the shipped weights' name (``src/nurbskit/learn/weights``)."""
    return f"shapes_{kind}_{input}"


def batch_fn(kind: str, input: str, n_points: int = N_POINTS):
    """``(generator, batch_size) -> batch`` for :func:`nurbskit.learn.train`."""
    return partial(_batch, kind=kind, images=input == "image", n_points=n_points)


def _batch(g, batch_size, *, kind, images, n_points):
    return make_batch(g, batch_size, kind, n_points, images=images)


def loss_fn(model, batch):
    """Chamfer between the input clouds and the generated surfaces; parts: both directions."""
    x = batch["images"] if model.input == "image" else batch["points"]
    surf = model.surface_points(model(x))
    total, to_surface, coverage = chamfer_distance(batch["points"], surf, return_parts=True)
    return total.mean(), {"to_surface": to_surface.mean(), "coverage": coverage.mean()}


def validation(kind: str, input: str, count: int = 32):
    """A fixed held-out batch; returns ``model -> {"val_chamfer", "val_to_surface_rms"}``."""
    from ...learn import batch_generator

    batch = batch_fn(kind, input)(batch_generator(VAL_SEED, 0), count)

    def validate(model):
        _, parts = loss_fn(model, batch)
        total = parts["to_surface"] + parts["coverage"]
        return {"val_chamfer": float(total), "val_to_surface_rms": float(parts["to_surface"].sqrt())}

    return validate


def register_train(subparsers) -> None:
    from ...cli.train_command import add_training_options

    p = subparsers.add_parser(
        "revolve", help="surfaces of revolution / extrusion from clouds or silhouettes (DeepSpline 3-D)",
        description="Train the learned path of issue 11: a PointNet (--input points) or a small CNN "
                    "(--input image, revolutions only) predicting a profile's control points, the "
                    "surface made by a fixed linear layer, trained by Chamfer against the input "
                    "(no ground truth) on random profiles generated on the fly.",
    )
    p.add_argument("--input", choices=("points", "image"), default="points", help="what the network sees")
    p.add_argument("--kind", choices=("revolution", "extrusion"), default="revolution", help="surface kind")
    add_training_options(p, DEFAULTS)
    p.set_defaults(run=_run)


def _run(args) -> int:
    from ...cli.train_command import run_training, training_config
    from ...errors import OptionError

    if args.input == "image" and args.kind != "revolution":
        raise OptionError("--input image: silhouettes are made for --kind revolution only")
    config = training_config(args, DEFAULTS)
    meta = {"name": model_name(args.kind, args.input), "kind": args.kind, "input": args.input,
            "arch": {"kind": args.kind, "input": args.input}, "n_points": N_POINTS}
    run_training(args, lambda: build_model(args.kind, args.input), batch_fn(args.kind, args.input), loss_fn,
                 config, meta, validate=validation(args.kind, args.input))
    return 0
