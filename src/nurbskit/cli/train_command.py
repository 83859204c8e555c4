"""``nurbskit train MODEL``: train one of nurbskit's networks on data it generates.

Every model trains through the one loop of :func:`nurbskit.learn.train`; a model's module
adds its sub-command here by listing itself in :data:`TRAINERS` and defining
``register_train(subparsers)``, which builds its parser with :func:`add_training_options`
and runs with :func:`run_training`.

Writes to ``--out`` (resumable with ``--resume``): ``checkpoint.pt``, ``weights.pt``,
``history.json``, ``training.png``. Copy ``weights.pt`` to
``src/nurbskit/learn/weights/<name>.pt`` to ship it (``docs/learned.md``).

Examples::

    nurbskit train curves --mode V --steps 4000 --out runs/curves_v
    nurbskit train curves --mode V --steps 6000 --out runs/curves_v --resume
"""

from __future__ import annotations

import importlib
import shlex
import sys
from pathlib import Path

from ..learn.trainer import MAX_STEPS  # registering the trainers below loads torch anyway
from .._fs import file_id
from ._options import int_in, number_in, resume_hint

# Modules that add a ``nurbskit train <model>`` sub-command (``register_train(subparsers)``).
TRAINERS: tuple[str, ...] = (
    "nurbskit.curves.nets.train",
    "nurbskit.shapes.nets.training",
)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "train", help="train one of nurbskit's networks on generated data",
        description="Train a network on data nurbskit generates (deterministic by --seed); "
                    "checkpoints, weights, history and a training-curve figure go to --out.",
    )
    models = p.add_subparsers(dest="model", metavar="MODEL")
    for name in TRAINERS:
        importlib.import_module(name).register_train(models)
    p.set_defaults(run=_no_model)


def _no_model(args) -> int:
    from ..errors import OptionError

    raise OptionError("train: name the model to train (nurbskit train --help lists them)")


def add_training_options(parser, defaults) -> None:
    """The options every ``nurbskit train`` sub-command shares; ``defaults`` a TrainConfig."""
    parser.add_argument("--out", required=True, metavar="DIR", help="run folder (checkpoints, weights, figures)")
    parser.add_argument("--steps", type=int_in(1, MAX_STEPS), default=defaults.steps, metavar="N",
                        help=f"optimiser steps (default {defaults.steps})")
    parser.add_argument("--batch-size", type=int_in(1, 4096), default=defaults.batch_size, metavar="B",
                        help=f"examples per step (default {defaults.batch_size})")
    parser.add_argument("--lr", type=number_in(0, 1, low_open=True), default=defaults.lr,
                        help=f"peak learning rate (AdamW, cosine decay; default {defaults.lr})")
    parser.add_argument("--seed", type=int_in(0), default=defaults.seed,
                        help=f"seed of the generated data and of the initial weights (default {defaults.seed})")
    parser.add_argument("--checkpoint-every", type=int_in(1), default=defaults.checkpoint_every, metavar="N",
                        help=f"steps between checkpoints (default {defaults.checkpoint_every})")
    parser.add_argument("--threads", type=int_in(1, 256), default=None, metavar="T",
                        help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--init", default=None, metavar="WEIGHTS",
                        help="start from these weights (a shipped name such as curves_mv, or a weights.pt "
                             "file of the same network) instead of random ones: a fine-tuning run")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run's files in --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def training_config(args, defaults):
    """A TrainConfig from the shared options (fields not on the command line keep ``defaults``)."""
    from dataclasses import replace

    return replace(defaults, steps=args.steps, batch_size=args.batch_size, lr=args.lr, seed=args.seed,
                   checkpoint_every=args.checkpoint_every)


def run_training(args, build_model, make_batch, loss_fn, config, meta: dict, validate=None):
    """Build the model (initial weights drawn from ``--seed``) and train it with a progress bar.

    ``build_model()`` returns the network; the rest as :func:`nurbskit.learn.train`.
    Prints one summary line; returns the :class:`~nurbskit.learn.TrainRun`. On Ctrl-C or
    SIGTERM says in one line what ``--out`` now holds and how to resume, then exits 130 / 143.
    """
    import torch

    from ..learn import train
    from ..learn.trainer import check_run_folder, load_checkpoint

    # Refused before any work or progress bar (train() checks again as it starts).
    check_run_folder(args.out, resume=args.resume, overwrite=args.overwrite)
    if args.threads:
        torch.set_num_threads(args.threads)
    meta = dict(meta, command="nurbskit " + " ".join(shlex.quote(a) for a in sys.argv[1:] if a != "--quiet"),
                torch=str(torch.__version__))  # TorchVersion is not plain data: weights_only loads refuse it
    with torch.random.fork_rng(devices=[]):  # the initial weights follow --seed; the global RNG is untouched
        torch.manual_seed(config.seed)
        model = build_model()
    if getattr(args, "init", None):  # on --resume the checkpoint's weights replace these; the record stays
        meta["init"] = _load_initial_weights(model, args.init, meta)
    if args.resume:  # a checkpoint of another network or other settings: refused before the bar
        load_checkpoint(args.out, model, config, meta)
    _check_step_memory(build_model, make_batch, loss_fn, config.batch_size)
    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=config.steps, desc=f"train {meta.get('name', '')}", unit="step", file=sys.stderr,
                   leave=False)

    def progress(step, steps, values):
        if bar is not None:
            bar.n = step
            bar.set_postfix_str(f"loss={values['loss']:.3e}", refresh=False)
            bar.update(0)

    out = Path(args.out)
    existed, before = out.exists(), file_id(out / "checkpoint.pt")
    try:
        run = train(model, make_batch, loss_fn, config, args.out, meta=meta, resume=args.resume,
                    overwrite=args.overwrite, progress=progress, validate=validate)
    except KeyboardInterrupt as exc:  # SIGTERM too (cli.Terminated): say what the folder now holds
        if bar is not None:
            bar.close()
            bar = None
        from . import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated

        terminated = isinstance(exc, Terminated)
        what = "terminated" if terminated else "interrupted"
        print(f"nurbskit train: {what}; {_left_behind(out, existed, before, config.steps)}", file=sys.stderr)
        raise SystemExit(EXIT_TERMINATED if terminated else EXIT_INTERRUPTED) from None
    finally:
        if bar is not None:
            bar.close()
    last = run.history[-1] if run.history else {}
    shown = ", ".join(f"{k} {v:.4g}" for k, v in last.items() if k not in ("step", "seconds", "lr"))
    print(f"{meta.get('name', 'model')}: {run.step} steps in {run.seconds:.1f} s; {shown}")
    print(f"wrote {Path(args.out)}/: checkpoint.pt, weights.pt, history.json, training.png")
    return run


def _saved_step(out: Path):
    """The step the run's files in ``out`` hold (history.json, written with the checkpoint), or None."""
    import json

    try:
        return int(json.loads((out / "history.json").read_text(encoding="utf-8"))["meta"]["steps"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _left_behind(out: Path, existed: bool, before, steps: int) -> str:
    """One truthful clause on what an interrupted ``train`` left in ``out``."""
    step = _saved_step(out)
    at = f"step {step} of {steps}" if step is not None else "its last step"
    if file_id(out / "checkpoint.pt") not in (None, before):
        return (f"kept the run at {at} in {out}/ (checkpoint.pt, weights.pt, history.json; training.png is "
                f"drawn at the end); {resume_hint('train')}")
    if before is not None:
        return f"{out}/ holds its files as they were (a run at {at}); nothing new was written"
    if existed:
        return f"{out}/ holds what it held before; nothing was written"
    return "no output was left behind"


def _check_step_memory(build_model, make_batch, loss_fn, batch_size: int) -> None:
    """Refuse, before the first step, a ``--batch-size`` whose steps cannot fit in memory
    (:func:`nurbskit.learn.trainer.step_memory`, half of its sum planned)."""
    from .._budget import available_bytes, require_memory
    from ..learn.trainer import step_memory

    fixed, per = step_memory(build_model, make_batch, loss_fn)
    fixed, per = fixed / 2, per / 2
    budget = available_bytes()
    fits = int((budget - fixed) // per) if per > 0 else batch_size
    require_memory(fixed + per * batch_size, f"--batch-size {batch_size} ({per / 2**20:.1f} MB an example)",
                   f"--batch-size {max(fits, 0)} fits" if fits >= 1 else "no batch fits", budget=budget)


def _load_initial_weights(model, name_or_path: str, run: dict | None = None) -> dict:
    """Load ``--init`` weights into ``model``; returns what the new weights record of them
    (the command, steps and seconds that made them: a fine-tuned model's full recipe).
    ``run``: this run's record (its ``name`` and ``arch`` name the network it trains)."""
    from ..errors import InputError, OptionError
    from ..learn import load_weights

    try:
        state, meta = load_weights(name_or_path)
    except InputError as exc:
        raise OptionError(f"--init {exc}") from None
    try:
        model.load_state_dict(state)
    except RuntimeError:
        def named(record: dict, default: str) -> str:
            arch = record.get("arch")
            return record.get("name", default) + (f" ({arch})" if arch else "")

        raise OptionError(f"--init {name_or_path}: its weights are those of {named(meta, 'an unnamed network')}, "
                          f"not of {named(run or {}, 'this network')}") from None
    return {"weights": str(name_or_path), **{k: meta[k] for k in ("name", "command", "steps", "seconds", "init")
                                             if k in meta}}
