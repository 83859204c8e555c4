"""Weights files: a model's ``state_dict`` with the facts that made it.

Convention: a weights file is ``torch.save({"state_dict": ..., "meta": ...})`` where
``meta`` is plain JSON data (strings, numbers, lists, dicts): the model name and its
architecture arguments (enough to rebuild it), the training command, seed, steps,
seconds, and the metrics measured on the held-out set. Files load with
``torch.load(weights_only=True)``: nothing in them can run code.

The weights shipped with nurbskit live in ``nurbskit/learn/weights/<name>.pt`` (package
data) and are made by ``nurbskit train ...``; ``docs/learned.md`` gives the commands.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from .._fs import atomic_path
from ..errors import InputError

_SHIPPED = Path(__file__).resolve().parent / "weights"


def weights_path(name: str) -> Path:
    """The path of the shipped weights called ``name`` (``curves_v`` -> ``.../weights/curves_v.pt``)."""
    return _SHIPPED / f"{name}.pt"


def shipped_weights() -> list[str]:
    """Names of the weights shipped with this installation, sorted."""
    return sorted(p.stem for p in _SHIPPED.glob("*.pt"))


def save_weights(path: str | os.PathLike, state_dict: dict, meta: dict) -> Path:
    """Write a weights file atomically; ``meta`` must be JSON data (checked)."""
    json.dumps(meta)  # raises TypeError on anything that is not plain data
    path = Path(path)
    state = {k: v.detach().cpu().clone() for k, v in state_dict.items()}
    with atomic_path(path) as tmp:
        torch.save({"state_dict": state, "meta": meta}, tmp)
    return path


def load_weights(name_or_path: str | os.PathLike, map_location="cpu") -> tuple[dict, dict]:
    """``(state_dict, meta)`` from a shipped name (``"curves_v"``) or a file path.

    Raises InputError (one line) for a missing or unreadable file.
    """
    path = Path(name_or_path)
    if path.suffix != ".pt" and not path.exists():
        path = weights_path(str(name_or_path))
        if not path.exists():
            have = ", ".join(shipped_weights()) or "none"
            raise InputError(f"no shipped weights called {name_or_path!r} (shipped: {have})")
    if not path.exists():
        raise InputError(f"{path}: no such weights file")
    try:
        data = torch.load(path, map_location=map_location, weights_only=True)
    except Exception:  # noqa: BLE001 - any unpickling failure is a bad file (torch's advice is not for users)
        raise InputError(f"{path}: not a nurbskit weights file (torch cannot read it as saved weights)") from None
    if not isinstance(data, dict) or "state_dict" not in data or "meta" not in data:
        hint = ("a training checkpoint: continue it with --resume, or pass the run's weights.pt"
                if isinstance(data, dict) and "model" in data else "expected the weights.pt a training run writes")
        raise InputError(f"{path}: not a nurbskit weights file ({hint})")
    return data["state_dict"], data["meta"]
