"""How fast is surface evaluation, with and without gradients, against geomdl and a naive loop?

Question: degree-3 surfaces with 14 x 13 and 32 x 32 control points on 64^2, 256^2
and 512^2 parameter grids, float32: forward, forward + backward to control points
and weights, and forward + backward with knot gradients too. Peers in the same
process: geomdl (pure Python, forward only) and a naive per-point loop (our own
scattered evaluation called once per point). Both peers are timed on a subset of
the points (every point of a 64^2 grid for geomdl, 1,024 points for the loop) and
reported per point; the ratio compares per-point costs.

Usage: python benchmarks/bench_core_eval.py [--quick] [--device cuda]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit.core import clamped_uniform, to_geomdl  # noqa: E402


def make_surface(n_u: int, n_v: int, device: str) -> NURBSSurface:
    rng = np.random.default_rng(0)
    cp = torch.tensor(rng.normal(size=(n_u, n_v, 3)), dtype=torch.float32, device=device)
    w = torch.tensor(rng.uniform(0.5, 1.5, size=(n_u, n_v)), dtype=torch.float32, device=device)
    return NURBSSurface(cp, (3, 3), weights=w)


def run(quick: bool, device: str) -> list[dict]:
    sync = torch.cuda.synchronize if device.startswith("cuda") else None
    sizes = [(14, 13), (32, 32)]
    grids = [64, 256] if quick else [64, 256, 512]
    if device.startswith("cuda"):
        grids = grids + [2048]
    rows = []
    for n_u, n_v in sizes:
        base = make_surface(n_u, n_v, device)
        # geomdl, per point, on a 64^2 grid (same surface in float64: geomdl has no float32)
        geomdl_per_point = None
        if not device.startswith("cuda"):
            g = to_geomdl(base.to(torch.float64))
            pts = [[float(a), float(b)] for a in np.linspace(0, 1, 32 if quick else 64) for b in np.linspace(0, 1, 32 if quick else 64)]
            geomdl_per_point = timeit(lambda: g.evaluate_list(pts), repeats=1 if quick else 3, warmup=0) / len(pts)
            # check agreement on those points while we are here
            ours = base.to(torch.float64).evaluate(torch.tensor(pts, dtype=torch.float64)).numpy()
            err = float(np.abs(np.asarray(g.evaluate_list(pts)) - ours).max())
        else:
            err = None
        # naive loop: one scattered evaluation per point
        loop_pts = torch.rand(256 if quick else 1024, 2, device=device)
        loop_per_point = timeit(lambda: [base.evaluate(p[None]) for p in loop_pts], repeats=3, warmup=1, sync=sync) / len(loop_pts)
        for r in grids:
            u = torch.linspace(0, 1, r, device=device)
            n_points = r * r

            def forward():
                with torch.no_grad():
                    base.evaluate_grid(u, u)

            cp = base.control_points.clone().requires_grad_()
            w = base.weights.clone().requires_grad_()
            kv = [k.clone().requires_grad_() for k in base.knot_vectors]

            def fwd_bwd():
                s = base._replace(control_points=cp, weights=w)
                s.evaluate_grid(u, u).square().sum().backward()

            def fwd_bwd_knots():
                s = base._replace(control_points=cp, weights=w, knot_vectors=kv)
                s.evaluate_grid(u, u).square().sum().backward()

            reps = 5 if quick else 15
            t_f = timeit(forward, repeats=reps, min_time=0.05, sync=sync)
            t_fb = timeit(fwd_bwd, repeats=reps, min_time=0.05, sync=sync)
            t_fbk = timeit(fwd_bwd_knots, repeats=reps, min_time=0.05, sync=sync)
            row = {
                "control": f"{n_u}x{n_v}", "grid": f"{r}^2", "points": n_points,
                "forward_ms": t_f * 1e3, "fwd_bwd_ms": t_fb * 1e3, "fwd_bwd_knots_ms": t_fbk * 1e3,
                "points_per_s": n_points / t_f,
                "naive_loop_ms_est": loop_per_point * n_points * 1e3,
                "speedup_vs_naive_loop": loop_per_point * n_points / t_f,
            }
            if geomdl_per_point is not None:
                row["geomdl_ms_est"] = geomdl_per_point * n_points * 1e3
                row["speedup_vs_geomdl"] = geomdl_per_point * n_points / t_f
                row["max_abs_diff_vs_geomdl_f64"] = err
            rows.append(row)
            print(row, flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    rows = run(args.quick, args.device)
    columns = [("control", "control"), ("grid", "grid"), ("forward_ms", "forward ms"),
               ("fwd_bwd_ms", "fwd+bwd ms (P, w)"), ("fwd_bwd_knots_ms", "fwd+bwd ms (P, w, knots)"),
               ("points_per_s", "points/s (forward)"), ("speedup_vs_geomdl", "x geomdl"),
               ("speedup_vs_naive_loop", "x naive loop")]
    subdir = "gpu" if args.device.startswith("cuda") else ""
    write_results("core_eval" + ("_quick" if args.quick else ""), rows, columns,
                  meta={"device": args.device, "quick": args.quick, "dtype": "float32", "degree": 3},
                  title="Surface evaluation: forward and backward, degree 3, float32", subdir=subdir,
                  notes="Median of repeats after warm-up. geomdl and the naive loop run on a subset of "
                        "points in the same process; their totals are per-point cost x points.")


if __name__ == "__main__":
    main()
