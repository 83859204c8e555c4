"""``DIR/summary.csv``, ``summary.json`` and ``summary.png``: one row per input and an aggregate.

Columns: ``input`` (what the user named), ``name`` (the output folder), ``status`` (``ok``
or ``failed``), ``error`` (one line), ``seconds`` (the item's own wall time on its worker),
``resumed`` (true when ``--resume`` found the item finished and did not run it), then the
command's headline metrics. The aggregate row (``input`` = ``ALL``) counts ok and failed
items, sums the seconds and gives the mean of each metric over the ok items; a metric
whose values are strings (a label: ``shape``'s ``kind``) is counted per value instead
(``"revolution: 3, extrusion: 1"``). Every file is written atomically.

Convention (the summary files in ``DIR``):
    ``DIR`` holds the item folders and the summary, so it is no output folder of
    :func:`nurbskit._fs.output_directory`; the batch marks its summary files as its own
    in ``DIR/.nurbskit-manifest.json`` (the manifest of :mod:`nurbskit._fs`: names and
    sizes). A summary file that is not listed there, or has changed size since, is the
    user's: :func:`check_summary_files` refuses the run before any work, whatever the
    flags, as ``output_directory`` refuses a folder holding files nurbskit did not write.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
from collections import Counter
from pathlib import Path
from typing import Sequence

from .._fs import MANIFEST, atomic_open, interrupts_held, read_manifest, write_manifest
from ..errors import OptionError

BASE_COLUMNS = ("input", "name", "status", "error", "seconds", "resumed")
SUMMARY_FILES = ("summary.csv", "summary.json", "summary.png")


def metric_names(records: Sequence[dict]) -> list[str]:
    """Metric names in first-seen order across ``records``."""
    names: list[str] = []
    for record in records:
        for key in record.get("metrics") or {}:
            if key not in names:
                names.append(key)
    return names


def flat_rows(records: Sequence[dict]) -> list[dict]:
    """Records with their metrics as top-level columns (one dict per input)."""
    names = metric_names(records)
    rows = []
    for r in records:
        row = {k: r.get(k, "") for k in BASE_COLUMNS}
        row["resumed"] = bool(r.get("resumed", False))
        metrics = r.get("metrics") or {}
        row.update({n: metrics.get(n, float("nan")) for n in names})
        rows.append(row)
    return rows


def aggregate(records: Sequence[dict]) -> dict:
    """The aggregate row: counts, total seconds, mean of each metric over ok items."""
    ok = [r for r in records if r.get("status") == "ok"]
    failed = len(records) - len(ok)
    row = {"input": "ALL", "name": "", "status": f"{len(ok)} ok, {failed} failed", "error": "",
           "seconds": float(sum(float(r.get("seconds") or 0.0) for r in records)),
           "resumed": sum(bool(r.get("resumed")) for r in records)}
    for name in metric_names(records):
        present = [r["metrics"][name] for r in ok if name in (r.get("metrics") or {})]
        labels = [v for v in present if isinstance(v, str)]
        if labels:
            row[name] = ", ".join(f"{label}: {count}" for label, count in Counter(labels).most_common())
            continue
        values = [float(v) for v in present]
        values = [v for v in values if math.isfinite(v)]
        row[name] = sum(values) / len(values) if values else float("nan")
    return row


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def check_summary_files(out: str | os.PathLike) -> None:
    """Refuse ``out`` when it holds a summary file that no batch wrote (see the Convention).

    Raises OptionError (one line naming ``--out``, the files and why). Creates nothing.
    """
    out = Path(out)
    listed = (read_manifest(out.resolve()) or {}) if out.is_dir() else {}
    foreign = []
    for name in SUMMARY_FILES:
        path = out / name
        if not (path.exists() or path.is_symlink()):
            continue
        if name not in listed or path.is_symlink() or not path.is_file():
            foreign.append(f"{name} (not in its {MANIFEST})")
        elif path.stat().st_size != listed[name]:
            foreign.append(f"{name} (changed since nurbskit batch wrote it)")
    if foreign:
        raise OptionError(
            f"--out {out}: the folder holds {', '.join(foreign)}; nurbskit batch replaces only summary files "
            "it wrote, even with --resume or --overwrite: move them or choose another folder"
        )


def _record_summary_files(out: Path, written: Sequence[Path]) -> None:
    """List ``written`` in ``out``'s manifest in place of the previous summary files (the
    manifest's other entries are kept); a summary file of an earlier batch that this run
    did not write again (``summary.png`` after an interrupt) is removed, as
    :func:`nurbskit._fs.output_directory` removes an earlier run's files."""
    old = read_manifest(out.resolve()) or {}
    names = {p.name for p in written}
    for name in SUMMARY_FILES:
        if name in old and name not in names:
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
    files = {k: v for k, v in old.items() if k not in SUMMARY_FILES}
    files.update({p.name: p.stat().st_size for p in written})
    write_manifest(out, files)


def write_summary(out: str | os.PathLike, records: Sequence[dict], meta: dict, *, figure: bool = True) -> list[Path]:
    """Write the summary files into ``out`` and list them in its manifest; returns their paths.

    Call :func:`check_summary_files` first, before any work: this replaces the files.
    Ctrl-C waits until the files and the manifest agree (a second at most, for the figure).
    """
    out = Path(out)
    rows = flat_rows(records)
    total = aggregate(records)
    columns = [*BASE_COLUMNS, *metric_names(records)]
    with interrupts_held():
        with atomic_open(out / "summary.csv", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
            writer.writeheader()
            for row in [*rows, total]:
                writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
        with atomic_open(out / "summary.json", encoding="utf-8") as handle:
            json.dump(_json_safe({**meta, "aggregate": total, "rows": rows}), handle, indent=1)
            handle.write("\n")
        paths = [out / "summary.csv", out / "summary.json"]
        if figure:
            paths.append(plot_summary(records, out / "summary.png", title=f"nurbskit batch {meta.get('command', '')}"))
        _record_summary_files(out, paths)
    return paths


def plot_summary(records: Sequence[dict], path: str | os.PathLike, title: str = "") -> Path:
    """Histograms of each metric and of the seconds per item (ok items), one panel each;
    a label metric (strings) as one bar per label."""
    from ..viz.plots import _figure, _save

    ok = [r for r in records if r.get("status") == "ok"]
    names = [*metric_names(records), "seconds"]
    fig = _figure((3.6 * len(names), 3.2))
    axes = fig.subplots(1, len(names), squeeze=False)[0]
    for ax, name in zip(axes, names):
        raw = [r["seconds"] if name == "seconds" else (r.get("metrics") or {}).get(name, math.nan) for r in ok]
        labels = Counter(v for v in raw if isinstance(v, str))
        if labels:
            ax.bar(list(labels), list(labels.values()), color="tab:blue", edgecolor="white")
            ax.set_xlabel(name)
            continue
        values = [float(v) for v in raw]
        values = [v for v in values if math.isfinite(v)]
        if values:
            lo, hi = min(values), max(values)
            # values equal up to rounding cannot be split into bins: one bar around them
            width = max(abs(lo), abs(hi), 1e-300) * 1e-6
            span = (lo - width, hi + width) if hi - lo <= width else None
            bins = 1 if span else min(30, max(5, len(values) // 2))
            ax.hist(values, bins=bins, range=span, color="tab:blue", edgecolor="white")
        else:
            ax.text(0.5, 0.5, "no values", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel(name)
    from matplotlib.ticker import MaxNLocator

    for ax in axes:  # counts of inputs: whole numbers
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0].set_ylabel("inputs")  # one label for the row: beside every panel it ran into its neighbour
    failed = len(records) - len(ok)
    fig.suptitle(f"{title}: {len(ok)} ok, {failed} failed".strip(": "))
    fig.tight_layout()
    return _save(fig, path)

