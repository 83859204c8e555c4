"""From INPUTS (files, folders, glob patterns) to work items with unique output names."""

from __future__ import annotations

import glob
import os
import re
from collections import Counter
from pathlib import Path
from typing import Iterable

from .._fs import MANIFEST
from ..errors import InputError, OptionError
from .commands import BatchCommand, Item
from .summary import SUMMARY_FILES

_GLOB = re.compile(r"[*?\[]")


def expand_inputs(inputs: Iterable[str | os.PathLike], command: BatchCommand,
                  exclude: str | os.PathLike | None = None) -> list[Path]:
    """Input files, in the order given; folders searched (recursively) by extension.

    A pattern with ``*``, ``?`` or ``[`` is expanded as a glob (``**`` recurses); a
    pattern or folder that matches nothing is an error, as is a missing file, and a folder
    that is ``exclude`` itself (``--out`` equal to an input folder). Each file
    appears once, at its first mention. Folder searches skip hidden entries, the folder
    ``exclude`` (the batch's own output: its ``points.off`` are no inputs) and any folder
    nurbskit wrote (it holds a manifest: an earlier run's ``overlay.png`` is no drawing).
    """
    skip = Path(exclude).resolve() if exclude is not None else None
    found: list[Path] = []
    seen: set[Path] = set()

    def add(path: Path) -> None:
        key = path.resolve()
        if key not in seen:
            seen.add(key)
            found.append(path)

    for raw in inputs:
        text = os.fspath(raw)
        if _GLOB.search(text) and not Path(text).exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise InputError(f"{text}: no file matches this pattern")
            for m in matches:
                path = Path(m)
                if path.is_dir():
                    for f in _search(path, command, skip):
                        add(f)
                else:
                    add(path)
            continue
        path = Path(text)
        if path.is_dir() and path.resolve() == skip:
            raise OptionError(f"--out {exclude}: expected a folder apart from the inputs, found the input folder "
                              f"{path} itself; choose another output folder")
        if path.is_dir():
            files = _search(path, command, skip)
            if not files:
                raise InputError(
                    f"{path}: folder holds no {command.name} input (searched for {', '.join(command.extensions)})"
                )
            for f in files:
                add(f)
        elif path.exists():
            add(path)
        else:
            raise InputError(f"{path}: no such file or folder")
    if not found:
        raise InputError("INPUTS: expected files, folders or patterns, got none")
    return found


def _search(folder: Path, command: BatchCommand, skip: Path | None = None) -> list[Path]:
    extensions = {e.lower() for e in command.extensions}
    skip_names = set(command.skip_names)
    files = []
    for root, dirs, names in os.walk(folder):
        if skip is not None and Path(root).resolve() == skip or (Path(root) / MANIFEST).is_file():
            dirs[:] = []  # the batch's own output, or any folder nurbskit wrote: its results are no inputs
            continue
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))  # hidden: temporary outputs, VCS
        files += [Path(root) / n for n in sorted(names)
                  if not n.startswith(".") and n not in skip_names and Path(n).suffix.lower() in extensions]
    return files


# Names of the batch's own files in DIR: no item folder may take them.
RESERVED = set(SUMMARY_FILES)
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def _safe(name: str) -> str:
    name = (_UNSAFE.sub("_", name).strip("._") or "input")[:120]
    return name + "_" if name.lower() in RESERVED else name


def assign_names(items: list[Item]) -> list[Item]:
    """Unique, filesystem-safe output names, deterministic for a given list of items.

    An item keeps its own name (a file's stem) when no other item claims it; clashing
    items are told apart by their file name, then by their parent folders with the stem,
    then with the file name, then by a number (``cloud``; ``cloud.ply`` beside
    ``cloud.xyz``; ``a_cloud`` and ``b_cloud``, as ``fits/a/surface.json`` and
    ``fits/b/surface.json`` give ``a_surface`` and ``b_surface``; ``cloud-2``).
    """
    def candidates(item: Item) -> list[str]:
        first = Path(item.paths[0])
        out = [_safe(item.name)]
        if item.name == first.stem:
            out.append(_safe(first.name))
            parts = first.resolve().parts[1:-1]
            for depth in range(1, len(parts) + 1):
                out += [_safe("_".join([*parts[len(parts) - depth:], leaf])) for leaf in (first.stem, first.name)]
        return out

    options = [candidates(it) for it in items]
    level = [0] * len(items)
    while True:
        names = [options[i][level[i]] for i in range(len(items))]
        counts = Counter(names)
        clashing = [i for i, n in enumerate(names) if counts[n] > 1]
        advanced = False
        for i in clashing:
            if level[i] + 1 < len(options[i]):
                level[i] += 1
                advanced = True
        if not advanced:
            break
    taken = set(names)
    seen: set[str] = set()
    for i, n in enumerate(names):
        if n in seen:
            k = 2
            while f"{n}-{k}" in taken:
                k += 1
            names[i] = f"{n}-{k}"
            taken.add(names[i])
        seen.add(n)
    return [Item(name=names[i], inputs=it.inputs, source=it.source) for i, it in enumerate(items)]


def find_items(inputs: Iterable[str | os.PathLike], command: BatchCommand,
               exclude: str | os.PathLike | None = None) -> list[Item]:
    """Every work item of ``inputs`` for ``command``, named uniquely."""
    items: list[Item] = []
    for path in expand_inputs(inputs, command, exclude):
        items += command.expand(path)
    return assign_names(items)
