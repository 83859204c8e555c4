"""How long does one least-squares solve of a control net take, dense against sparse?

Question: the alternation and the initial fit solve ``(A^T A + lambda D^T D) P = A^T X``
for the control points once per round. The dense solve builds the design matrix
``(M, k)`` and factors the ``(k, k)`` normal matrix (``k^3 / 3`` work); where
``lstsq.solves_sparse`` says so (without gradients, on the CPU), nurbskit assembles the
same system as scipy sparse matrices and solves it with SuperLU.

Method: a rational bicubic surface with n x n control points (n = 8, 16, 32, 48, 64, 100;
``--quick``: 8, 16, 32), M = 20,000 points at random parameters with noise (seed 0),
smoothness 1e-3, open topology. Each solve under ``torch.no_grad()``; the dense one is
forced by replacing ``solves_sparse`` for the call. Median of 3 runs after one warm-up
(dense at n = 100: one run, no warm-up; it is skipped with ``--quick``). The peak of the
dense path is estimated from its largest arrays (the design matrix three times, the
normal matrix several times: ``fit.checks.fit_bytes``'s term); both results are
compared (largest difference over the largest control coordinate). 2 threads.

Run: ``python benchmarks/bench_lstsq_sparse.py [--quick]``; writes
``benchmarks/results/lstsq_sparse.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "2")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit.fit import lstsq  # noqa: E402
from nurbskit.fit.params import Topology  # noqa: E402


def case(n: int, m: int = 20_000, quick: bool = False) -> dict:
    g = torch.Generator().manual_seed(0)
    s = NURBSSurface(torch.rand(n, n, 3, dtype=torch.float64, generator=g), (3, 3),
                     weights=torch.rand(n, n, dtype=torch.float64, generator=g) + 0.5)
    uv = torch.rand(m, 2, dtype=torch.float64, generator=g)
    with torch.no_grad():
        X = s.evaluate(uv) + 0.01 * torch.randn(m, 3, dtype=torch.float64, generator=g)
    args = (uv, X, s.knot_vectors, s.degrees, s.sizes, s.weights, Topology(), 1e-3)
    k = n * n
    row = {"net": f"{n}x{n}", "unknowns": k, "points": m, "sparse_path": lstsq.solves_sparse(m, k, "cpu")}

    def solve(sparse: bool):
        chooser = lstsq.solves_sparse
        lstsq.solves_sparse = lambda *_: sparse
        try:
            with torch.no_grad():
                return lstsq.solve_control_points(*args)
        finally:
            lstsq.solves_sparse = chooser

    row["sparse_s"] = timeit(lambda: solve(True), repeats=3, warmup=1)
    dense_bytes = 8.0 * (3.0 * m * k + 8.0 * k * k)
    row["dense_estimate_gb"] = dense_bytes / 2**30
    if n >= 100 and quick:
        return row
    if n >= 100:
        t = time.perf_counter()
        dense = solve(False)
        row["dense_s"] = time.perf_counter() - t
    else:
        row["dense_s"] = timeit(lambda: solve(False), repeats=3, warmup=1)
        dense = solve(False)
    row["x_dense"] = row["dense_s"] / row["sparse_s"]
    row["max_rel_diff"] = float((solve(True) - dense).abs().max() / dense.abs().max())
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(2)
    sizes = (8, 16, 32) if args.quick else (8, 16, 32, 48, 64, 100)
    rows = []
    for n in sizes:
        rows.append(case(n, quick=args.quick))
        print(rows[-1], flush=True)
    columns = [("net", "net"), ("unknowns", "unknowns"), ("points", "points"), ("sparse_path", "sparse by default"),
               ("dense_s", "dense s"), ("sparse_s", "sparse s"), ("x_dense", "x dense"),
               ("dense_estimate_gb", "dense arrays GB (estimate)"), ("max_rel_diff", "max |sparse - dense| / max |P|")]
    write_results("lstsq_sparse" + ("_quick" if args.quick else ""), rows, columns,
                  title="One least-squares solve of a control net: dense against sparse",
                  notes="Method: the module docstring. `sparse by default`: whether nurbskit takes the sparse "
                        f"path itself (from {lstsq.SPARSE_UNKNOWNS} unknowns or {lstsq.SPARSE_ENTRIES:,} "
                        "design-matrix entries).")


if __name__ == "__main__":
    main()
