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
    * ``resume=True`` continues only a folder an earlier ``train`` wrote (its manifest lists
      ``checkpoint.pt``; nothing else in it), from a checkpoint of the same network and
      settings (:func:`load_checkpoint`); anything else is refused in one line.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import torch
from torch import Tensor, nn

from .._fs import atomic_open, atomic_path, check_output_dir, interrupts_held, read_manifest, write_manifest
from ..errors import InputError, OptionError
from .weights import save_weights

FILES = ("checkpoint.pt", "weights.pt", "history.json", "training.png")
MAX_STEPS = 10**9  # far beyond any run (the shipped ones take a few thousand); bigger is a typo


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
        if int(self.steps) > MAX_STEPS:
            raise OptionError(f"steps must be at most {MAX_STEPS}, got {self.steps}")
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


def check_run_folder(out: str | os.PathLike, *, resume: bool = False, overwrite: bool = False) -> Path:
    """Refuse a run folder before any work starts (one line naming ``--out``); returns it as a Path.

    Without ``resume`` the output-folder rules of :func:`nurbskit._fs.check_output_dir`.
    With ``resume`` the same rules, ``--overwrite`` implied for the run's own files: the
    folder must hold ``checkpoint.pt`` and nothing but what an earlier ``train`` wrote
    there (listed in its manifest, unchanged since), so a resumed run never writes over a
    file nurbskit did not write.
    """
    out = Path(out)
    if not resume:
        return check_output_dir(out, overwrite)
    if out.exists() and not out.is_dir():
        raise OptionError(f"--out {out}: expected a run folder to resume, found an existing file")
    if not (out / "checkpoint.pt").is_file():
        raise OptionError(f"--out {out}: no checkpoint.pt to resume from; start without --resume")
    check_output_dir(out, True)  # files nurbskit did not write refuse the run, as they do without --resume
    others = sorted(set(read_manifest(out.resolve()) or {}) - set(FILES))
    if others:
        raise OptionError(
            f"--out {out}: the folder holds outputs of another nurbskit command ({', '.join(others[:3])}); "
            "--resume continues only a folder that `nurbskit train` wrote"
        )
    return out


def _prepare(out: Path, resume: bool, overwrite: bool) -> list[str]:
    """Check the run folder and create it; returns the earlier run's files, removed at the first save."""
    check_run_folder(out, resume=resume, overwrite=overwrite)
    if resume:
        return []
    # An earlier run's files stay until this run saves (an interrupted start leaves them as they were).
    earlier = list(read_manifest(out.resolve()) or {}) if out.is_dir() else []
    out.mkdir(parents=True, exist_ok=True)
    return earlier


_KEYS = ("model", "optimizer", "step", "seconds", "history", "config")
# Facts of ``meta`` that say how a run was started, not what it trains: free to differ on resume.
_RUN_FACTS = frozenset({"command", "torch", "init", "steps", "seconds", "config"})
# Facts of ``meta`` that no option sets: a difference there means another kind of network.
_NOT_OPTIONS = frozenset({"name", "units"})
# Settings of TrainConfig that change the data a step sees: a resumed run must keep them.
_SAME_CONFIG = ("seed", "batch_size", "lr")  # a run is one recipe: --steps may only grow


def _held(value: Any) -> str:
    """A short description of what a file held, for messages."""
    if isinstance(value, dict):
        keys = ", ".join(str(k) for k in list(value)[:6]) + (", ..." if len(value) > 6 else "")
        return f"a dict of {keys}" if value else "an empty dict"
    if isinstance(value, Tensor):
        return f"a tensor of shape {tuple(value.shape)}"
    return f"a {type(value).__name__}"


def _json_field(ckpt: Path, data: dict, key: str, kind: type) -> Any:
    expected = "a JSON " + ("list" if kind is list else "object")
    text = data.get(key)
    if not isinstance(text, str):
        raise InputError(f"{ckpt}: not a nurbskit training checkpoint ({key} should be {expected} in a string, "
                         f"found {_held(text)})")
    try:
        value = json.loads(text)
    except ValueError:
        raise InputError(f"{ckpt}: not a nurbskit training checkpoint ({key} is not {expected})") from None
    if not isinstance(value, kind):
        raise InputError(f"{ckpt}: not a nurbskit training checkpoint ({key} should be {expected}, "
                         f"found {_held(value)})")
    return value


def read_checkpoint(path: str | os.PathLike) -> dict:
    """A training checkpoint, checked: ``{model, optimizer, step, seconds, history, config, meta}``
    with ``history`` a list, ``config`` and ``meta`` dicts (``meta`` None in checkpoints older
    than it). Raises InputError (one line naming the file) for anything else."""
    ckpt = Path(path)
    try:
        with warnings.catch_warnings():  # torch warns about some files it then loads or refuses
            warnings.simplefilter("ignore")
            data = torch.load(ckpt, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - an unreadable checkpoint is a user's file problem
        why = (str(exc).strip().splitlines() or [""])[0][:200]
        raise InputError(f"{ckpt}: not a nurbskit training checkpoint ({type(exc).__name__}: {why})") from None
    expected = "a nurbskit training checkpoint (a dict of " + ", ".join(_KEYS) + ")"
    if not isinstance(data, dict):
        raise InputError(f"{ckpt}: expected {expected}, found {_held(data)}")
    missing = [k for k in _KEYS if k not in data]
    if missing:
        raise InputError(f"{ckpt}: expected {expected}, found {_held(data)} (no {', '.join(missing)})")
    model = data["model"]
    if not isinstance(model, dict) or not all(isinstance(v, Tensor) for v in model.values()):
        raise InputError(f"{ckpt}: its model should be a dict of tensors (a state_dict), found {_held(model)}")
    if not isinstance(data["optimizer"], dict):
        raise InputError(f"{ckpt}: its optimizer should be a dict (a state_dict), found {_held(data['optimizer'])}")
    step, seconds = data["step"], data["seconds"]
    if isinstance(step, bool) or not isinstance(step, int) or step < 0:
        raise InputError(f"{ckpt}: its step should be a count of steps, found {step!r}"[:300])
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)):
        raise InputError(f"{ckpt}: its seconds should be a number, found {_held(seconds)}")
    out = {"model": model, "optimizer": data["optimizer"], "step": step, "seconds": float(seconds),
           "history": _json_field(ckpt, data, "history", list), "config": _json_field(ckpt, data, "config", dict),
           "meta": _json_field(ckpt, data, "meta", dict) if "meta" in data else None}
    for name in _SAME_CONFIG:
        if name not in out["config"]:
            raise InputError(f"{ckpt}: not a nurbskit training checkpoint (its config has no {name})")
    return out


def _option(key: str) -> str:
    return "--" + key.replace("_", "-")


def _said(value: Any) -> str:
    return " ".join(str(v) for v in value) if isinstance(value, list) else str(value)


def _check_same_run(ckpt: Path, saved: dict, model: nn.Module, config: TrainConfig, meta: dict) -> None:
    """Refuse resuming ``saved`` (from :func:`read_checkpoint`) with other settings or another network."""
    out = ckpt.parent
    have = saved["meta"]
    if have is None:  # a checkpoint older than its meta: weights.pt was written with it and has the same facts
        with contextlib.suppress(InputError):
            from .weights import load_weights

            have = load_weights(out / "weights.pt")[1]
    want = json.loads(json.dumps(meta))  # as it would read back (tuples -> lists)
    if isinstance(have, dict):
        have = {k: v for k, v in have.items() if k not in _RUN_FACTS}
        want = {k: v for k, v in want.items() if k not in _RUN_FACTS}
        what = f"a {have.get('name', 'unnamed')} run"
        if set(have) == set(want):  # the same kind of network: name the option that differs
            for key in sorted(set(want) - _NOT_OPTIONS, key=lambda k: (isinstance(want[k], dict), k)):
                new, old = want[key], have[key]
                pairs = ([(sub, new.get(sub), old.get(sub)) for sub in sorted(set(new) | set(old))]
                         if isinstance(new, dict) and isinstance(old, dict) else [(key, new, old)])
                for sub, a, b in pairs:
                    if a != b:
                        opt = _option(sub)
                        given = f"{opt} {_said(a)}" if a is not None else f"no {opt}"
                        started = f"with {opt} {_said(b)}" if b is not None else f"without {opt}"
                        raise OptionError(f"{given}: the run in {out} ({what}) was started {started}; resume it "
                                          "with the settings that started it, or choose another --out")
        if have != want:
            raise InputError(f"{ckpt}: not a {want.get('name', 'matching')} checkpoint (it holds {what}); "
                             "resume it with the command that started it, or choose another --out")
    for name in _SAME_CONFIG:
        new, old = getattr(config, name), saved["config"][name]
        if new != old:
            raise OptionError(f"{_option(name)} {new}: the run in {out} was started with {_option(name)} {old}; "
                              "resume it with the same value, or choose another --out")
    if config.steps < saved["step"]:
        raise OptionError(f"--steps {config.steps}: the run in {out} has already made {saved['step']} steps; "
                          f"pass --steps {saved['step']} or more")
    current = model.state_dict()
    theirs = saved["model"]
    differ = sorted(set(current) ^ set(theirs))
    if differ:
        name = differ[0]
        where = "here" if name in current else "there"
        raise InputError(f"{ckpt}: its network is not this one (parameter {name} exists only {where}); "
                         "resume it with the command that started it, or choose another --out")
    for name, value in current.items():
        if tuple(theirs[name].shape) != tuple(value.shape):
            raise InputError(f"{ckpt}: its network is not this one (parameter {name} has shape "
                             f"{tuple(theirs[name].shape)} there, {tuple(value.shape)} here); resume it with the "
                             "command that started it, or choose another --out")


def load_checkpoint(out: str | os.PathLike, model: nn.Module, config: TrainConfig, meta: dict | None = None) -> dict:
    """``out/checkpoint.pt`` read and checked against this run (:func:`read_checkpoint`): the
    network (its kind, options and parameter shapes), ``seed``, ``batch_size`` and ``lr`` must be the
    run's, ``steps`` at least its step. Raises OptionError naming the option that differs, or
    InputError naming the file; loads nothing into ``model``."""
    ckpt = Path(out) / "checkpoint.pt"
    saved = read_checkpoint(ckpt)
    _check_same_run(ckpt, saved, model, config, dict(meta or {}))
    return saved


def _write_manifest(out: Path) -> None:
    write_manifest(out, {name: (out / name).stat().st_size for name in FILES if (out / name).exists()})


def _save_run(out: Path, model: nn.Module, optimizer, run: TrainRun, config: TrainConfig, meta: dict,
              figure: bool = True, earlier: list[str] = ()) -> None:
    """Write the run's files and manifest; Ctrl-C and SIGTERM wait until all agree.

    ``earlier``: an earlier run's files (``--overwrite``) to remove once this run's are written.
    """
    state = {
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "step": run.step,
        "seconds": run.seconds,
        "history": json.dumps(run.history),
        "config": json.dumps(asdict(config)),
        "meta": json.dumps(meta),
    }
    facts = dict(meta, steps=run.step, seconds=round(run.seconds, 1), config=asdict(config))
    with interrupts_held():  # a manifest that disagreed with the files would refuse --resume
        with atomic_path(out / "checkpoint.pt") as tmp:
            torch.save(state, tmp)
        save_weights(out / "weights.pt", model.state_dict(), facts)
        with atomic_open(out / "history.json", "w", encoding="utf-8") as handle:
            json.dump({"meta": facts, "history": run.history}, handle, indent=1)
        written = {"checkpoint.pt", "weights.pt", "history.json"}
        if figure and run.history:
            from ..viz.plots import plot_training

            plot_training(run.history, out / "training.png", title=str(meta.get("name", "training")))
            written.add("training.png")
        for name in earlier:
            if name not in written:
                with contextlib.suppress(FileNotFoundError, IsADirectoryError):
                    (out / name).unlink()
                for parent in Path(name).parents:  # an earlier command's subfolders, once empty
                    if str(parent) != ".":
                        with contextlib.suppress(OSError):
                            (out / parent).rmdir()
        _write_manifest(out)


def step_memory(build_model: Callable[[], nn.Module], make_batch, loss_fn) -> tuple[float, float]:
    """``(fixed, per_example)`` bytes of one training step, measured before training: the
    bytes every operation of a forward and backward pass allocates (views aside), on
    batches of one and three examples of a fresh model (the global RNG untouched).

    The sum of a step's allocations over-states its peak, since most are freed before the
    last is made: the curve networks' resident peak measured a quarter to a third of it
    (MV and V at 64 and 128 px); callers plan half of it.
    """
    from torch.utils._python_dispatch import TorchDispatchMode
    from torch.utils._pytree import tree_leaves

    class Allocated(TorchDispatchMode):
        def __init__(self):
            super().__init__()
            self.bytes = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            out = func(*args, **(kwargs or {}))
            if not getattr(func, "is_view", False):
                self.bytes += sum(t.numel() * t.element_size() for t in tree_leaves(out) if isinstance(t, Tensor))
            return out

    def measured(n: int) -> int:
        with torch.random.fork_rng(devices=[]):
            model = build_model()
            batch = make_batch(torch.Generator().manual_seed(0), n)
            with Allocated() as counter:
                loss, _ = loss_fn(model, batch)
                loss.backward()
        return counter.bytes

    one, three = measured(1), measured(3)
    per = max(0.0, (three - one) / 2)
    return max(0.0, one - per), per


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
        resume: continue from ``out/checkpoint.pt`` (:func:`load_checkpoint`: the
            network, ``meta``'s settings, seed and batch size must match; ``steps``
            may grow).
        overwrite: replace an earlier run's files in ``out``.
        progress: called after every step with ``(step, steps, parts as floats)``.
        validate: called at every log with the model in eval mode; its numbers join
            the history record (name them ``val_...``).

    Returns:
        A :class:`TrainRun`; on Ctrl-C (or SIGTERM raised as KeyboardInterrupt) a
        checkpoint of the last step is written and the interrupt propagates; a folder
        this call created and wrote nothing to is removed, and an earlier run's files
        (``overwrite``) stay until this run's first checkpoint replaces them.
    """
    meta = dict(meta or {})
    out = None if out is None else Path(out)
    run = TrainRun(model=model, out=out)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    created = out is not None and not out.exists()
    earlier = _prepare(out, resume, overwrite) if out is not None else []
    if out is not None and resume:
        checkpoint = load_checkpoint(out, model, config, meta)
        ckpt = out / "checkpoint.pt"
        try:
            model.load_state_dict(checkpoint["model"])
            optimizer.load_state_dict(checkpoint["optimizer"])
        except (RuntimeError, ValueError, KeyError, TypeError) as exc:
            why = (str(exc).strip().splitlines() or [""])[0][:200]
            raise InputError(f"{ckpt}: its state does not fit this network ({type(exc).__name__}: {why})") from None
        run.step, run.seconds = checkpoint["step"], checkpoint["seconds"]
        run.history = checkpoint["history"]
    saved_step = run.step  # the step the files in ``out`` hold (none yet for a new run)
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
                _save_run(out, model, optimizer, run, config, meta, figure=run.step == config.steps, earlier=earlier)
                saved_step, earlier = run.step, []
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt) and out is not None and run.step > saved_step:
            _save_run(out, model, optimizer, run, config, meta, figure=False, earlier=earlier)
        elif created and saved_step == 0:
            with contextlib.suppress(OSError):
                out.rmdir()  # the folder this run made, still empty: nothing is left behind
        raise
    model.eval()
    return run
