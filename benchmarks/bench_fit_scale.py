"""How the default surface fit scales with the number of points, on the CPU or a GPU.

Question (issue 16): how long does ``fit_surface(points, "default")`` take at 5k, 20k,
100k and 1M points, how many loop iterations does it run, what does one iteration cost,
and how many aten operations and host reads does an iteration make? GPU goals: 20k
within 1.5 s, 100k within 3 s, 1M within 20 s, with the same result as on the CPU.

Method: the smooth open patch of ``bench_fit_goals.py`` (a 6 x 6 bicubic net with random
heights, 0.1 % noise) sampled at N random parameters, float64, the default pipeline
(which fits a seeded random subset of at most ``max_points`` = 20,000 points and keeps
all N as the result's points). One warm-up fit of 300 points (the default 15 x 15 grid needs at least 225) pays for imports and, on a
GPU, for the CUDA context. Then per size: one timed fit (wall-clock seconds, the loop's
seconds and iterations, the alternation's rounds) and the mean input-to-surface distance
of the fitted surface over (a subset of) the points, in units of the bounding-box
diagonal. Operations and host reads per iteration come from a second fit of the same
points under ``nurbskit._opcount.OperationCounter``: the counter's totals are read in the
progress callback after every loop iteration, and the differences between consecutive
callbacks are one iteration's counts (the optimiser's own reads included: torch's
L-BFGS reads its scalars in the line search). ``--compare-cpu`` also fits the sizes up to
20k on the CPU in the same process and reports the largest distance between the two
fitted surfaces (64 x 64 samples of each projected onto the other, over the diagonal; the
parametrisations may differ by the sign of a principal axis).

On CUDA the loop replays its objective and its warm foot-point refresh as CUDA graphs
(:mod:`nurbskit._cuda_graph`); each size is also fitted with them turned off
(``NURBSKIT_CUDA_GRAPHS=0``, every kernel launched from Python) in the same process,
with the largest difference between the two fitted control nets over the diagonal
(``--no-eager`` skips it).

The optimiser: the loop's L-BFGS (:class:`nurbskit.fit.optim.LBFGS`) against
``torch.optim.LBFGS`` configured as the loop used it before (one iteration per step,
strong Wolfe, history 20), swapped in for ``--peer-optimizer`` sizes in the same process:
loss evaluations per loop iteration (the start of the step and the line search), CPU
seconds (``time.process_time``, which the load of the shared machine does not inflate as
it does the wall clock), iterations, operations and host reads, and the fit's accuracy.
The two are timed in ``--rounds`` rounds of alternating order (ours then torch, torch then
ours, ...), and the seconds are the medians: the machine's speed drifts by 10 to 20 %
within minutes, and alternating rounds share the drift.

Usage: ``python benchmarks/bench_fit_scale.py [--device cpu|cuda] [--sizes 5000 20000 ...]
[--skip-1m] [--compare-cpu] [--peer-optimizer 5000 20000] [--rounds 2] [--threads 2] [--out FILE]``; writes
``benchmarks/results/fit_scale.{json,md}`` (``results/gpu/`` for CUDA).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402
from bench_fit_goals import smooth_patch  # noqa: E402

F64 = torch.float64


def _config(device: str):
    """The default pipeline; the fit runs on ``device`` because its points are moved there."""
    from nurbskit.fit import get_pipeline

    return get_pipeline("default")


def _mean_distance(surface, points, device, limit: int = 200_000) -> float:
    from nurbskit.core.project import project_points

    pts = points
    if pts.shape[0] > limit:
        pick = torch.randperm(pts.shape[0], generator=torch.Generator().manual_seed(1))[:limit]
        pts = pts[pick.to(pts.device)]
    s = surface.detach().to(device=device, dtype=F64)
    with torch.no_grad():
        d = project_points(s, pts.to(device=device, dtype=F64)).distance
    diag = float((points.max(0).values - points.min(0).values).norm())
    return float(d.mean()) / diag


def _surface_gap(a, b, points) -> float:
    """Largest distance between two fitted surfaces (64 x 64 samples of each projected onto
    the other), over the diagonal: independent of their parametrisations (a principal
    axis may come out with the opposite sign on another device)."""
    from nurbskit.core.project import project_points

    a = a.detach().to(device="cpu", dtype=F64)
    b = b.detach().to(device="cpu", dtype=F64)
    gap = max(float(project_points(b, a.sample((64, 64)).reshape(-1, 3)).distance.max()),
              float(project_points(a, b.sample((64, 64)).reshape(-1, 3)).distance.max()))
    return gap / float((points.max(0).values - points.min(0).values).norm())


def _sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


@contextlib.contextmanager
def torch_lbfgs():
    """The loop steps ``torch.optim.LBFGS`` as it did before :mod:`nurbskit.fit.optim`."""
    from nurbskit.fit import loop

    ours = loop.make_optimizer

    def make(stage, tensors):
        if stage.optimizer != "lbfgs":
            return ours(stage, tensors)
        # max_eval bounds the line search too (torch derives it from max_iter=1 as 1).
        return torch.optim.LBFGS(tensors, lr=stage.lr, max_iter=1, max_eval=25, history_size=20,
                                 line_search_fn="strong_wolfe", tolerance_grad=1e-14, tolerance_change=1e-16)

    loop.make_optimizer = make
    try:
        yield
    finally:
        loop.make_optimizer = ours


def fit_once(points, device: str, graphs: bool = True) -> dict:
    """One timed fit; ``graphs=False`` runs the loop's steps eagerly (``NURBSKIT_CUDA_GRAPHS=0``)."""
    from nurbskit.fit import fit_surface

    before = os.environ.get("NURBSKIT_CUDA_GRAPHS")
    os.environ["NURBSKIT_CUDA_GRAPHS"] = "1" if graphs else "0"
    try:
        _sync(device)
        t0, c0 = time.perf_counter(), time.process_time()
        result = fit_surface(points.to(device), _config(device))
        _sync(device)
        seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    finally:
        if before is None:
            del os.environ["NURBSKIT_CUDA_GRAPHS"]
        else:
            os.environ["NURBSKIT_CUDA_GRAPHS"] = before
    # the loop counts its loss evaluations per iteration (a replayed graph calls no loss function)
    evaluations = sum(h.get("evaluations", 0) for h in result.history)
    return {
        "result": result,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "loop_seconds": result.loop_seconds,
        "iterations": result.iterations,
        "evaluations_per_iteration": evaluations / max(result.iterations, 1),
        "alternation_rounds": len(result.alternation),
        "s_per_iteration": result.seconds_per_iteration,
        "cuda_graphs": sorted({h["cuda_graph"] for h in result.history if "cuda_graph" in h}),
    }


def count_per_iteration(points, device: str) -> dict:
    from nurbskit._opcount import OperationCounter
    from nurbskit.fit import fit_surface

    marks = []
    with OperationCounter() as count:
        fit_surface(points.to(device), _config(device),
                    callback=lambda progress: marks.append((count.operations, count.host_reads)))
    ops = [b[0] - a[0] for a, b in zip(marks, marks[1:])]
    reads = [b[1] - a[1] for a, b in zip(marks, marks[1:])]
    return {
        "ops_per_iteration": statistics.median(ops) if ops else 0,
        "host_reads_per_iteration": statistics.median(reads) if reads else 0,
        "host_read_ops": dict(count.host_reads_by_name),
        "ops_total": count.operations,
        "host_reads_total": count.host_reads,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5_000, 20_000, 100_000, 1_000_000])
    parser.add_argument("--skip-1m", action="store_true", help="skip sizes >= 1,000,000 (minutes on a small CPU)")
    parser.add_argument("--compare-cpu", action="store_true", help="also fit sizes <= 20k on the CPU and compare")
    parser.add_argument("--count-sizes", type=int, nargs="+", default=[5_000, 20_000],
                        help="sizes whose iterations are also counted (a second fit each)")
    parser.add_argument("--peer-optimizer", type=int, nargs="*", default=[5_000, 20_000],
                        help="sizes also fitted with torch.optim.LBFGS in the loop (the optimiser before)")
    parser.add_argument("--rounds", type=int, default=2,
                        help="rounds of alternating order in which both optimisers are timed (--peer-optimizer sizes)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-eager", action="store_true",
                        help="on CUDA, do not also time the fit with its steps run eagerly (NURBSKIT_CUDA_GRAPHS=0)")
    parser.add_argument("--out", help="also write the JSON rows here")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    device = args.device
    if device == "cuda" and not torch.cuda.is_available():
        print("CUDA requested but not available", file=sys.stderr)
        return 2
    sizes = [n for n in args.sizes if not (args.skip_1m and n >= 1_000_000)]

    fit_once(smooth_patch(300, 0.001, 99), device)  # warm-up
    rows = []
    for n in sizes:
        points = smooth_patch(n, 0.001, seed=0)
        run = fit_once(points, device)
        result = run.pop("result")
        if n in args.peer_optimizer:
            # Both optimisers timed in rounds of alternating order (ours first, then torch
            # first, ...): the machine's speed drifts, and the rounds share that drift.
            times = {"ours": [(run["seconds"], run["cpu_seconds"])], "torch": []}
            for r in range(args.rounds):
                for who in (("torch", "ours") if r % 2 == 0 else ("ours", "torch")):
                    if r == 0 and who == "ours":
                        continue  # the first fit above opened round 0
                    with torch_lbfgs() if who == "torch" else contextlib.nullcontext():
                        again = fit_once(points, device)
                    times[who].append((again["seconds"], again["cpu_seconds"]))
            run["seconds"] = statistics.median(t for t, _ in times["ours"])
            run["cpu_seconds"] = statistics.median(c for _, c in times["ours"])
            peer_times = times["torch"]
        row = {"points": n, "device": device, **run,
               "to_surface_mean": _mean_distance(result.surface, points, device)}
        if n in args.count_sizes:
            row.update(count_per_iteration(points, device))
        if device == "cuda" and not args.no_eager:
            # the same fit with the loop's steps launched one kernel at a time, in the same
            # process: what the CUDA graphs buy
            eager = fit_once(points, device, graphs=False)
            row["eager_seconds"] = eager["seconds"]
            row["x_eager"] = eager["seconds"] / row["seconds"]
            # the same device and parametrisation: control points compared directly (the
            # projection-based gap also measures where a fit folds near its edge)
            net = (result.surface.control_points - eager["result"].surface.control_points).abs().max()
            row["max_net_difference_vs_eager"] = float(net) / float((points.max(0).values - points.min(0).values).norm())
        if args.compare_cpu and device != "cpu" and n <= 20_000:
            cpu = fit_once(points, "cpu")
            row["cpu_fit_seconds"] = cpu["seconds"]
            row["cpu_iterations"] = cpu["iterations"]
            row["max_surface_difference_vs_cpu"] = _surface_gap(result.surface, cpu["result"].surface, points)
            row["cpu_to_surface_mean"] = _mean_distance(cpu["result"].surface, points, "cpu")
        row["optimizer"] = "nurbskit L-BFGS"
        rows.append(row)
        print(json.dumps(row), flush=True)
        if n in args.peer_optimizer:
            with torch_lbfgs():
                run = fit_once(points, device)
                result = run.pop("result")
                peer_times.append((run["seconds"], run["cpu_seconds"]))
                run["seconds"] = statistics.median(t for t, _ in peer_times)
                run["cpu_seconds"] = statistics.median(c for _, c in peer_times)
                peer = {"points": n, "device": device, "optimizer": "torch.optim.LBFGS", **run,
                        "to_surface_mean": _mean_distance(result.surface, points, device)}
                if n in args.count_sizes:
                    peer.update(count_per_iteration(points, device))
            rows.append(peer)
            print(json.dumps(peer), flush=True)

    columns = [
        ("points", "points"), ("optimizer", "optimizer"), ("seconds", "fit s"), ("cpu_seconds", "CPU s"),
        ("iterations", "loop iterations"), ("evaluations_per_iteration", "evaluations / iteration"),
        ("alternation_rounds", "alternation rounds"), ("s_per_iteration", "s / iteration"),
        ("ops_per_iteration", "aten ops / iteration"), ("host_reads_per_iteration", "host reads / iteration"),
        ("to_surface_mean", "to-surface mean / diag"), ("max_surface_difference_vs_cpu", "max gap to CPU fit / diag"),
    ]
    if device == "cuda":
        columns += [("eager_seconds", "fit s, steps eager"), ("x_eager", "x eager"),
                    ("max_net_difference_vs_eager", "max control-point gap to eager fit / diag"), ("cuda_graphs", "CUDA graphs")]
    notes = ("Default pipeline, float64, smooth patch with 0.1 % noise (bench_fit_goals.py); the fit uses a seeded "
             "random subset of at most 20,000 points (max_points). Ops and host reads per iteration: median over the "
             "loop iterations after the first, counted in a second fit (the L-BFGS line search included). "
             "torch.optim.LBFGS rows: the same fit with the optimiser the loop used before nurbskit.fit.optim, "
             f"in the same process; for those sizes both are timed in {args.rounds} rounds of alternating order "
             "and the seconds are medians.")
    if args.skip_1m and any(n >= 1_000_000 for n in args.sizes):
        notes += " The 1M-point size was skipped (--skip-1m)."
    write_results("fit_scale", rows, columns, meta={"device": device, "sizes": sizes},
                  title=f"Default fit at growing point counts ({device})", notes=notes,
                  subdir="gpu" if device == "cuda" else "")
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=2, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
