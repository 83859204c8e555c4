"""How fast is surface evaluation, alone and in batches, against NURBS-Diff, geomdl and loops?

Question: degree-3 rational surfaces with 14 x 13 and 32 x 32 control points on 64^2,
256^2 and 512^2 parameter grids (2048^2 added on a GPU), float32: forward with fixed
knots (the basis comes from the cache after the first call; the surface unchecked, as
inside a loop), forward + backward to
control points and weights, and forward + backward with knot gradients too (the basis
is then rebuilt, vectorised over the degree, on every call). And a batch: 64 surfaces of
16 x 16 control points on 128^2 grids, forward and forward + backward, as one batched
call against a Python loop over the 64 surfaces.

Peers in the same process:

* NURBS-Diff v2 (``../shared/peers/nurbsdiff_v2``, its ``SurfEval`` layer with the
  basis precomputed for its own grid; skipped with the reason when the folder or
  ``einops`` is missing). Its samples run from 1e-8 to 1 - 1e-8; we report its time,
  the number of NaN it returns and its largest error against our float64 evaluation
  at its own parameters, never use it as an oracle.
* geomdl (pure Python, forward only, CPU) on every point of a 64^2 grid, per point.
* a naive loop (our own scattered evaluation called once per point), per point.
* a floor: the two dense matrix products a grid needs at least,
  ``(R x n)(n x n D)`` and ``(R D x n)(n x R)`` on precomputed operands.

On CUDA each grid also times the forward + backward step captured once as a CUDA graph
(``torch.cuda.graph``: the whole step, loss and backward included, replayed as one
launch; PyTorch's "whole-network capture"), ours and NURBS-Diff's alike (a peer that
cannot be captured is reported with the reason), and checks that the replayed gradients
equal the eager ones; and our forward alone captured the same way, against the two-GEMM
floor (which is timed eagerly: two launches). Eager, both are bound by per-operation
overhead at these sizes (``benchmarks/README.md``); the graph is what a training loop
with fixed shapes can use.

Loop overhead (the batch part): the loop's per-surface cost beyond the arithmetic, timed on a
2 x 2 grid, and the ceiling ``(arithmetic + 64 x overhead) / arithmetic`` it allows the
batch-vs-loop ratio (see ``loop_overhead``).

Page faults (the batch part, where ``resource`` exists): minor faults per call of each
fwd+bwd, counted over 20 calls after warm-up. The batch's buffers (16.8 MB for the
homogeneous grid, 12.6 MB for the samples and each of the loss's tensors) lie above
glibc's mmap threshold, so the allocator can hand their pages back to the kernel between
calls and each call faults them in again (zeroed); each loop element's buffers (about
260 KB) are reused from the heap. See ``benchmarks/README.md`` for what that costs and
the allocator settings that avoid it.

Usage: python benchmarks/bench_core_eval.py [--quick] [--device cpu|cuda] [--threads N] [--only grids|batch] [--peer PATH] [--tag NAME]
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit._opcount import OperationCounter  # noqa: E402
from nurbskit.core import to_geomdl  # noqa: E402

DEFAULT_PEER = Path(__file__).resolve().parents[1].parent / "shared" / "peers" / "nurbsdiff_v2"


def load_peer(path: Path):
    """NURBS-Diff's ``SurfEval`` class, or ``(None, reason)``."""
    if not path.is_dir():
        return None, f"peer folder {path} not found"
    sys.path.insert(0, str(path))
    try:
        module = importlib.import_module("NURBSDiff.surf_eval")
    except ImportError as exc:
        return None, f"NURBS-Diff could not be imported ({exc})"
    return module.SurfEval, ""


def make_surface(n_u: int, n_v: int, device: str, batch=(), seed: int = 0) -> NURBSSurface:
    rng = np.random.default_rng(seed)
    cp = torch.tensor(rng.normal(size=tuple(batch) + (n_u, n_v, 3)), dtype=torch.float32, device=device)
    w = torch.tensor(rng.uniform(0.5, 1.5, size=tuple(batch) + (n_u, n_v)), dtype=torch.float32, device=device)
    return NURBSSurface(cp, (3, 3), weights=w)


def homogeneous(s: NURBSSurface) -> torch.Tensor:
    w = s.weights.unsqueeze(-1)
    return torch.cat([s.control_points * w, w], dim=-1)


def floor_time(n: int, r: int, device: str, sync) -> float:
    """Two dense GEMMs of a grid on precomputed operands: the arithmetic floor."""
    g = torch.Generator(device=device).manual_seed(0)
    Bu = torch.rand(r, n, device=device, generator=g)
    P = torch.rand(n, n * 4, device=device, generator=g)
    Y = torch.rand(r * 4, n, device=device, generator=g)
    BvT = torch.rand(n, r, device=device, generator=g)

    def two():
        Bu.mm(P)
        Y.mm(BvT)

    return timeit(two, repeats=9, min_time=0.05, sync=sync)


def captured(step, leaves) -> tuple[object, str]:
    """``step()`` (forward, loss, backward) captured as a CUDA graph -> ``(graph.replay, "")``,
    or ``(None, why)`` when capture fails. Warm-up on a side stream, then ``.grad`` of
    ``leaves`` set to None so that the captured backward allocates them from the graph's
    pool: every replay writes the gradients of the current values of the (static) leaves
    into the same tensors (the pattern of PyTorch's CUDA-graphs notes)."""
    try:
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            for _ in range(3):
                step()
        torch.cuda.current_stream().wait_stream(side)
        for t in leaves:
            t.grad = None
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            step()
    except Exception as exc:  # noqa: BLE001 - a peer that cannot be captured is reported, not fatal
        return None, f"{type(exc).__name__}: {str(exc)[:200]}"
    return graph.replay, ""


def graph_rows(prefix: str, step, leaves, sync, reps: int) -> dict:
    """Time ``step`` captured as a CUDA graph, and the largest difference between the
    gradients of a replay and those of the eager step (both on the leaves' current values)."""
    replay, why = captured(step, leaves)
    if replay is None:
        return {f"{prefix}fwd_bwd_graph": f"not captured: {why}"}
    replay()
    sync()
    replayed = [t.grad.clone() for t in leaves]
    for t in leaves:
        t.grad = None
    step()
    diff = max(float((a - t.grad).abs().max()) for a, t in zip(replayed, leaves))
    return {f"{prefix}fwd_bwd_graph_ms": timeit(replay, repeats=reps, min_time=0.05, sync=sync) * 1e3,
            f"{prefix}graph_grad_diff": diff}


def peer_rows(SurfEval, base: NURBSSurface, r: int, device: str, sync, reps: int) -> dict:
    n_u, n_v = base.sizes
    layer = SurfEval(n_u - 1, n_v - 1, dimension=3, p=3, q=3, out_dim_u=r, out_dim_v=r, device=device)
    Pw = homogeneous(base).unsqueeze(0).contiguous()
    with torch.no_grad():
        out = layer(Pw)[0]
    # our float64 evaluation at the peer's own parameters
    ref = base.to(torch.float64).evaluate_grid(layer.u.double(), layer.v.double())
    nan = int(torch.isnan(out).sum())
    finite = torch.isfinite(out)
    err = float((out.double() - ref).abs()[finite].max()) if bool(finite.any()) else float("nan")
    Pg = Pw.clone().requires_grad_()

    def forward():
        with torch.no_grad():
            layer(Pw)

    def fwd_bwd():
        Pg.grad = None
        layer(Pg).square().sum().backward()

    t_f = timeit(forward, repeats=reps, min_time=0.05, sync=sync)
    t_fb = timeit(fwd_bwd, repeats=reps, min_time=0.05, sync=sync)
    row = {"nurbsdiff_forward_ms": t_f * 1e3, "nurbsdiff_fwd_bwd_ms": t_fb * 1e3,
           "nurbsdiff_nan": nan, "nurbsdiff_max_err": err, "nurbsdiff_outputs": int(out.numel())}
    if device.startswith("cuda"):
        row.update(graph_rows("nurbsdiff_", fwd_bwd, [Pg], sync, reps))
    return row


def run_grids(quick: bool, device: str, SurfEval, peer_reason: str) -> list[dict]:
    sync = torch.cuda.synchronize if device.startswith("cuda") else None
    sizes = [(14, 13), (32, 32)]
    grids = [64, 256] if quick else [64, 256, 512]
    if device.startswith("cuda"):
        grids = grids + [2048]
    rows = []
    for n_u, n_v in sizes:
        base = make_surface(n_u, n_v, device)
        geomdl_per_point = err = None
        if not device.startswith("cuda"):
            g = to_geomdl(base.to(torch.float64))
            side = 32 if quick else 64
            pts = [[float(a), float(b)] for a in np.linspace(0, 1, side) for b in np.linspace(0, 1, side)]
            geomdl_per_point = timeit(lambda: g.evaluate_list(pts), repeats=1 if quick else 3, warmup=0) / len(pts)
            ours = base.to(torch.float64).evaluate(torch.tensor(pts, dtype=torch.float64)).numpy()
            err = float(np.abs(np.asarray(g.evaluate_list(pts)) - ours).max())
        loop_pts = torch.rand(256 if quick else 1024, 2, device=device)
        loop_per_point = timeit(lambda: [base.evaluate(p[None]) for p in loop_pts], repeats=3, warmup=1,
                                sync=sync) / len(loop_pts)
        # Inside a loop (a fit, a network) splines are unchecked (validate=False); a validated
        # object adds one host read per call for the domain check.
        unchecked = base._replace(validate=False)
        for r in grids:
            u = torch.linspace(0, 1, r, device=device)
            n_points = r * r

            def forward():
                with torch.no_grad():
                    unchecked.evaluate_grid(u, u)

            cp = base.control_points.clone().requires_grad_()
            w = base.weights.clone().requires_grad_()
            kv = [k.clone().requires_grad_() for k in base.knot_vectors]

            def fwd_bwd():
                cp.grad = w.grad = None
                base._replace(control_points=cp, weights=w, validate=False).evaluate_grid(u, u).square().sum().backward()

            def fwd_bwd_knots():
                cp.grad = w.grad = None
                base._replace(control_points=cp, weights=w, knot_vectors=kv, validate=False).evaluate_grid(u, u).square().sum().backward()

            reps = 5 if quick else 15
            t_f = timeit(forward, repeats=reps, min_time=0.05, sync=sync)
            t_fb = timeit(fwd_bwd, repeats=reps, min_time=0.05, sync=sync)
            t_fbk = timeit(fwd_bwd_knots, repeats=reps if r < 2048 else 3, min_time=0.05, sync=sync)
            t_floor = floor_time(max(n_u, n_v), r, device, sync)
            row = {
                "control": f"{n_u}x{n_v}", "grid": f"{r}^2", "points": n_points,
                "forward_ms": t_f * 1e3, "fwd_bwd_ms": t_fb * 1e3, "fwd_bwd_knots_ms": t_fbk * 1e3,
                "points_per_s": n_points / t_f, "floor_ms": t_floor * 1e3, "x_floor": t_f / t_floor,
                "naive_loop_ms_est": loop_per_point * n_points * 1e3,
                "speedup_vs_naive_loop": loop_per_point * n_points / t_f,
            }
            if device.startswith("cuda"):
                row.update(graph_rows("", fwd_bwd, [cp, w], sync, reps))
                # the forward alone captured too: its kernels without the host's launch cost
                replay, why = captured(forward, [])
                if replay is not None:
                    row["forward_graph_ms"] = timeit(replay, repeats=reps, min_time=0.05, sync=sync) * 1e3
                    row["x_floor_graph"] = row["forward_graph_ms"] / row["floor_ms"]
            if geomdl_per_point is not None:
                row["geomdl_ms_est"] = geomdl_per_point * n_points * 1e3
                row["speedup_vs_geomdl"] = geomdl_per_point * n_points / t_f
                row["max_abs_diff_vs_geomdl_f64"] = err
            if SurfEval is not None and (n_u, n_v) == (32, 32):
                row.update(peer_rows(SurfEval, base, r, device, sync, reps))
                row["x_nurbsdiff_fwd_bwd"] = row["nurbsdiff_fwd_bwd_ms"] / row["fwd_bwd_ms"]
                row["x_nurbsdiff_forward"] = row["nurbsdiff_forward_ms"] / row["forward_ms"]
                if "fwd_bwd_graph_ms" in row:
                    row["x_nurbsdiff_eager_graph"] = row["nurbsdiff_fwd_bwd_ms"] / row["fwd_bwd_graph_ms"]
                    if "nurbsdiff_fwd_bwd_graph_ms" in row:
                        row["x_nurbsdiff_graph_graph"] = row["nurbsdiff_fwd_bwd_graph_ms"] / row["fwd_bwd_graph_ms"]
            elif SurfEval is None:
                row["nurbsdiff"] = f"skipped: {peer_reason}"
            rows.append(row)
            print(row, flush=True)
    return rows


def batch_calls(batch: NURBSSurface, singles: list, cp: torch.Tensor, w: torch.Tensor, r: int) -> dict:
    """The four calls the batch question times, on a grid of ``r^2``.

    ``bf`` / ``bfb``: the batch ``(64, n, n, 3)`` forward / forward + backward to ``cp`` and
    ``w`` (the batch's control points and weights, leaves); ``lf`` / ``lfb``: the same as a
    Python loop over ``singles``, element ``i`` taking ``cp[i]`` and ``w[i]``. The loss is
    ``square().sum()`` of the samples, summed over the elements in the loop.
    ``bench_core_versions.py`` times these same calls for several source trees.
    """
    def bf():
        with torch.no_grad():
            batch.sample(r)

    def bfb():
        cp.grad = w.grad = None
        batch._replace(control_points=cp, weights=w).sample(r).square().sum().backward()

    def lf():
        with torch.no_grad():
            for s in singles:
                s.sample(r)

    def lfb():
        cp.grad = w.grad = None
        total = 0
        for i, s in enumerate(singles):
            total = total + s._replace(control_points=cp[i], weights=w[i]).sample(r).square().sum()
        total.backward()

    return {"bf": bf, "bfb": bfb, "lf": lf, "lfb": lfb}


def loop_overhead(batch, singles, cp, w, r: int, reps: int, sync) -> dict:
    """What a loop pays per surface beyond the arithmetic, and the batch-vs-loop ceiling it allows.

    The loop's body (``_replace``, ``sample``, ``square``, ``sum``, the running total, and
    their backward nodes) is timed on a 2 x 2 grid, where the arithmetic is nothing: that
    is the per-call overhead. The arithmetic is the batched call's time less its own
    overhead (the batched call on a 2 x 2 grid). If the batch removed all of the loop's
    overhead and did the loop's arithmetic, the loop would take at most
    ``(arithmetic + 64 x overhead) / arithmetic`` times the batch: the ceiling of the ratio.
    Operations per loop iteration are counted with ``OperationCounter`` (they do not
    depend on the load).
    """
    count = len(singles)
    tiny, full = batch_calls(batch, singles, cp, w, 2), batch_calls(batch, singles, cp, w, r)

    looped_f = timeit(tiny["lf"], repeats=reps, min_time=0.05, sync=sync)
    batched_f = timeit(tiny["bf"], repeats=reps, min_time=0.05, sync=sync)
    looped_tiny = timeit(tiny["lfb"], repeats=reps, min_time=0.05, sync=sync)
    batched_tiny = timeit(tiny["bfb"], repeats=reps, min_time=0.05, sync=sync)
    batched_full = timeit(full["bfb"], repeats=reps, min_time=0.05, sync=sync)
    batched_full_f = timeit(full["bf"], repeats=reps, min_time=0.05, sync=sync)
    s0 = singles[0]
    s0.sample(r)
    with OperationCounter() as fwd_ops:
        with torch.no_grad():
            s0.sample(r)
    with OperationCounter() as body_ops:
        total = s0._replace(control_points=cp[0], weights=w[0]).sample(r).square().sum()
        total = total + 0
    with OperationCounter() as bwd_ops:
        total.backward()
    cp.grad = w.grad = None
    arith_fb = batched_full - batched_tiny
    arith_f = batched_full_f - batched_f
    return {
        "loop_overhead_us_per_surface_fwd": (looped_f - batched_f) / count * 1e6,
        "loop_overhead_us_per_surface_fwd_bwd": (looped_tiny - batched_tiny) / count * 1e6,
        "loop_ops_per_surface_fwd": fwd_ops.operations,
        "loop_ops_per_surface_fwd_bwd": body_ops.operations + bwd_ops.operations,
        "arithmetic_ms_fwd": arith_f * 1e3,
        "arithmetic_ms_fwd_bwd": arith_fb * 1e3,
        "ceiling_x_loop_fwd": (arith_f + (looped_f - batched_f)) / arith_f,
        "ceiling_x_loop_fwd_bwd": (arith_fb + (looped_tiny - batched_tiny)) / arith_fb,
    }


def faults_per_call(fn, calls: int = 20) -> float | None:
    """Minor page faults of this process per call of ``fn`` (after two warm-up calls); None
    where the ``resource`` module is missing (Windows)."""
    try:
        import resource
    except ImportError:
        return None
    for _ in range(2):
        fn()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(calls):
        fn()
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / calls


def run_batch(quick: bool, device: str, SurfEval) -> list[dict]:
    """64 surfaces of 16 x 16 at 128^2: one batched call against a loop over the surfaces."""
    sync = torch.cuda.synchronize if device.startswith("cuda") else None
    count, r = 64, 128
    batch = make_surface(16, 16, device, batch=(count,), seed=1)
    cp = batch.control_points.clone().requires_grad_()
    w = batch.weights.clone().requires_grad_()
    singles = [batch[i] for i in range(count)]
    reps = 3 if quick else 7

    calls = batch_calls(batch, singles, cp, w, r)

    # the batch equals the loop (same float32 arithmetic, another order)
    with torch.no_grad():
        diff = float((batch.sample(r) - torch.stack([s.sample(r) for s in singles])).abs().max())
    row = {"surfaces": count, "control": "16x16", "grid": f"{r}^2",
           "batched_forward_ms": timeit(calls["bf"], repeats=reps, min_time=0.05, sync=sync) * 1e3,
           "looped_forward_ms": timeit(calls["lf"], repeats=reps, min_time=0.05, sync=sync) * 1e3,
           "batched_fwd_bwd_ms": timeit(calls["bfb"], repeats=reps, min_time=0.05, sync=sync) * 1e3,
           "looped_fwd_bwd_ms": timeit(calls["lfb"], repeats=reps, min_time=0.05, sync=sync) * 1e3,
           "max_abs_diff_batch_vs_loop": diff}
    row["batched_faults_per_call"] = faults_per_call(calls["bfb"])
    row["looped_faults_per_call"] = faults_per_call(calls["lfb"])
    row["x_loop_forward"] = row["looped_forward_ms"] / row["batched_forward_ms"]
    row["x_loop_fwd_bwd"] = row["looped_fwd_bwd_ms"] / row["batched_fwd_bwd_ms"]
    row.update(loop_overhead(batch, singles, cp, w, r, reps, sync))
    if SurfEval is not None:
        layer = SurfEval(15, 15, dimension=3, p=3, q=3, out_dim_u=r, out_dim_v=r, device=device)
        Pg = homogeneous(batch).detach().clone().requires_grad_()

        def peer_fwd_bwd():
            Pg.grad = None
            layer(Pg).square().sum().backward()

        row["nurbsdiff_fwd_bwd_ms"] = timeit(peer_fwd_bwd, repeats=reps, min_time=0.05, sync=sync) * 1e3
    print(row, flush=True)
    return [row]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--peer", type=Path, default=DEFAULT_PEER, help="folder holding NURBSDiff (NURBS-Diff v2)")
    parser.add_argument("--only", choices=["grids", "batch"], help="run one part (writes only its results file)")
    parser.add_argument("--tag", default="", help="appended to the results files' names (a run under other settings)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    SurfEval, reason = load_peer(args.peer)
    if SurfEval is None:
        print(f"NURBS-Diff skipped: {reason}", flush=True)
    rows = run_grids(args.quick, args.device, SurfEval, reason) if args.only != "batch" else []
    batch_rows = run_batch(args.quick, args.device, SurfEval) if args.only != "grids" else []
    subdir = "gpu" if args.device == "cuda" else ""
    suffix = ("_quick" if args.quick else "") + (f"_{args.tag}" if args.tag else "")
    allocator = {k: v for k, v in os.environ.items() if k.startswith("MALLOC_") or k in ("LD_PRELOAD", "THP_MEM_ALLOC_ENABLE")}
    meta = {"device": args.device, "quick": args.quick, "dtype": "float32", "degree": 3, "allocator_env": allocator,
            "nurbsdiff": "ok" if SurfEval is not None else f"skipped: {reason}"}
    columns = [("control", "control"), ("grid", "grid"), ("forward_ms", "forward ms"),
               ("fwd_bwd_ms", "fwd+bwd ms (P, w)"), ("fwd_bwd_knots_ms", "fwd+bwd ms (P, w, knots)"),
               ("points_per_s", "points/s (forward)"), ("x_floor", "forward / 2-GEMM floor"),
               ("nurbsdiff_forward_ms", "NURBS-Diff fwd ms"), ("nurbsdiff_fwd_bwd_ms", "NURBS-Diff fwd+bwd ms"),
               ("x_nurbsdiff_fwd_bwd", "x NURBS-Diff (fwd+bwd)"), ("nurbsdiff_nan", "NURBS-Diff NaN"),
               ("nurbsdiff_max_err", "NURBS-Diff max err"), ("speedup_vs_geomdl", "x geomdl"),
               ("speedup_vs_naive_loop", "x naive loop")]
    if args.device == "cuda":
        columns += [("forward_graph_ms", "forward ms, CUDA graph"), ("x_floor_graph", "forward graph / floor"),
                    ("fwd_bwd_graph_ms", "fwd+bwd ms, CUDA graph"), ("graph_grad_diff", "graph vs eager grad diff"),
                    ("nurbsdiff_fwd_bwd_graph_ms", "NURBS-Diff fwd+bwd ms, CUDA graph"),
                    ("x_nurbsdiff_eager_graph", "NURBS-Diff eager / ours graph"),
                    ("x_nurbsdiff_graph_graph", "NURBS-Diff graph / ours graph"),
                    ("nurbsdiff_fwd_bwd_graph", "NURBS-Diff capture")]
    if rows:
        write_results("core_eval" + suffix, rows, columns, meta=meta,
                      title="Surface evaluation: forward and backward, degree 3, float32", subdir=subdir,
                      notes="Median of repeats after warm-up. Forward with fixed knots uses the cached basis. "
                            "NURBS-Diff v2 runs in the same process on its own grid (1e-8 inside the ends); its "
                            "error is against our float64 evaluation at its parameters. geomdl and the naive loop "
                            "run on a subset of points; their totals are per-point cost x points.")
    if batch_rows:
        write_results("core_batch" + suffix, batch_rows,
                      [("surfaces", "surfaces"), ("control", "control"), ("grid", "grid"),
                       ("batched_forward_ms", "batched fwd ms"), ("looped_forward_ms", "looped fwd ms"),
                       ("x_loop_forward", "x loop (fwd)"), ("batched_fwd_bwd_ms", "batched fwd+bwd ms"),
                       ("looped_fwd_bwd_ms", "looped fwd+bwd ms"), ("x_loop_fwd_bwd", "x loop (fwd+bwd)"),
                       ("loop_overhead_us_per_surface_fwd_bwd", "loop overhead us/surface (fwd+bwd)"),
                       ("loop_ops_per_surface_fwd_bwd", "loop ops/surface (fwd+bwd)"),
                       ("arithmetic_ms_fwd_bwd", "arithmetic ms (fwd+bwd)"),
                       ("ceiling_x_loop_fwd_bwd", "ceiling x loop (fwd+bwd)"),
                       ("ceiling_x_loop_fwd", "ceiling x loop (fwd)"),
                       ("nurbsdiff_fwd_bwd_ms", "NURBS-Diff fwd+bwd ms"),
                       ("batched_faults_per_call", "page faults/call, batched fwd+bwd"),
                       ("looped_faults_per_call", "page faults/call, looped fwd+bwd"),
                       ("max_abs_diff_batch_vs_loop", "max |batch - loop|")],
                      meta=meta, title="A batch of 64 surfaces against a loop, float32", subdir=subdir,
                      notes="One NURBSSurface with control points (64, 16, 16, 3) sampled on 128^2, against a "
                            "Python loop over the 64 single surfaces; forward + backward to control points and weights. "
                            "Loop overhead: the loop's time on a 2 x 2 grid less the batch's, per surface; arithmetic: "
                            "the batch at 128^2 less the batch at 2 x 2; ceiling = (arithmetic + 64 x overhead) / "
                            "arithmetic, the most a batch can gain over the loop when both do the same arithmetic. "
                            "Page faults: minor faults per call over 20 calls (see the module docstring).")


if __name__ == "__main__":
    main()
