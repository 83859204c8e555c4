"""One training loop for every network nurbskit ships (issues 10 and 11).

Convention:
    * Data is generated, never read: ``make_batch(generator, batch_size)`` draws a batch
      from a ``torch.Generator`` seeded by :func:`batch_generator` ``(seed, step)``. A
      resumed run therefore sees the very batches an uninterrupted one would have seen.
    * ``loss_fn(model, batch) -> (loss, parts)``: ``loss`` a scalar tensor to minimise,
      ``parts`` named scalar tensors to log (the loss's terms, accuracies).
    * A run folder holds ``checkpoint.pt`` (model, optimiser, step, history: what
      ``resume=True`` continues from), ``weights.pt`` (the model alone, with its facts:
      see :mod:`nurbskit.learn.weights`), ``history.json`` and ``training.png``. Every
      file is written atomically and listed in the folder's ``.nurbskit-manifest.json``,
      so ``--overwrite`` replaces a previous run's files and nothing else.
    * AdamW with a cosine learning-rate decay to ``lr * lr_final`` over ``steps`` and
      gradient-norm clipping; Ctrl-C writes a checkpoint, then stops.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import torch
from torch import Tensor, nn

from .._fs import MANIFEST, atomic_open, atomic_path, check_output_dir, read_manifest, write_manifest
from ..errors import InputError, OptionError
from .weights import save_weights

FILES = ("checkpoint.pt", "weights.pt", "history.json", "training.png")


@dataclass
class TrainConfig:
    """How to train: steps, batch size, learning rate and its decay, the data seed."""

    steps: int = 2000
    batch_size: int = 32
    lr: float = 1e-3
    lr_final: float = 0.05  # the learning rate ends at lr * lr_final (cosine decay)
    weight_decay: float = 1e-4
    grad_clip: float = 1.0
    seed: int = 0
    log_every: int = 20  # history records average the parts over this many steps
    checkpoint_every: int = 250

    def __post_init__(self):
        for name in ("steps", "batch_size", "log_every", "checkpoint_every"):
            if int(getattr(self, name)) < 1:
                raise OptionError(f"{name} must be a positive integer, got {getattr(self, name)}")
        if not self.lr > 0:
            raise OptionError(f"lr must be positive, got {self.lr}")


@dataclass
class TrainRun:
    """What :func:`train` returns: the trained model and its record."""

    model: nn.Module
    history: list[dict] = field(default_factory=list)
    step: int = 0
    seconds: float = 0.0
    out: Path | None = None


def batch_generator(seed: int, step: int, device="cpu") -> torch.Generator:
    """The generator that draws the batch of ``step`` in a run seeded ``seed`` (deterministic)."""
    g = torch.Generator(device=device)
    g.manual_seed((int(seed) * 1_000_003 + int(step)) % (2**63 - 1))
    return g


def _lr_at(config: TrainConfig, step: int) -> float:
    t = min(step / max(config.steps, 1), 1.0)
    return config.lr * (config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * t)))


def _prepare(out: Path, resume: bool, overwrite: bool) -> dict | None:
    """Check the run folder; returns the checkpoint to resume from (or None)."""
    if resume:
        ckpt = out / "checkpoint.pt"
        if not ckpt.exists():
            raise OptionError(f"--out {out}: no checkpoint.pt to resume from; start without --resume")
        try:
            return torch.load(ckpt, map_location="cpu", weights_only=True)
        except Exception as exc:  # noqa: BLE001 - an unreadable checkpoint is a user's file problem
            raise InputError(f"{ckpt}: not a nurbskit checkpoint ({type(exc).__name__}: {exc})") from None
    check_output_dir(out, overwrite)
    if out.is_dir():
        for name in read_manifest(out.resolve()) or {}:  # only what an earlier run wrote
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
        with contextlib.suppress(FileNotFoundError):
            (out / MANIFEST).unlink()
    out.mkdir(parents=True, exist_ok=True)
    return None


def _write_manifest(out: Path) -> None:
    write_manifest(out, {name: (out / name).stat().st_size for name in FILES if (out / name).exists()})


def _save_run(out: Path, model: nn.Module, optimizer, run: TrainRun, config: TrainConfig, meta: dict,
              figure: bool = True) -> None:
    state = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "step": run.step,
        "seconds": run.seconds,
        "history": json.dumps(run.history),
        "config": json.dumps(asdict(config)),
    }
    with atomic_path(out / "checkpoint.pt") as tmp:
        torch.save(state, tmp)
    facts = dict(meta, steps=run.step, seconds=round(run.seconds, 1), config=asdict(config))
    save_weights(out / "weights.pt", model.state_dict(), facts)
    with atomic_open(out / "history.json", "w", encoding="utf-8") as handle:
        json.dump({"meta": facts, "history": run.history}, handle, indent=1)
    if figure and run.history:
        from ..viz.plots import plot_training

        plot_training(run.history, out / "training.png", title=str(meta.get("name", "training")))
    _write_manifest(out)


def train(
    model: nn.Module,
    make_batch: Callable[[torch.Generator, int], Any],
    loss_fn: Callable[[nn.Module, Any], tuple[Tensor, dict[str, Tensor]]],
    config: TrainConfig,
    out: str | os.PathLike | None = None,
    *,
    meta: dict | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: Callable[[int, int, dict], None] | None = None,
    validate: Callable[[nn.Module], dict[str, float]] | None = None,
) -> TrainRun:
    """Train ``model`` for ``config.steps`` steps on generated batches.

    Args:
        model: the network (its parameters are updated in place).
        make_batch: ``(generator, batch_size) -> batch`` (see the module's convention).
        loss_fn: ``(model, batch) -> (loss, parts)``.
        config: steps, batch size, learning rate, seed.
        out: the run folder (checkpoints, weights, history, figure), or None to keep
            nothing on disk.
        meta: plain data stored in ``weights.pt`` (name, architecture, command).
        resume: continue from ``out/checkpoint.pt`` (the seed must match; ``steps``
            may grow).
        overwrite: replace an earlier run's files in ``out``.
        progress: called after every step with ``(step, steps, parts as floats)``.
        validate: called at every log with the model in eval mode; its numbers join
            the history record (name them ``val_...``).

    Returns:
        A :class:`TrainRun`; on Ctrl-C a checkpoint is written and KeyboardInterrupt
        propagates.
    """
    meta = dict(meta or {})
    out = None if out is None else Path(out)
    run = TrainRun(model=model, out=out)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    checkpoint = _prepare(out, resume, overwrite) if out is not None else None
    if checkpoint is not None:
        saved = json.loads(checkpoint["config"])
        if saved["seed"] != config.seed:
            raise OptionError(f"--seed {config.seed}: the run in {out} was started with seed {saved['seed']}")
        model.load_state_dict(checkpoint["model"])
        optimizer.load_state_dict(checkpoint["optimizer"])
        run.step, run.seconds = int(checkpoint["step"]), float(checkpoint["seconds"])
        run.history = json.loads(checkpoint["history"])
    sums: dict[str, float] = {}
    count = 0
    started = time.perf_counter() - run.seconds
    model.train()
    try:
        while run.step < config.steps:
            for group in optimizer.param_groups:
                group["lr"] = _lr_at(config, run.step)
            batch = make_batch(batch_generator(config.seed, run.step), config.batch_size)
            loss, parts = loss_fn(model, batch)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if config.grad_clip:
                nn.utils.clip_grad_norm_(model.parameters(), config.grad_clip)
            optimizer.step()
            run.step += 1
            values = {"loss": float(loss.detach())}  # one host read per step: the progress bar's
            values.update({k: float(v.detach()) for k, v in parts.items()})
            for k, v in values.items():
                sums[k] = sums.get(k, 0.0) + v
            count += 1
            run.seconds = time.perf_counter() - started
            if run.step % config.log_every == 0 or run.step == config.steps:
                record = {"step": run.step, "seconds": round(run.seconds, 2), "lr": _lr_at(config, run.step)}
                record.update({k: v / count for k, v in sums.items()})
                if validate is not None:
                    model.eval()
                    with torch.no_grad():
                        record.update(validate(model))
                    model.train()
                run.history.append(record)
                sums, count = {}, 0
            if progress is not None:
                progress(run.step, config.steps, values)
            if out is not None and (run.step % config.checkpoint_every == 0 or run.step == config.steps):
                _save_run(out, model, optimizer, run, config, meta, figure=run.step == config.steps)
    except KeyboardInterrupt:
        if out is not None and run.step > 0:
            _save_run(out, model, optimizer, run, config, meta, figure=False)
        raise
    model.eval()
    return run
