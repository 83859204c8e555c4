"""Point-to-surface projection: vectorised Newton (core.project) against a per-point loop.

Question: how long does ``project_points`` take for 10^4 and 10^5 points on a 32 x 32
bicubic surface, how does that compare with the naive approach (``scipy.optimize.minimize``
point by point, from the same start), and how accurate is it?

Method: see README_projection.md. Usage:

    python benchmarks/bench_projection.py [--quick] [--threads 2] [--device cpu|cuda]
        [--sizes 10000 100000 1000000] [--naive-subset 300]

Also records, per row, the aten operations and host reads of one ``project_points`` call
(``nurbskit._opcount``, counted on a separate call of the same size): on a GPU each
operation is a kernel launch and each host read a stream synchronisation. Goal (issue
16): >= 1e7 points/s in float32 on a GPU, exact to 2e-16 (float64) / 1e-7 (float32).

Writes benchmarks/results/projection.json and projection.md (results/gpu/ for CUDA).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit.core.project import nearest_grid_params, project_points  # noqa: E402


def wavy_surface(n: int = 32, dtype=torch.float64, device="cpu") -> NURBSSurface:
    """A 32 x 32 bicubic height field over [0, 1]^2 with a few waves (curvature radius >~ 0.1)."""
    g = np.linspace(0.0, 1.0, n)
    u, v = np.meshgrid(g, g, indexing="ij")
    z = 0.08 * np.sin(2 * math.pi * 1.5 * u) * np.cos(2 * math.pi * v) + 0.05 * u * v
    cp = torch.tensor(np.stack([u, v, z], axis=-1), dtype=dtype, device=device)
    return NURBSSurface(cp, degrees=(3, 3))


def make_points(surface: NURBSSurface, count: int, seed: int):
    """Points at known distance: ``S(u, v) + t n(u, v)`` with ``|t| <= 0.02`` (well inside the
    reach of the surface, so ``|t|`` is the true distance), plus 10 % scattered beyond the
    edges (no closed form; judged against the naive loop)."""
    gen = torch.Generator().manual_seed(seed)
    inner = count - count // 10
    uv = torch.rand(inner, 2, generator=gen, dtype=torch.float64).to(surface.dtype).to(surface.device)
    t = (torch.rand(inner, generator=gen, dtype=torch.float64) * 0.04 - 0.02).to(surface.dtype).to(surface.device)
    with torch.no_grad():
        near = surface.evaluate(uv) + t[:, None] * surface.normals(uv)
    outer = torch.rand(count // 10, 3, generator=gen, dtype=torch.float64) * torch.tensor([1.6, 1.6, 0.4], dtype=torch.float64)
    outer = (outer - torch.tensor([0.3, 0.3, 0.2], dtype=torch.float64)).to(surface.dtype).to(surface.device)
    return torch.cat([near, outer]), t.abs(), inner


def naive_projection(surface: NURBSSurface, points: torch.Tensor, starts: torch.Tensor):
    """One ``scipy.optimize.minimize`` (L-BFGS-B, bounds = the domain) per point, objective and
    gradient from ``surface.derivatives`` on that single point: the per-point loop a
    vectorised kernel replaces."""
    from scipy.optimize import minimize

    bounds = surface.domain
    # stopping tests the dtype can meet (float32 gradients carry ~7 digits)
    double = surface.dtype == torch.float64
    options = {"ftol": 1e-15 if double else 1e-7, "gtol": 1e-12 if double else 1e-5, "maxiter": 200}
    out = []
    for x, t0 in zip(points, starts):
        def fun(t, x=x):
            d = surface.derivatives(torch.as_tensor(t, dtype=surface.dtype, device=surface.device)[None], order=1)[0]
            r = d[0, 0] - x
            grad = torch.stack([(2 * r * d[1, 0]).sum(), (2 * r * d[0, 1]).sum()])
            return float(r.square().sum()), grad.cpu().numpy()

        res = minimize(fun, t0.cpu().numpy(), jac=True, method="L-BFGS-B", bounds=bounds, options=options)
        out.append(res.x)
    params = torch.as_tensor(np.array(out), dtype=surface.dtype, device=surface.device)
    with torch.no_grad():
        return (surface.evaluate(params) - points).norm(dim=-1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes, fewer repeats (a smoke run)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--sizes", type=int, nargs="+", help="point counts (default 10^4 and 10^5; --quick 10^3, 10^4)")
    parser.add_argument("--naive-subset", type=int, help="points of the per-point scipy loop (default 300; 0 skips it)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    sync = torch.cuda.synchronize if device.type == "cuda" else None
    sizes = args.sizes or ([1_000, 10_000] if args.quick else [10_000, 100_000])
    repeats = 3 if args.quick else 5
    naive_subset = args.naive_subset if args.naive_subset is not None else (50 if args.quick else 300)
    from nurbskit._opcount import OperationCounter

    rows = []
    for dtype in (torch.float64, torch.float32):
        surface = wavy_surface(dtype=dtype, device=device)
        for n in sizes:
            points, true_distance, inner = make_points(surface, n, seed=n)
            with torch.no_grad():
                result = project_points(surface, points)
            seconds = timeit(lambda: project_points(surface.detach(), points), repeats=repeats, warmup=1, sync=sync)
            with OperationCounter() as count:
                project_points(surface.detach(), points)
            # accuracy against the known distances of the offset points
            err_known = (result.distance[:inner] - true_distance).abs()
            # first-order optimality of every result with a free (interior) foot point:
            # the residual is orthogonal to S_u and S_v; report the cosine of the angle
            d = surface.derivatives(result.params, order=1)
            r = result.closest - points
            lo = torch.tensor([a for a, _ in surface.domain], dtype=dtype, device=device)
            hi = torch.tensor([b for _, b in surface.domain], dtype=dtype, device=device)
            interior = ((result.params > lo) & (result.params < hi)).all(-1) & (r.norm(dim=-1) > 1e-6)
            cos = torch.stack([(r * d[:, 1, 0]).sum(-1) / (r.norm(dim=-1) * d[:, 1, 0].norm(dim=-1)),
                               (r * d[:, 0, 1]).sum(-1) / (r.norm(dim=-1) * d[:, 0, 1].norm(dim=-1))], -1).abs()
            # the naive loop on a subset (the same grid starts), timed once and scaled to n
            if naive_subset:
                pick = torch.linspace(0, n - 1, naive_subset).round().long().to(device)
                start_t = nearest_grid_params(surface, points[pick])
                surf64 = surface.detach()
                t0 = time.perf_counter()
                naive_d = naive_projection(surf64, points[pick], start_t)
                if sync:
                    sync()
                naive_seconds = (time.perf_counter() - t0) * n / naive_subset
                diff = (result.distance[pick] - naive_d)
            else:
                naive_seconds, diff = float("nan"), torch.full((1,), float("nan"))
            rows.append({
                "dtype": str(dtype).replace("torch.", ""),
                "points": n,
                "vectorised_s": seconds,
                "points_per_s": n / seconds,
                "naive_loop_s_scaled": naive_seconds,
                "naive_subset": naive_subset,
                "speedup": naive_seconds / seconds,
                "operations": count.operations,
                "host_reads": count.host_reads,
                "max_err_known_distance": float(err_known.max()),
                "median_err_known_distance": float(err_known.median()),
                "max_cos_residual_tangent": float(cos[interior].max()) if bool(interior.any()) else 0.0,
                "max_ours_minus_naive": float(diff.max()),
                "min_ours_minus_naive": float(diff.min()),
                "frac_ours_le_naive": float((diff <= 1e-9 if dtype == torch.float64 else diff <= 1e-5).float().mean()),
            })
            print(rows[-1], flush=True)

    columns = [
        ("dtype", "dtype"), ("points", "points"), ("vectorised_s", "project_points s (median)"),
        ("points_per_s", "points/s"), ("operations", "aten ops"), ("host_reads", "host reads"),
        ("naive_loop_s_scaled", "naive loop s (scaled)"), ("speedup", "speed-up"),
        ("max_err_known_distance", "max err vs known distance"), ("max_cos_residual_tangent", "max cos(residual, tangent)"),
        ("max_ours_minus_naive", "max (ours - naive)"), ("min_ours_minus_naive", "min (ours - naive)"),
        ("frac_ours_le_naive", "ours <= naive"),
    ]
    notes = ("32 x 32 bicubic height field; 90 % of the points at a known distance |t| <= 0.02 along the normal, "
             "10 % scattered beyond the edges. Vectorised: median of repeats after a warm-up. Naive: "
             "scipy L-BFGS-B per point from the same grid start, run on an evenly spaced subset and scaled "
             "to the full count. 'ours - naive' < 0 means Newton found the closer point.")
    write_results("projection", rows, columns, meta={"device": str(device), "quick": args.quick, "repeats": repeats,
                                                     "sizes": sizes, "naive_subset": naive_subset},
                  title="Point projection onto a 32 x 32 bicubic surface", notes=notes,
                  subdir="gpu" if device.type == "cuda" else "")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
