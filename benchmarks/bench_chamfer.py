"""Chamfer distance, forward + backward: KD-tree + gather against the full distance matrix.

Question: what does ``nurbskit.losses.chamfer_distance`` (nearest neighbours without
gradient via a KD-tree, distances recomputed by gathering) cost against the textbook
full-matrix version (``torch.cdist``, default compute mode -> min over both axes) for 10^3 .. 10^5 points?

Method (see benchmarks/README_losses.md):

* two clouds of N = M points, uniform in the unit cube, float32, CPU, fixed seed;
* every (method, N) case runs in a fresh child process, with ``torch.set_num_threads(2)``
  and the KD-tree on all cores (``workers=-1``; the benchmark machine has 2);
* one warm-up run, then the median (and min, max) of ``repeats`` timed forward+backward runs;
* peak memory: the child's peak resident set size (``ru_maxrss``) minus its resident set
  after set-up, i.e. what the computation added at its peak; plus an analytical estimate;
* the full-matrix version is skipped where its estimate exceeds ``--max-full-gib``;
* where both run, the two values are compared (they must agree).

Usage: ``python benchmarks/bench_chamfer.py [--quick] [--device cpu|cuda]``; writes
``benchmarks/results/chamfer.json`` and ``benchmarks/results/chamfer.md`` (``results/gpu/``
for CUDA, where the "KD-tree" column is the tiled exact search and memory is the device's).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
THREADS = 2
SIZES_FULL = [1_000, 3_000, 10_000, 30_000, 100_000]
SIZES_QUICK = [1_000, 3_000, 10_000]
DIM = 3
ELEM = 4  # float32 bytes


def estimate_bytes(method: str, n: int, m: int) -> int:
    """Analytical peak of the computation's large buffers (bytes)."""
    if method == "full":
        # about four live N x M float32 buffers: x @ y^T inside cdist, the distance
        # matrix, its square, and the gradient matrix in backward
        return 4 * n * m * ELEM
    # points as float64 copies for scipy, two trees (~ 2 * 8 * D bytes/point plus index),
    # gathered neighbours and their gradients in float32
    return (n + m) * (2 * 8 * DIM + 16 + 4 * DIM * ELEM)


def _rss_bytes() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def run_case(method: str, n: int, repeats: int, seed: int, device: str = "cpu") -> dict:
    """Time one (method, N) case in this process (called in a child)."""
    import torch

    from nurbskit.losses import chamfer_distance

    torch.set_num_threads(THREADS)
    g = torch.Generator().manual_seed(seed)
    x0 = torch.rand(n, DIM, generator=g).to(device)
    y0 = torch.rand(n, DIM, generator=g).to(device)
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)

    def full_chamfer(x, y):
        # torch's default mode (matrix-multiply formula above 25 rows): the fast, usual peer
        d = torch.cdist(x, y) ** 2
        return d.min(dim=1).values.mean() + d.min(dim=0).values.mean()

    fn = chamfer_distance if method == "kdtree" else full_chamfer

    def once():
        x = x0.clone().requires_grad_(True)
        y = y0.clone().requires_grad_(True)
        sync()
        start = time.perf_counter()
        value = fn(x, y)
        sync()
        mid = time.perf_counter()
        value.backward()
        sync()
        end = time.perf_counter()
        return end - start, mid - start, float(value)

    # load lazy imports (scipy.spatial, kernels) on a tiny problem before the baseline
    fn(x0[:16].clone().requires_grad_(True), y0[:16].clone().requires_grad_(True)).backward()
    baseline = _rss_bytes()
    once()  # warm-up at full size
    times, forward, value = [], [], None
    for _ in range(repeats):
        t, f, value = once()
        times.append(t)
        forward.append(f)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    if device == "cuda":  # device memory instead of the host's
        baseline, peak = 0, torch.cuda.max_memory_allocated()
    return {
        "method": method,
        "n": n,
        "m": n,
        "repeats": repeats,
        "median_s": statistics.median(times),
        "min_s": min(times),
        "max_s": max(times),
        "forward_median_s": statistics.median(forward),
        "value": value,
        "peak_rss_added_mib": max(0, peak - baseline) / 2**20,
        "estimate_mib": estimate_bytes(method, n, n) / 2**20,
    }


def _child(method: str, n: int, repeats: int, seed: int, device: str = "cpu") -> dict:
    env = dict(os.environ, OMP_NUM_THREADS=str(THREADS), MKL_NUM_THREADS=str(THREADS))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--case", method, str(n), str(repeats), str(seed), device]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        return {"method": method, "n": n, "m": n, "error": out.stderr.strip().splitlines()[-1:] or ["failed"]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def _fmt(v, spec):
    return "-" if v is None else format(v, spec)


def write_markdown(report: dict, path: Path) -> None:
    lines = [
        f"# Chamfer forward + backward ({report.get('device', 'cpu')})",
        "",
        f"{report['date']}, torch {report['torch']}, scipy {report['scipy']}, {report['threads']} threads, "
        f"{report['cpu_count']} cores, load average at start {report['load_average_start']}.",
        "Median of the repeats (forward + backward; forward alone in the fwd columns); memory = peak RSS added by the computation (estimate in brackets).",
        "Timings may be contended by other processes on a shared machine.",
        "",
        "| N = M | KD-tree + gather (s) | full cdist (s) | full / KD | KD fwd (s) | full fwd (s) "
        "| KD mem MiB | full mem MiB | abs diff |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in report["rows"]:
        kd, full = row["kdtree"], row.get("full")
        full_s = full.get("median_s") if full else None
        lines.append(
            "| {n} | {kd} | {fu} | {ratio} | {kdf} | {fuf} | {kdm} ({kde}) | {fum} | {diff} |".format(
                n=row["n"],
                kd=_fmt(kd.get("median_s"), ".4f"),
                fu=_fmt(full_s, ".4f") if full else "skipped",
                ratio=_fmt(row.get("speedup"), ".1f"),
                kdf=_fmt(kd.get("forward_median_s"), ".4f"),
                fuf=_fmt(full.get("forward_median_s"), ".4f") if full else "skipped",
                kdm=_fmt(kd.get("peak_rss_added_mib"), ".0f"),
                kde=_fmt(kd.get("estimate_mib"), ".0f"),
                fum=(
                    f"{_fmt(full.get('peak_rss_added_mib'), '.0f')} ({_fmt(full.get('estimate_mib'), '.0f')})"
                    if full
                    else f"skipped ({row['full_estimate_mib']:.0f} est.)"
                ),
                diff=_fmt(row.get("abs_diff"), ".1e"),
            )
        )
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="sizes up to 10^4 and 3 repeats")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per case (default 5, quick 3)")
    parser.add_argument("--max-full-gib", type=float, default=2.0, help="skip the full matrix above this estimate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder for chamfer.json and chamfer.md")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"],
                        help="cuda: tiled exact search on the GPU, memory = torch.cuda.max_memory_allocated")
    parser.add_argument("--case", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.case:
        method, n, repeats, seed, device = args.case
        print(json.dumps(run_case(method, int(n), int(repeats), int(seed), device)))
        return 0

    import scipy
    import torch

    sizes = SIZES_QUICK if args.quick else SIZES_FULL
    repeats = args.repeats or (3 if args.quick else 5)
    rows = []
    for n in sizes:
        kd = _child("kdtree", n, repeats, args.seed, args.device)
        row = {"n": n, "kdtree": kd, "full_estimate_mib": estimate_bytes("full", n, n) / 2**20}
        if estimate_bytes("full", n, n) <= args.max_full_gib * 2**30:
            full = _child("full", n, repeats, args.seed, args.device)
            row["full"] = full
            if "median_s" in kd and "median_s" in full:
                row["speedup"] = full["median_s"] / kd["median_s"]
                row["abs_diff"] = abs(full["value"] - kd["value"])
        rows.append(row)
        print(f"N={n}: kd {kd.get('median_s')} s, full {row.get('full', {}).get('median_s', 'skipped')}", file=sys.stderr)

    report = {
        "benchmark": "chamfer forward+backward",
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "quick": bool(args.quick),
        "torch": torch.__version__,
        "scipy": scipy.__version__,
        "python": platform.python_version(),
        "device": args.device,
        "dtype": "float32",
        "dim": DIM,
        "threads": THREADS,
        "cpu_count": os.cpu_count(),
        "load_average_start": [round(v, 2) for v in os.getloadavg()],
        "repeats": repeats,
        "max_full_gib": args.max_full_gib,
        "data": "two independent uniform clouds in the unit cube, N = M",
        "rows": rows,
    }
    if args.device == "cuda" and args.out == RESULTS:
        args.out = RESULTS / "gpu"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "chamfer.json").write_text(json.dumps(report, indent=2) + "\n")
    write_markdown(report, args.out / "chamfer.md")
    print((args.out / "chamfer.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
