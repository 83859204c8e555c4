"""Projection onto a batch of surfaces in one pass against a Python loop over its elements (issue 16).

Question: what does ``project_points`` on a batch of surfaces (control points
``(Bt, n_u, n_v, 3)``, points ``(Bt, N, 3)``) save against calling it on each element?
Multi-patch fitting refits hundreds of small patches; a GPU pays per operation.

Method:

- Bt bicubic 8 x 8 rational patches (random heights and weights around a unit square,
  seeded), N = 500 points per patch near it (on the patch at random parameters, moved
  0.05 along random directions, 10 % of them beyond the edges), float64.
- Two calls per size, each timed batched and looped (median of repeats after a warm-up,
  2 threads, ``time.perf_counter``), with aten operations and host reads counted by
  ``nurbskit._opcount.OperationCounter`` (machine-independent):
  *cold*: the default call (start at the nearest grid sample, Newton until converged);
  *warm*: a fitting loop's refresh (start at the last foot points, 2 Gauss-Newton
  iterations, ``check_every=0``, ``periodic`` given, ``validate=False``).
- The batched result is checked against the loop: the foot-point parameters must be
  equal and the distances equal to rounding (largest difference reported).

Run: ``PYTHONPATH=src python benchmarks/bench_projection_batch.py [--device cpu|cuda] [--sizes 8 64 256]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit._opcount import OperationCounter  # noqa: E402
from nurbskit.core.project import project_points  # noqa: E402

N_POINTS = 500
CONTROL = 8


def patches(count: int, device: str, seed: int = 0):
    """A batch of ``count`` rational bicubic patches and ``N_POINTS`` points near each."""
    g = torch.Generator().manual_seed(seed)
    t = torch.linspace(0, 1, CONTROL, dtype=torch.float64)
    uu, vv = torch.meshgrid(t, t, indexing="ij")
    heights = 0.2 * torch.rand(count, CONTROL, CONTROL, generator=g, dtype=torch.float64)
    cp = torch.stack([uu.expand(count, -1, -1), vv.expand(count, -1, -1), heights], -1)
    w = 0.7 + 0.6 * torch.rand(count, CONTROL, CONTROL, generator=g, dtype=torch.float64)
    batch = NURBSSurface(cp, (3, 3), weights=w)
    uv = torch.rand(count, N_POINTS, 2, generator=g, dtype=torch.float64)
    x = batch.evaluate(uv) + 0.05 * torch.randn(count, N_POINTS, 3, generator=g, dtype=torch.float64)
    x[:, : N_POINTS // 10, :2] += 0.3  # a tenth beyond the edges: foot points on the boundary
    return batch.to(device), x.to(device)


def _counted(fn):
    with OperationCounter() as count:
        fn()
    return count.operations, count.host_reads


def run(count: int, device: str, sync) -> list[dict]:
    batch, x = patches(count, device)
    singles = [batch[i] for i in range(count)]
    first = project_points(batch, x)
    warm_opts = dict(iterations=2, check_every=0, periodic=(False, False), validate=False, second_order=False)
    calls = {
        "cold": (lambda: project_points(batch, x),
                 lambda: [project_points(s, x[i]) for i, s in enumerate(singles)]),
        "warm": (lambda: project_points(batch, x, params=first.params, **warm_opts),
                 lambda: [project_points(s, x[i], params=first.params[i], **warm_opts) for i, s in enumerate(singles)]),
    }
    rows = []
    for name, (batched, looped) in calls.items():
        res, parts = batched(), looped()
        same = all(torch.equal(res.params[i], p.params) for i, p in enumerate(parts))
        diff = max(float((res.distance[i] - p.distance).abs().max()) for i, p in enumerate(parts))
        reps = 5 if count * N_POINTS <= 32_000 else 3
        tb = timeit(batched, repeats=reps, warmup=1, sync=sync)
        tl = timeit(looped, repeats=reps, warmup=1, sync=sync)
        ob, hb = _counted(batched)
        ol, hl = _counted(looped)
        rows.append({"call": name, "surfaces": count, "points_per_surface": N_POINTS, "batched_ms": tb * 1e3,
                     "looped_ms": tl * 1e3, "x_loop": tl / tb, "batched_ops": ob, "looped_ops": ol,
                     "batched_host_reads": hb, "looped_host_reads": hl, "params_equal": same,
                     "max_abs_distance_diff": diff})
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 64, 256])
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    sync = torch.cuda.synchronize if args.device == "cuda" else None
    rows = [r for count in args.sizes for r in run(count, args.device, sync)]
    columns = [("call", "call"), ("surfaces", "surfaces"), ("points_per_surface", "points each"),
               ("batched_ms", "batched ms"), ("looped_ms", "looped ms"), ("x_loop", "x loop"),
               ("batched_ops", "batched aten ops"), ("looped_ops", "looped aten ops"),
               ("batched_host_reads", "batched host reads"), ("looped_host_reads", "looped host reads"),
               ("params_equal", "params equal"), ("max_abs_distance_diff", "max |distance diff|")]
    write_results("projection_batch", rows, columns, meta={"device": args.device},
                  subdir="gpu" if args.device == "cuda" else "",
                  title="Projection onto a batch of surfaces: one pass against a loop",
                  notes=__doc__.split("Method:")[1].split("Run:")[0].strip())


if __name__ == "__main__":
    main()
