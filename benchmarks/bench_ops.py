"""Knot operations: nurbskit (matrix from the identity + one GEMM) against geomdl.

Question: what do ``insert_knot``, ``refine_knots`` and ``elevate_degree`` of
``nurbskit.core.ops`` cost on rational surfaces of 10x10 .. 40x40 control points, against
geomdl 5.4 doing the same operation in pure Python on the same surface, and how does
our time split between building the per-direction matrix (NumPy, The NURBS Book
A5.1 / A5.4 run on the identity, elevation through the Bezier form) and applying it
(torch)?

Method (see benchmarks/README_ops.md):

* rational surfaces, degree 3 x 3, clamped knots with random interior knots, float64,
  CPU, ``torch.set_num_threads(2)``, fixed seed;
* cases: one knot inserted once in u; u refined with geomdl's ``density=1`` knot set
  (every break and span midpoint to multiplicity p); degree raised by 1 in u (geomdl
  has no surface degree elevation: no peer, ratio left empty);
* the process first runs small float64 GEMMs until 20 in a row take under 1 ms (at
  most 10 s; the time is recorded): on the shared 2-core benchmark machine the first
  seconds of a process showed ~45 ms per tiny GEMM, which would otherwise be measured
  as the cost of the operation;
* one warm-up, then the median (and min, max) of ``repeats`` timed runs; geomdl gets
  fewer repeats where one run is long;
* both results are compared before timing (control points to 1e-9): a benchmark of
  two different answers would be meaningless.

Usage: ``python benchmarks/bench_ops.py [--quick] [--threads N]``; writes
``benchmarks/results/ops.json`` and ``benchmarks/results/ops.md`` (``ops_threadsN.*``
for another thread count).
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
import statistics
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch
from geomdl import operations as gops

from nurbskit.core import NURBSSurface, from_geomdl, to_geomdl
from nurbskit.core import ops
from nurbskit.core.spline import TensorSpline

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
THREADS = 2
SIZES_FULL = [10, 20, 40]
SIZES_QUICK = [10, 20]
DEGREE = 3


def make_surface(n: int, seed: int = 0) -> NURBSSurface:
    rng = np.random.default_rng(seed)
    kvs = []
    for _ in range(2):
        inner = np.sort(rng.uniform(0.0, 1.0, n - DEGREE - 1))
        kvs.append(torch.tensor(np.concatenate([np.zeros(DEGREE + 1), inner, np.ones(DEGREE + 1)])))
    cp = torch.tensor(rng.normal(size=(n, n, 3)))
    w = torch.tensor(rng.uniform(0.5, 2.0, size=(n, n)))
    return NURBSSurface(cp, (DEGREE, DEGREE), kvs, w)


def density_one_knots(s: NURBSSurface) -> np.ndarray:
    """The knots geomdl's ``refine_knotvector(s, [1, 0])`` inserts in u (breaks and midpoints, to multiplicity p)."""
    kv = s.knot_vectors[0].numpy()
    breaks = np.unique(kv[DEGREE:-DEGREE])
    dense = np.sort(np.concatenate([breaks, (breaks[:-1] + breaks[1:]) / 2]))
    return np.repeat(dense, [max(DEGREE - int((kv == t).sum()), 0) for t in dense])


def settle(limit_s: float = 10.0) -> float:
    """Run tiny GEMMs until 20 in a row are fast; return the seconds it took."""
    a = torch.rand(16, 16, dtype=torch.float64)
    start = time.perf_counter()
    fast = 0
    while fast < 20 and time.perf_counter() - start < limit_s:
        t = time.perf_counter()
        a @ a
        fast = fast + 1 if time.perf_counter() - t < 1e-3 else 0
    return time.perf_counter() - start


def timed(fn, repeats: int) -> dict:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return {"median_s": statistics.median(times), "min_s": min(times), "max_s": max(times), "repeats": repeats}


def split_build_apply(s: NURBSSurface, case: str, repeats: int) -> dict:
    """Our time spent building the matrix (NumPy) versus applying it (torch), per case."""
    kv = s.knot_vectors[0].numpy()
    if case == "insert":
        build = lambda: ops._insertion_matrix(kv, DEGREE, 0.5, 1)  # noqa: E731
    elif case == "refine":
        X = density_one_knots(s)
        build = lambda: ops._refinement_matrix(kv, DEGREE, X)  # noqa: E731
    else:
        build = lambda: ops._elevation_matrix(kv, DEGREE, 1)  # noqa: E731
    T, knots = build()
    return {
        "build": timed(build, repeats),
        "apply": timed(lambda: ops._apply(s, 0, T, knots, None if case != "elevate" else DEGREE + 1), repeats),
    }


def run_case(n: int, case: str, repeats: int) -> dict:
    s = make_surface(n)
    if case == "insert":
        ours = lambda: ops.insert_knot(s, 0.5, 1, axis=0)  # noqa: E731
        peer = lambda g: gops.insert_knot(g, [0.5, None], [1, 0])  # noqa: E731
    elif case == "refine":
        X = density_one_knots(s)
        ours = lambda: ops.refine_knots(s, X, axis=0)  # noqa: E731
        peer = lambda g: gops.refine_knotvector(g, [1, 0])  # noqa: E731
    else:
        ours = lambda: ops.elevate_degree(s, 1, axis=0)  # noqa: E731
        peer = None
    result: TensorSpline = ours()
    row = {"n": n, "case": case, "control_points": n * n}
    row["nurbskit"] = timed(ours, repeats)
    row["nurbskit_parts"] = split_build_apply(s, case, repeats)
    if peer is not None:
        g0 = to_geomdl(s)
        g = copy.deepcopy(g0)
        peer(g)
        ref = from_geomdl(g)
        err = float((ref.control_points - result.control_points).abs().max())
        if err > 1e-9:
            raise SystemExit(f"{case} n={n}: nurbskit and geomdl disagree by {err:g}")
        row["max_abs_difference"] = err
        peer_repeats = max(1, min(repeats, 3 if n >= 40 else repeats))

        def run_peer():
            peer(copy.deepcopy(g0))

        copy_cost = timed(lambda: copy.deepcopy(g0), peer_repeats)["median_s"]
        row["geomdl"] = timed(run_peer, peer_repeats)
        row["geomdl"]["deepcopy_s_subtracted"] = copy_cost
        row["geomdl"]["median_s"] = max(row["geomdl"]["median_s"] - copy_cost, 0.0)
        row["ratio_geomdl_over_nurbskit"] = row["geomdl"]["median_s"] / row["nurbskit"]["median_s"]
    else:
        row["geomdl"] = None
        row["ratio_geomdl_over_nurbskit"] = None
    return row


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes, fewer repeats")
    parser.add_argument("--threads", type=int, default=THREADS, help=f"torch intra-op threads (default {THREADS})")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per case (default 7, quick 3)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    settle_s = settle()
    sizes = SIZES_QUICK if args.quick else SIZES_FULL
    repeats = args.repeats or (3 if args.quick else 7)
    rows = [run_case(n, case, repeats) for n in sizes for case in ("insert", "refine", "elevate")]
    meta = {
        "question": "knot operations: nurbskit matrix + GEMM against geomdl 5.4 pure Python",
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "python": sys.version.split()[0],
        "torch": torch.__version__,
        "numpy": np.__version__,
        "platform": platform.platform(),
        "threads": args.threads,
        "dtype": "float64",
        "device": "cpu",
        "degree": DEGREE,
        "quick": args.quick,
        "settle_s": settle_s,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = "ops" if args.threads == THREADS else f"ops_threads{args.threads}"
    (RESULTS / f"{stem}.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    lines = [
        "| n x n | case | nurbskit median ms | build ms | apply ms | geomdl median ms | geomdl / nurbskit |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        peer = "-" if r["geomdl"] is None else f"{1e3 * r['geomdl']['median_s']:.1f}"
        ratio = "-" if r["ratio_geomdl_over_nurbskit"] is None else f"{r['ratio_geomdl_over_nurbskit']:.2g}x"
        parts = r["nurbskit_parts"]
        lines.append(
            f"| {r['n']}x{r['n']} | {r['case']} | {1e3 * r['nurbskit']['median_s']:.2f} "
            f"| {1e3 * parts['build']['median_s']:.2f} | {1e3 * parts['apply']['median_s']:.2f} | {peer} | {ratio} |"
        )
    table = "\n".join(lines)
    (RESULTS / f"{stem}.md").write_text(
        f"Run {meta['date_utc']} ({'quick' if args.quick else 'full'}), {args.threads} thread(s), float64, CPU.\n\n{table}\n"
    )
    sys.stdout.write(table + "\n")


if __name__ == "__main__":
    main()
