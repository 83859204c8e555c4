"""How many aten operations and host reads does one call of the core cost?

Question: per call of ``sample``, ``evaluate``, ``derivatives`` (and ``evaluate_grid``) on a
32 x 32 rational bicubic surface in float32, how many aten operations are dispatched and
how many of them read a value back to the host (``.item()``, ``bool(tensor)``,
``nonzero``, boolean-mask indexing)? On a GPU every operation is a kernel launch and every
host read a stream synchronisation, so these counts are the device-independent evidence
of overhead, and they do not depend on the load of the machine.

Method: ``nurbskit._opcount.OperationCounter`` (a ``TorchDispatchMode``) around the second
call (the first builds the cached basis); control points change before every counted
call, as in a fit. Cases: fixed knots (basis cached) and trainable knots (knots require
gradients: the basis is rebuilt, vectorised over the degree); an unchecked surface
(``validate=False`` or derived with ``_replace``, as in loops) and a validated one (the
domain check: one host read); a batch of 64 surfaces of 16 x 16. The "before" column is
the same count on the code before the batch/cache change (commit 97a14e7), measured once
with this script's cases and kept here as constants.

Cases added in the eighth session: forward + backward of a 256^2 sample (control points
and weights as leaves); ``project_points`` of 1,000 points with its defaults, and warm
from the last foot points with 2 first-order iterations (what the fit's refresh runs);
the objective of one fit iteration after the first (refresh, loss, backward).

Since the twelfth session each row also gives ``kernels``: the operations less the views
(``view``, ``expand``, ``slice``, ``unbind``, ``detach``, ...; ``OpOverload.is_view``),
which alias their input and launch nothing on a GPU. ``_unsafe_view`` (a reshape's view
of a fresh tensor) is not marked a view by its schema and stays counted as a kernel.

Usage: python benchmarks/bench_opcount.py [--device cpu|cuda] [--out FILE] [--session-start FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit._opcount import OperationCounter, count_fit_iterations  # noqa: E402
from nurbskit.core.project import project_points  # noqa: E402

# The commit the eighth session started from (its rows: --session-start).
SESSION_START = "b40661d"

# (operations, host reads) per call on commit 97a14e7, the code before this change.
BEFORE = {
    ("sample 64^2", "fixed"): (210, 4),
    ("sample 64^2", "trainable"): (212, 4),
    ("evaluate 500 points", "fixed"): (211, 0),
    ("evaluate 500 points", "trainable"): (211, 0),
    ("derivatives order 1, 500 points", "fixed"): (301, 0),
    ("derivatives order 1, 500 points", "trainable"): (301, 0),
}


def count(make, call) -> OperationCounter:
    """Operations of ``call(make())``, counted on a second object (the first call builds the
    cached basis); the object is made outside the counter, with new control points."""
    call(make())
    obj = make()
    with OperationCounter() as counter:
        call(obj)
    return counter


def run(device: str) -> list[dict]:
    g = torch.Generator().manual_seed(0)
    cp = torch.rand(32, 32, 3, generator=g).to(device)
    w = (torch.rand(32, 32, generator=g) + 0.5).to(device)
    checked = NURBSSurface(cp, (3, 3), weights=w)
    uv = torch.rand(500, 2, generator=g).to(device)
    u = torch.linspace(0, 1, 64, device=device)
    batch_cp = torch.rand(64, 16, 16, 3, generator=g).to(device)
    batch = NURBSSurface(batch_cp, (3, 3), validate=False)
    points = torch.rand(1000, 3, generator=g).to(device)
    with torch.no_grad():
        warm = project_points(checked, points).params  # foot points of the last iteration, as in a fit
    rows = []
    for knots in ("fixed", "trainable"):
        kvs = checked.knot_vectors if knots == "fixed" else [k.clone().requires_grad_() for k in checked.knot_vectors]
        state = {"step": 0}

        def moved(validate=False, kvs=kvs):
            state["step"] += 1  # new control points for every call, as in a fit
            s = checked._replace(control_points=cp + state["step"] * 1e-3, knot_vectors=kvs)
            s.validate = validate
            return s

        def checked_moved():
            return moved(True)

        def moved_leaf(kvs=kvs):
            # control points and weights as the leaves of a fit, knots as above
            state["step"] += 1
            P = (cp + state["step"] * 1e-3).requires_grad_()
            return checked._replace(control_points=P, weights=w.clone().requires_grad_(), knot_vectors=kvs)

        def sample_fwd_bwd(s):
            s.sample(256).square().sum().backward()

        cases = [
            ("sample 64^2", "unchecked", moved, lambda s: s.sample(64)),
            ("evaluate_grid 64^2", "unchecked", moved, lambda s: s.evaluate_grid(u, u)),
            ("evaluate_grid 64^2", "validated", checked_moved, lambda s: s.evaluate_grid(u, u)),
            ("evaluate 500 points", "unchecked", moved, lambda s: s.evaluate(uv)),
            ("evaluate 500 points", "validated", checked_moved, lambda s: s.evaluate(uv)),
            ("derivatives order 1, 500 points", "unchecked", moved, lambda s: s.derivatives(uv, order=1)),
            ("derivatives order 2, 500 points", "unchecked", moved, lambda s: s.derivatives(uv, order=2)),
        ]
        if knots == "fixed":
            def batch_moved():
                state["step"] += 1
                return batch._replace(control_points=batch_cp + state["step"] * 1e-3)

            cases.append(("batch of 64 (16x16): sample 64^2", "unchecked", batch_moved, lambda s: s.sample(64)))
            cases.append(("batch of 64 (16x16): evaluate 500 shared points", "unchecked", batch_moved,
                          lambda s: s.evaluate(uv)))
        cases.append(("sample 256^2, forward + backward", "unchecked", moved_leaf, sample_fwd_bwd))
        if knots == "fixed":
            cases.append(("project_points 1,000 points (defaults)", "unchecked", moved,
                          lambda s: project_points(s, points)))
            cases.append(("project_points 1,000 points, warm: 2 first-order iterations (a fit's refresh)",
                          "unchecked", moved, lambda s: project_points(
                              s, points, params=warm, periodic=(False, False), iterations=2, check_every=0,
                              validate=False, second_order=False)))
        for name, mode, make, call in cases:
            c = count(make, call)
            row = {"call": name, "knots": knots, "object": mode, "operations": c.operations,
                   "kernels": c.kernels, "host_reads": c.host_reads, "host_read_ops": c.host_read_names(),
                   "top_ops": dict(c.by_name.most_common(5))}
            before = BEFORE.get((name, knots))
            if before and mode == "unchecked":
                row["operations_before"], row["host_reads_before"] = before
            rows.append(row)
            print(row, flush=True)
    rows.append(fit_iteration(device))
    print(rows[-1], flush=True)
    return rows


def fit_iteration(device: str) -> dict:
    """The objective of one iteration of the default refine stage after the first (as in
    ``tests/test_fit_lstsq.py``): refresh the foot points, the loss, its backward; 2,000
    points near a 6 x 6 bicubic patch, trainable control points, weights and knots, float64.
    The optimiser's own operations are in ``bench_fit_scale.py``."""
    from nurbskit.core import NURBSSurface as Surface
    from nurbskit.fit.loop import Target
    from nurbskit.fit.params import SurfaceParameters, Topology
    from nurbskit.fit.pipelines import get_pipeline

    g = torch.Generator().manual_seed(30)
    t = torch.linspace(0, 1, 6, dtype=torch.float64)
    uu, vv = torch.meshgrid(t, t, indexing="ij")
    cp = torch.stack([uu, vv, 0.2 * torch.rand(6, 6, generator=g, dtype=torch.float64)], -1).to(device)
    s = Surface(cp, (3, 3))
    x = s.evaluate(torch.rand(2000, 2, generator=g, dtype=torch.float64).to(device))
    stage = get_pipeline("default").stages[0]
    params = SurfaceParameters(s, Topology(), train_weights=True, train_knots=True)
    counts, _ = count_fit_iterations(params, stage, Target(points=x), (24, 24))
    c = counts[-1]
    return {"call": "fit iteration: refresh + loss + backward (default refine, 2,000 points, float64)",
            "knots": "trainable", "object": "unchecked", "operations": c.operations, "kernels": c.kernels,
            "host_reads": c.host_reads,
            "host_read_ops": c.host_read_names(), "top_ops": dict(c.by_name.most_common(5))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--out", help="also write the rows as JSON here")
    parser.add_argument("--session-start", help="rows of this script run on the session's first commit "
                        "(its JSON from --out), shown beside")
    args = parser.parse_args()
    rows = run(args.device)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=2))
    columns = [("call", "call"), ("knots", "knots"), ("object", "object"), ("operations", "aten ops"),
               ("kernels", "kernels (ops less views)"), ("host_reads", "host reads"), ("operations_before", "aten ops before"),
               ("host_reads_before", "host reads before")]
    if args.session_start:
        start = {(r["call"], r["knots"], r["object"]): r for r in json.loads(Path(args.session_start).read_text())}
        for row in rows:
            old = start.get((row["call"], row["knots"], row["object"]))
            if old:
                row["operations_start"], row["host_reads_start"] = old["operations"], old["host_reads"]
        columns += [("operations_start", f"aten ops at {SESSION_START}"),
                    ("host_reads_start", f"host reads at {SESSION_START}")]
    write_results("opcount", rows, columns, meta={"device": args.device},
                  title="Operations and host reads per call (32 x 32 bicubic, float32)",
                  subdir="gpu" if args.device == "cuda" else "",
                  notes="OperationCounter around one call after a first call built the cached basis; "
                        "control points change before every call. 'before': commit 97a14e7. "
                        f"'at {SESSION_START}': this script on that commit (the eighth session's start), "
                        "run with --out and read back with --session-start.")


if __name__ == "__main__":
    main()
