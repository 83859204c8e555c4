"""Shared benchmark helpers: timing, result files, environment description.

Method (every benchmark): warm-up runs first, then the median of repeated runs with
``time.perf_counter``; ``torch.set_num_threads`` fixed (2 by default, the CI machine);
results written as JSON (raw numbers plus the environment) and as a markdown table.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Callable

import torch

RESULTS = Path(__file__).resolve().parent / "results"


def timeit(fn: Callable[[], object], *, repeats: int = 7, warmup: int = 2, min_time: float = 0.0, sync=None) -> float:
    """Median seconds of ``fn()`` over ``repeats`` runs after ``warmup`` runs.

    When one call is short, each run loops until ``min_time`` seconds pass and the
    per-call time is taken, which keeps timer resolution out of the numbers.
    """
    for _ in range(warmup):
        fn()
    if sync:
        sync()
    samples = []
    for _ in range(repeats):
        count, start = 0, time.perf_counter()
        while True:
            fn()
            count += 1
            if sync:
                sync()
            elapsed = time.perf_counter() - start
            if elapsed >= min_time:
                break
        samples.append(elapsed / count)
    return statistics.median(samples)


def environment(device: str = "cpu") -> dict:
    env = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "device": device,
    }
    if device.startswith("cuda") and torch.cuda.is_available():
        env["gpu"] = torch.cuda.get_device_name()
    return env


def write_results(name: str, rows: list[dict], columns: list[tuple[str, str]], *, meta: dict | None = None,
                  title: str = "", notes: str = "", subdir: str = "") -> Path:
    """Write ``results/[subdir/]name.json`` and ``name.md`` (a markdown table of ``columns``)."""
    out = RESULTS / subdir if subdir else RESULTS
    out.mkdir(parents=True, exist_ok=True)
    payload = {"benchmark": name, "environment": environment(meta.get("device", "cpu") if meta else "cpu"),
               "meta": meta or {}, "rows": rows}
    (out / f"{name}.json").write_text(json.dumps(payload, indent=2))
    lines = [f"# {title or name}", ""]
    if notes:
        lines += [notes, ""]
    lines.append("| " + " | ".join(h for _, h in columns) + " |")
    lines.append("|" + "---|" * len(columns))
    for row in rows:
        cells = []
        for key, _ in columns:
            v = row.get(key, "")
            cells.append(f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    env = payload["environment"]
    lines += ["", f"Environment: torch {env['torch']}, {env['threads']} threads, {env['device']}, Python {env['python']}."]
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")
    return out / f"{name}.md"
