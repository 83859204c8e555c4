"""The learned path of issue 11 (DeepSpline 3-D): how close is the network alone, how fast, and does it help the refinement?

Method.

* **Network, canonical** (the network's own question): a held-out set drawn from the
  training generator (:func:`nurbskit.shapes.nets.make_batch` with data seed 777, never a
  training seed: training draws step ``s`` of seed 0 with generator seed ``s``), ``--count``
  clouds per model, 2,000 points, Gaussian noise of exactly 0.5 % of the diagonal per
  coordinate (training used 0-1 %), already in the canonical frame (axis / direction =
  z, centred, unit ball). The network predicts the profile; the exact surface is built by
  the core's constructor; per cloud, the input-to-surface mean and p95 by true projection
  (:func:`nurbskit.metrics.surface_distances`) over the cloud's bounding-box diagonal.
  The image model sees the silhouette of the same shape (64 x 64) and is scored against
  the same cloud. Time: one batched forward over the set, per cloud, and one cloud alone
  (median of repeats, ``_harness.timeit``).
* **World pose** (what ``fit_shape(init="network")`` gets): the clouds of
  ``benchmarks/bench_shapes.py`` (``vase_cloud`` / ``extrusion_cloud`` alternately smooth
  and L, seeds 10_000 + i, random axis and position; profiles not from the training
  generator), 2,000 points, 0.5 % noise. Rows: ``initial_guess`` (search of the direction
  by Chamfer over 54 candidates, then the profile), the geometric start
  (``fit_shape(..., refine=False)``), and network then refinement
  (``fit_shape(..., init="network")``) when ``fit_shape`` has the ``init`` hook ("not run
  (hook not merged)" otherwise). Per cloud: the axis (direction) angle error in degrees,
  input-to-surface mean and p95 over the diagonal, seconds (wall clock, after a warm-up).

Reported: means over the clouds of the per-cloud mean and p95 (percent of the diagonal)
and medians of angles and times. The machine is a shared 2-core box (load average in the
results): milliseconds are inflated by the load, the distances are not.

Run: ``PYTHONPATH=src python benchmarks/bench_shapes_nets.py [--count 40] [--threads 1] [--name shapes_nets]``.
The issue asks for 500 clouds per kind; the committed run used fewer (``count``).
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit.learn import batch_generator, shipped_weights  # noqa: E402
from nurbskit.metrics import surface_distances  # noqa: E402
from nurbskit.shapes import fit_shape  # noqa: E402
from nurbskit.shapes.nets import guess_surface, initial_guess  # noqa: E402
from nurbskit.shapes.nets.data import exact_surface, normalise, random_profiles, sample_clouds, silhouettes  # noqa: E402
from nurbskit.shapes.nets.guess import load_model  # noqa: E402
from nurbskit.shapes.nets.training import model_name  # noqa: E402
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud  # noqa: E402

HELD_OUT_SEED = 777
NOISE = 0.005
POINTS = 2000


def _pct(values) -> float:
    return 100 * float(np.mean(values))


def canonical(kind: str, input: str, count: int) -> dict:
    name = model_name(kind, input)
    model = load_model(kind, input)
    images = input == "image"
    # make_batch's steps with exactly 0.5 % noise (make_batch draws it in [0, max_noise])
    g = batch_generator(HELD_OUT_SEED, 0)
    coords_true = random_profiles(g, count, kind)
    pts, centre, scale = normalise(sample_clouds(g, coords_true, kind, POINTS, NOISE))
    x = silhouettes(coords_true, centre, scale).float() if images else pts.float()
    with torch.no_grad():
        coords = model(x).double()
    means, p95s = [], []
    for b in range(count):
        d = surface_distances(exact_surface(kind, coords[b]), pts[b])
        means.append(d["to_surface_mean"])
        p95s.append(d["to_surface_p95"])
    with torch.no_grad():
        batch_ms = 1000 * timeit(lambda: model(x), repeats=3, warmup=1) / count
        one_ms = 1000 * timeit(lambda: model(x[:1]), repeats=7, warmup=2)
    return {"model": name, "kind": kind, "input": input, "method": "network, canonical", "count": count,
            "to_surface_mean_pct": _pct(means), "to_surface_p95_pct": _pct(p95s),
            "worst_cloud_mean_pct": 100 * max(means), "ms_per_cloud_batched": batch_ms, "ms_one_cloud": one_ms,
            "axis_deg_median": "", "status": "run"}


def _angle(a, b) -> float:
    a, b = a / a.norm(), b / b.norm()
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)))))


def _cloud(kind: str, i: int):
    seed = 10_000 + i
    if kind == "revolution":
        return vase_cloud(POINTS, NOISE, seed)
    return extrusion_cloud(POINTS, NOISE, seed, "L" if seed % 2 else "smooth")


def world(kind: str, count: int, has_hook: bool) -> list[dict]:
    per = {"network": [], "geometric": [], "refined": []}
    initial_guess(_cloud(kind, 9999 - 10_000).points, kind)  # warm-up (model load, imports)
    for i in range(count):
        c = _cloud(kind, i)
        t = time.perf_counter()
        guess = initial_guess(c.points, kind)
        sec = time.perf_counter() - t
        d = surface_distances(guess_surface(guess, kind), c.points)
        per["network"].append((_angle(guess["axis_direction"], c.axis_direction), d["to_surface_mean"],
                               d["to_surface_p95"], sec))
        t = time.perf_counter()
        geo = fit_shape(c.points, kind, refine=False)
        sec = time.perf_counter() - t
        per["geometric"].append((_angle(torch.as_tensor(geo.axis["direction"], dtype=torch.float64), c.axis_direction),
                                 geo.distance_mean, geo.distance_p95, sec))
        if has_hook:
            t = time.perf_counter()
            fit = fit_shape(c.points, kind, init="network")
            sec = time.perf_counter() - t
            per["refined"].append((_angle(torch.as_tensor(fit.axis["direction"], dtype=torch.float64),
                                          c.axis_direction), fit.distance_mean, fit.distance_p95, sec))
        print(kind, i, "network", [round(v, 5) for v in per["network"][-1]],
              "geometric", [round(v, 5) for v in per["geometric"][-1]], flush=True)
    labels = {"network": "network alone, world pose (initial_guess)",
              "geometric": "geometric start (fit_shape refine=False)",
              "refined": "network then refinement (fit_shape init='network')"}
    rows = []
    for key, label in labels.items():
        r = per[key]
        row = {"model": model_name(kind, "points") if key != "geometric" else "", "kind": kind, "input": "points",
               "method": label, "count": len(r)}
        if not r:
            row["status"] = "not run (hook not merged)"
            rows.append(row)
            continue
        ang, mean, p95, sec = zip(*r)
        row.update({"axis_deg_median": statistics.median(ang), "axis_deg_p95": float(np.percentile(ang, 95)),
                    "to_surface_mean_pct": _pct(mean), "to_surface_p95_pct": _pct(p95),
                    "worst_cloud_mean_pct": 100 * max(mean), "ms_one_cloud": 1000 * statistics.median(sec),
                    "status": "run"})
        rows.append(row)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=40, help="held-out clouds per model / kind")
    ap.add_argument("--world-count", type=int, default=None, help="world-pose clouds per kind (default --count)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--name", default="shapes_nets", help="results file name (results/NAME.json, .md)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    load = os.getloadavg()[0]
    has_hook = "init" in inspect.signature(fit_shape).parameters
    rows = []
    for kind, input in (("revolution", "points"), ("extrusion", "points"), ("revolution", "image")):
        if model_name(kind, input) in shipped_weights():
            rows.append(canonical(kind, input, args.count))
            print(rows[-1], flush=True)
    for kind in ("revolution", "extrusion"):
        if model_name(kind, "points") in shipped_weights():
            rows.extend(world(kind, args.world_count or args.count, has_hook))
    cols = [("kind", "kind"), ("input", "input"), ("method", "method"), ("count", "clouds"),
            ("to_surface_mean_pct", "in-to-surface mean (% diag)"), ("to_surface_p95_pct", "p95 (% diag)"),
            ("worst_cloud_mean_pct", "worst cloud mean (%)"), ("axis_deg_median", "axis err median (deg)"),
            ("axis_deg_p95", "axis err p95"), ("ms_one_cloud", "ms / cloud"),
            ("ms_per_cloud_batched", "ms / cloud, batched"), ("status", "status")]
    notes = (f"Held-out sets: canonical rows {args.count} clouds per model from the training generator "
             f"(data seed {HELD_OUT_SEED}); world rows {args.world_count or args.count} clouds per kind from "
             f"benchmarks/bench_shapes.py's generator (seeds 10000+i). The issue asks for 500 per kind. "
             f"{POINTS} points, noise {NOISE:.1%} of the diagonal per coordinate. Goals (issue 11): network "
             "alone within 2 % of the diagonal, <= 10 ms per cloud. Times are wall clock with "
             f"{args.threads} torch thread(s) on a shared 2-core machine, load average {load:.1f} at the "
             "start: inflated several times; distances do not depend on the load.")
    write_results(args.name, rows, cols,
                  meta={"count": args.count, "world_count": args.world_count or args.count, "noise": NOISE,
                        "points": POINTS, "held_out_seed": HELD_OUT_SEED, "load_average": load,
                        "init_hook": has_hook},
                  title="Shapes: the learned path (DeepSpline 3-D networks)", notes=notes)


if __name__ == "__main__":
    main()
