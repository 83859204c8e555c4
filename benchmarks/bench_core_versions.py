"""Is the core faster or slower than an earlier commit, measured in the same process?

Question: surface evaluation (32 x 32 rational bicubic at 64^2, 256^2 and 512^2: forward
with fixed knots, forward + backward to control points and weights, and with knot
gradients too) and the batch of 64 surfaces of 16 x 16 at 128^2 against a loop, for
several source trees of nurbskit at once. On a machine shared with other jobs, two runs
minutes apart are not comparable; runs interleaved in one process are.

Method: each tree (``NAME=SRC``, e.g. ``old=/tmp/core_old/src`` from
``git worktree add /tmp/core_old 775fc58``) is imported under its own module objects (the
``nurbskit`` entries of ``sys.modules`` are cleared between imports); for every case the
trees take turns, one timed sample each (a sample loops until ``--min-time``), ``--repeats``
rounds; the median and the minimum per call are reported, in CPU seconds of the process
(``time.process_time``, ``--clock cpu``, the default: not counting time the scheduler gave
to other jobs) or wall seconds (``--clock wall``, for a quiet machine). Cases:
``f:R``, ``fb:R``, ``fbk:R`` (single surface, as ``bench_core_eval.py``), ``bf:R`` / ``bfb:R``
(the batch, forward / forward + backward) and ``lf:R`` / ``lfb:R`` (the loop over the 64);
at ``R = 2`` the arithmetic is nothing, so ``lf:2 - bf:2`` is the loop's overhead.

Usage: python benchmarks/bench_core_versions.py [--threads N] [--clock cpu|wall] [--repeats K]
    [--min-time S] [--cases f:64 fb:256 ...] [--out NAME] -- NAME=SRC [NAME=SRC ...]
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402
from bench_core_eval import batch_calls  # noqa: E402  (the same calls bench_core_eval times)

DEFAULT_CASES = ["f:64", "f:256", "f:512", "fb:64", "fb:256", "fb:512", "fbk:64", "fbk:256", "fbk:512",
                 "bf:128", "lf:128", "bfb:128", "lfb:128", "bf:2", "lf:2", "bfb:2", "lfb:2"]


def load_trees(trees: list[tuple[str, str]]) -> dict:
    mods = {}
    for name, src in trees:
        for key in [k for k in sys.modules if k == "nurbskit" or k.startswith("nurbskit.")]:
            del sys.modules[key]
        sys.path.insert(0, src)
        try:
            mods[name] = importlib.import_module("nurbskit")
            importlib.import_module("nurbskit.core")
        finally:
            sys.path.remove(src)
    return mods


def make(NS, n: int, batch=(), seed: int = 0):
    rng = np.random.default_rng(seed)
    cp = torch.tensor(rng.normal(size=tuple(batch) + (n, n, 3)), dtype=torch.float32)
    w = torch.tensor(rng.uniform(0.5, 1.5, size=tuple(batch) + (n, n)), dtype=torch.float32)
    return NS(cp, (3, 3), weights=w)


def case_fn(module, case: str):
    NS = module.NURBSSurface
    kind, r = case.split(":")
    r = int(r)
    if kind in ("bf", "bfb", "lf", "lfb"):
        b = make(NS, 16, (64,), 1)
        cp, w = b.control_points.clone().requires_grad_(), b.weights.clone().requires_grad_()
        singles = [b[i] for i in range(64)]
        return batch_calls(b, singles, cp, w, r)[kind]
    base = make(NS, 32)
    u = torch.linspace(0, 1, r)
    def unchecked_copy(**changes):
        # Inside a loop splines are unchecked. Since the twenty-third session `_replace` keeps
        # the object's `validate`; older trees' `_replace` did not validate, so the flag is
        # set on the result, which reads the same in every tree.
        obj = base._replace(**changes)
        obj.validate = False
        return obj

    unchecked = unchecked_copy()
    cp, w = base.control_points.clone().requires_grad_(), base.weights.clone().requires_grad_()
    kv = [k.clone().requires_grad_() for k in base.knot_vectors]

    def f():
        with torch.no_grad():
            unchecked.evaluate_grid(u, u)

    def fb():
        cp.grad = w.grad = None
        unchecked_copy(control_points=cp, weights=w).evaluate_grid(u, u).square().sum().backward()

    def fbk():
        cp.grad = w.grad = None
        unchecked_copy(control_points=cp, weights=w, knot_vectors=kv).evaluate_grid(u, u).square().sum().backward()

    return {"f": f, "fb": fb, "fbk": fbk}[kind]


def main() -> None:
    argv = sys.argv[1:]
    split = argv.index("--") if "--" in argv else len(argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--clock", choices=["cpu", "wall"], default="cpu")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--min-time", type=float, default=0.05)
    parser.add_argument("--cases", nargs="+", default=DEFAULT_CASES)
    parser.add_argument("--out", default="core_versions")
    args = parser.parse_args(argv[:split])
    trees = [tuple(t.split("=", 1)) for t in argv[split + 1:]]
    if not trees:
        parser.error("name the trees after '--': NAME=SRC ...")
    torch.set_num_threads(args.threads)
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    mods = load_trees(trees)
    rows = []
    for case in args.cases:
        fns = {}
        for name, module in mods.items():
            try:
                fns[name] = case_fn(module, case)
                for _ in range(3):
                    fns[name]()
            except Exception as exc:  # an old tree may lack a feature (the batch before issue 16)
                print(f"{case} {name}: {type(exc).__name__}: {exc}", flush=True)
                fns.pop(name, None)
        samples = {name: [] for name in fns}
        for _ in range(args.repeats):
            for name, fn in fns.items():
                count, start = 0, clock()
                while True:
                    fn()
                    count += 1
                    elapsed = clock() - start
                    if elapsed >= args.min_time:
                        break
                samples[name].append(elapsed / count * 1e3)
        row = {"case": case}
        for name, values in samples.items():
            row[f"{name}_median_ms"] = statistics.median(values)
            row[f"{name}_min_ms"] = min(values)
        rows.append(row)
        print(row, flush=True)
    names = [name for name, _ in trees]
    columns = [("case", "case")] + [(f"{n}_median_ms", f"{n} median ms") for n in names] + \
              [(f"{n}_min_ms", f"{n} min ms") for n in names]
    write_results(args.out, rows, columns,
                  meta={"device": "cpu", "clock": args.clock, "threads": args.threads, "repeats": args.repeats,
                        "trees": dict(trees)},
                  title=f"Core evaluation, source trees interleaved in one process ({args.clock} clock)",
                  notes="f: forward, fixed knots; fb: forward + backward to control points and weights; fbk: "
                        "with knot gradients too (32 x 32 bicubic, grid R^2); bf/bfb: batch of 64 16 x 16, "
                        "lf/lfb: loop over the 64. Per call, median and minimum over interleaved samples.")


if __name__ == "__main__":
    main()
