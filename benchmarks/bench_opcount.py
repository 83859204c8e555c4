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

Usage: python benchmarks/bench_opcount.py [--device cpu|cuda]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

from nurbskit import NURBSSurface  # noqa: E402
from nurbskit._opcount import OperationCounter  # noqa: E402

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
        for name, mode, make, call in cases:
            c = count(make, call)
            row = {"call": name, "knots": knots, "object": mode, "operations": c.operations,
                   "host_reads": c.host_reads, "host_read_ops": c.host_read_names(),
                   "top_ops": dict(c.by_name.most_common(5))}
            before = BEFORE.get((name, knots))
            if before and mode == "unchecked":
                row["operations_before"], row["host_reads_before"] = before
            rows.append(row)
            print(row, flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    args = parser.parse_args()
    rows = run(args.device)
    columns = [("call", "call"), ("knots", "knots"), ("object", "object"), ("operations", "aten ops"),
               ("host_reads", "host reads"), ("operations_before", "aten ops before"),
               ("host_reads_before", "host reads before")]
    write_results("opcount", rows, columns, meta={"device": args.device},
                  title="Operations and host reads per call (32 x 32 bicubic, float32)",
                  subdir="gpu" if args.device == "cuda" else "",
                  notes="OperationCounter around one call after a first call built the cached basis; "
                        "control points change before every call. 'before': commit 97a14e7.")


if __name__ == "__main__":
    main()
