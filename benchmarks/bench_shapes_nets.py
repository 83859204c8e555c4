"""The learned path of issue 11 (DeepSpline 3-D): how close is the network alone, how fast, and does it help the refinement?

Method.

* **World pose** (the issue's held-out synthetic set, and what ``fit_shape(init="network")``
  gets): the clouds of ``benchmarks/bench_shapes.py``, same definition and seeds
  (``vase_cloud`` for revolutions; ``extrusion_cloud`` with an L profile for odd seeds, a
  smooth cubic wave for even ones; seed ``10_000 + i``, random axis and position),
  ``--count`` clouds per kind (the issue: 500), 2,000 points, Gaussian noise of 0.5 % of
  the diagonal per coordinate. These profiles are not from the training generator, and
  no training seed draws them (training uses ``make_batch`` with generator seeds
  ``batch_generator(0, step)``). Rows:

  - **network alone** (``initial_guess`` then ``guess_surface``: from the raw world cloud
    to an exact surface): the direction from the shape package's normals estimators on
    400 points (``direction="normals"``, the default), the profile by the network;
  - **network alone, direction searched by the network** (``direction="search"``: 54
    candidate directions scored by Chamfer, the learned path with no geometric help);
  - **network then refinement** (``fit_shape(points, kind, init="network")``: the
    shape fitter's refinement, 30 L-BFGS iterations by default);
  - optionally (``--geometric``) the geometric start (``fit_shape(refine=False)``); the
    geometric path's own 500-cloud run is ``bench_shapes.py``'s.

  Per cloud: the axis (direction) angle error in degrees; input-to-surface mean and
  95th percentile by true projection (:func:`nurbskit.metrics.surface_distances`) over
  the cloud's bounding-box diagonal; the **noise floor** (the same mean for the TRUE
  surface: no surface does much better on average); seconds, wall clock and CPU
  (``time.process_time`` of the process: load-independent up to cache effects), after a
  warm-up cloud per worker. Reported: the mean over clouds of the per-cloud mean and p95
  (percent of the diagonal), the worst cloud's mean, medians of angles and times.
* **Network, canonical** (the network's own question): a held-out set drawn from the
  training generator (:func:`nurbskit.shapes.nets.data.random_profiles` /
  ``sample_clouds`` with data seed 777, never a training seed), ``--canonical-count``
  clouds per model, 2,000 points, noise exactly 0.5 %, already in the canonical frame.
  The image model sees the silhouette of the same shape (64 x 64) and is scored against
  the same cloud. Time: one batched forward over the set per cloud, and one cloud alone
  (median of repeats), wall and CPU.
* **Fixed batch** (what ``tests/test_shapes_nets.py`` recomputes): per model, the mean
  input-to-surface distance on ``make_batch(batch_generator(123, 0), 8, kind, 600,
  max_noise=0.005)``; per kind, ``initial_guess`` on world clouds 0 and 1 (axis error and
  mean). Stored in the results' ``meta.fixed_batch`` and printed; the test asserts the
  shipped weights reproduce them.

Work is spread over ``--jobs`` worker processes with one torch thread each: first the
network-alone rows of every cloud (kinds alternating), then the canonical sets, then the
refinement of the first ``--refine-count`` clouds per kind (2-3 CPU seconds each, the
bulk of the run); the results are rewritten every 100 light or 20 refinement tasks, so a run stopped early leaves
a consistent table, each row with its own count. Run it niced: the machine is shared.

**Timing only** (``--timing-only``, the number the 10 ms goal is about): the network alone
on ``--count`` world clouds per kind in one process of one torch thread, median CPU ms per
cloud after a warm-up, and its aten operations and host reads per call
(``nurbskit._opcount``, load-independent); with ``--compare SRC`` the nurbskit source tree
``SRC`` (e.g. an export of the commit before a change: ``git archive COMMIT src | tar -x -C
/tmp/old``) is timed too, the two alternating ``--rounds`` times in fresh processes so that
both see the same load, and the ratio after / before is reported. Quiet-machine rerun:
``PYTHONPATH=src python benchmarks/bench_shapes_nets.py --timing-only --count 100 --name
shapes_nets_timing`` (add ``--compare /tmp/old/src --rounds 3`` for before/after).

Run: ``PYTHONPATH=src nice -n 10 python benchmarks/bench_shapes_nets.py [--count 500]
[--search-count 500] [--refine-count 500] [--canonical-count 500] [--jobs 2] [--geometric]
[--no-refine] [--name shapes_nets]``. The committed run's counts are in its table (the
machine is shared: the refinement rows cover fewer clouds than the issue's 500).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import timeit, write_results  # noqa: E402

from nurbskit.learn import batch_generator, shipped_weights  # noqa: E402
from nurbskit.metrics import surface_distances  # noqa: E402
from nurbskit.shapes import fit_shape  # noqa: E402
from nurbskit.shapes.nets import guess_surface, initial_guess, make_batch  # noqa: E402
from nurbskit.shapes.nets.data import exact_surface, normalise, random_profiles, sample_clouds, silhouettes  # noqa: E402
from nurbskit.shapes.nets.guess import load_model  # noqa: E402
from nurbskit.shapes.nets.training import model_name  # noqa: E402
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud  # noqa: E402

HELD_OUT_SEED = 777
NOISE = 0.005
POINTS = 2000
MODELS = (("revolution", "points"), ("extrusion", "points"), ("revolution", "image"))
FIXED_WORLD = (0, 1)  # world clouds whose initial_guess numbers the test recomputes
CHUNK = 50  # canonical clouds per task


def _pct(values) -> float:
    return 100 * float(np.mean(values))


def _angle(a, b) -> float:
    a = torch.as_tensor(a, dtype=torch.float64)
    b = torch.as_tensor(b, dtype=torch.float64)
    return math.degrees(math.acos(min(1.0, abs(float(a @ b) / float(a.norm() * b.norm())))))


def world_cloud(kind: str, i: int):
    """Cloud ``i`` of ``kind``: the definition of ``bench_shapes.py`` (seed ``10_000 + i``)."""
    seed = 10_000 + i
    if kind == "revolution":
        return vase_cloud(POINTS, NOISE, seed)
    return extrusion_cloud(POINTS, NOISE, seed, "L" if seed % 2 else "smooth")


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def network_alone(points, kind: str, direction: str = "normals") -> tuple:
    """``(guess, surface)``: everything from the raw world cloud to the exact surface."""
    guess = initial_guess(points, kind, direction=direction)
    return guess, guess_surface(guess, kind)


def fixed_world(kind: str) -> list[dict]:
    """``initial_guess`` on the world clouds :data:`FIXED_WORLD` (the test's fixed batch)."""
    out = []
    for i in FIXED_WORLD:
        c = world_cloud(kind, i)
        guess, surface = network_alone(c.points, kind)
        out.append({"cloud": i, "axis_deg": _angle(guess["axis_direction"], c.axis_direction),
                    "to_surface_mean": surface_distances(surface, c.points)["to_surface_mean"]})
    return out


def fixed_canonical(kind: str, input: str) -> float:
    """Mean input-to-surface (% diag) of the model on the test's fixed batch of 8 clouds."""
    model = load_model(kind, input)
    batch = make_batch(batch_generator(123, 0), 8, kind, 600, images=input == "image", max_noise=0.005)
    with torch.no_grad():
        coords = model(batch["images"] if input == "image" else batch["points"]).double()
    means = [surface_distances(exact_surface(kind, coords[b]), batch["points"][b].double(), 32)["to_surface_mean"]
             for b in range(8)]
    return 100 * sum(means) / 8


# --- worker tasks (one torch thread each) ------------------------------------------------


def _init_worker() -> None:
    torch.set_num_threads(1)


_WARM: set = set()


def _warm(kind: str) -> None:
    if kind not in _WARM:
        c = world_cloud(kind, 99_999)
        network_alone(c.points, kind)
        fit_shape(c.points, kind, init="network", iterations=1)
        _WARM.add(kind)


def world_task(kind: str, i: int, parts: tuple) -> dict:
    """The rows ``parts`` (keys of :data:`LABELS`, plus "floor") for world cloud ``i``."""
    _warm(kind)  # model load and imports, once per worker and kind
    c = world_cloud(kind, i)
    out = {"kind": kind, "cloud": i}
    if "floor" in parts:
        out["noise_floor"] = surface_distances(c.surface, c.points)["to_surface_mean"]

    def record(key, direction, surface, wall, cpu):
        d = surface_distances(surface, c.points)
        out[key] = {"axis_deg": _angle(direction, c.axis_direction), "wall": wall, "cpu": cpu,
                    "mean": d["to_surface_mean"], "p95": d["to_surface_p95"]}

    for key, direction in (("network", "normals"), ("search", "search")):
        if key in parts:
            (guess, surface), w, cp = _timed(lambda: network_alone(c.points, kind, direction))
            record(key, guess["axis_direction"], surface, w, cp)
            out[key]["direction_from"] = guess["direction_from"]
    for key, opts in (("refined", {"init": "network"}), ("geometric", {"refine": False})):
        if key in parts:
            fit, w, cp = _timed(lambda: fit_shape(c.points, kind, **opts))
            out[key] = {"axis_deg": _angle(fit.axis["direction"], c.axis_direction), "wall": w, "cpu": cp,
                        "mean": fit.distance_mean, "p95": fit.distance_p95}
    return out


def canonical_data(kind: str, input: str, count: int):
    g = batch_generator(HELD_OUT_SEED, 0)
    coords_true = random_profiles(g, count, kind)
    pts, centre, scale = normalise(sample_clouds(g, coords_true, kind, POINTS, NOISE))
    x = silhouettes(coords_true, centre, scale).float() if input == "image" else pts.float()
    return pts, x


def canonical_task(kind: str, input: str, count: int, start: int) -> list[tuple[float, float]]:
    pts, x = canonical_data(kind, input, count)
    stop = min(count, start + CHUNK)
    with torch.no_grad():
        coords = load_model(kind, input)(x[start:stop]).double()
    out = []
    for b in range(stop - start):
        d = surface_distances(exact_surface(kind, coords[b]), pts[start + b])
        out.append((d["to_surface_mean"], d["to_surface_p95"]))
    return out


# --- summary -----------------------------------------------------------------------------

LABELS = {"network": "network alone, world pose (direction from normals, profile by the network)",
          "search": "network alone, world pose (direction searched by the network)",
          "refined": "network then refinement (fit_shape init='network')",
          "geometric": "geometric start (fit_shape refine=False)"}


def world_rows(raw: list[dict]) -> list[dict]:
    rows = []
    for kind in ("revolution", "extrusion"):
        r = [x for x in raw if x["kind"] == kind]
        if not r:
            continue
        for key, label in LABELS.items():
            m = [x[key] for x in r if key in x]
            if not m:
                continue
            floor = _pct([x["noise_floor"] for x in r if key in x])  # over the same clouds
            ang = [v["axis_deg"] for v in m]
            row = {"model": model_name(kind, "points") if key != "geometric" else "", "kind": kind,
                   "input": "points", "method": label, "count": len(m),
                   "axis_deg_median": statistics.median(ang), "axis_deg_p95": float(np.percentile(ang, 95)),
                   "to_surface_mean_pct": _pct([v["mean"] for v in m]),
                   "to_surface_p95_pct": _pct([v["p95"] for v in m]),
                   "worst_cloud_mean_pct": 100 * max(v["mean"] for v in m), "noise_floor_pct": floor,
                   "ms_wall": 1000 * statistics.median(v["wall"] for v in m),
                   "ms_cpu": 1000 * statistics.median(v["cpu"] for v in m),
                   "ms_cpu_p95": 1000 * float(np.percentile([v["cpu"] for v in m], 95)), "status": "run"}
            if key == "network":
                row["direction_from_normals"] = sum(v["direction_from"] == "normals" for v in m)
            rows.append(row)
    return rows


def canonical_row(kind: str, input: str, count: int, results: list) -> dict:
    means, p95s = zip(*results)
    _, x = canonical_data(kind, input, count)
    model = load_model(kind, input)

    def cpu_timeit(fn, repeats):
        fn()
        c = time.process_time()
        for _ in range(repeats):
            fn()
        return (time.process_time() - c) / repeats

    with torch.no_grad():
        one = x[:1]
        row = {"model": model_name(kind, input), "kind": kind, "input": input, "method": "network, canonical",
               "count": len(means), "to_surface_mean_pct": _pct(means), "to_surface_p95_pct": _pct(p95s),
               "worst_cloud_mean_pct": 100 * max(means),
               "ms_wall": 1000 * timeit(lambda: model(one), repeats=15, warmup=3),
               "ms_cpu": 1000 * cpu_timeit(lambda: model(one), 15),
               "ms_batched_wall": 1000 * timeit(lambda: model(x), repeats=3, warmup=1) / count,
               "ms_batched_cpu": 1000 * cpu_timeit(lambda: model(x), 3) / count, "status": "run"}
    return row


COLUMNS = [("kind", "kind"), ("input", "input"), ("method", "method"), ("count", "clouds"),
           ("axis_deg_median", "axis err median (deg)"), ("axis_deg_p95", "axis err p95"),
           ("to_surface_mean_pct", "in-to-surface mean (% diag)"), ("to_surface_p95_pct", "p95 (% diag)"),
           ("worst_cloud_mean_pct", "worst cloud mean (%)"), ("noise_floor_pct", "noise floor mean (%)"),
           ("ms_cpu", "ms / cloud, CPU"), ("ms_wall", "ms / cloud, wall"), ("ms_batched_cpu", "ms / cloud batched, CPU")]


# --- network-alone timing (--timing-only) -----------------------------------------------


def time_network_alone(count: int) -> dict:
    """Per kind, in this process (one torch thread): the network alone (``network_alone``) on
    world clouds ``0 .. count - 1`` after a warm-up cloud: median and p95 CPU ms
    (``time.process_time``), median wall ms, and the aten operations and host reads of one
    call (``nurbskit._opcount``, load-independent). Uses only what every version of the
    learned path has (``initial_guess``, ``guess_surface``), so a worker run against an
    older source tree times that tree."""
    from nurbskit._opcount import OperationCounter

    torch.set_num_threads(1)
    out = {}
    for kind in ("revolution", "extrusion"):
        clouds = [world_cloud(kind, i).points for i in range(count)]
        network_alone(world_cloud(kind, 99_999).points, kind)  # model load, first calls
        cpu, wall = [], []
        for points in clouds:
            _, w, c = _timed(lambda: network_alone(points, kind))
            cpu.append(c)
            wall.append(w)
        with OperationCounter() as ops:
            network_alone(clouds[min(1, count - 1)], kind)
        out[kind] = {"ms_cpu": 1000 * statistics.median(cpu), "ms_cpu_p95": 1000 * float(np.percentile(cpu, 95)),
                     "ms_wall": 1000 * statistics.median(wall), "operations": ops.operations,
                     "host_reads": ops.host_reads}
    return out


def timing_only(args) -> None:
    """``--timing-only``: the network alone's time per cloud in one process, one thread; with
    ``--compare SRC`` also that of the nurbskit source tree ``SRC`` (the version before a
    change), the two run alternately ``--rounds`` times in fresh worker processes (this script
    with ``--timing-worker`` and ``PYTHONPATH`` set to each tree), so that both see the same
    load: medians over rounds of each round's median, and the ratio after / before."""
    import json
    import subprocess

    here = str(Path(__file__).resolve().parents[1] / "src")
    trees = [("after", here)] if args.compare is None else [("before", str(Path(args.compare).resolve())), ("after", here)]
    rounds = {label: [] for label, _ in trees}
    load_start = os.getloadavg()[0]
    for r in range(args.rounds if args.compare else 1):
        for label, src in trees:
            env = dict(os.environ, PYTHONPATH=src, OMP_NUM_THREADS="1")
            res = subprocess.run([sys.executable, __file__, "--timing-worker", "--count", str(args.count)],
                                 env=env, check=True, capture_output=True, text=True)
            rounds[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(label, r, rounds[label][-1], flush=True)
    rows = []
    for kind in ("revolution", "extrusion"):
        for label, src in trees:
            per = [x[kind] for x in rounds[label]]
            rows.append({"kind": kind, "version": label, "source": src, "count": args.count, "rounds": len(per),
                         "ms_cpu": statistics.median(x["ms_cpu"] for x in per),
                         "ms_cpu_rounds": [round(x["ms_cpu"], 3) for x in per],
                         "ms_wall": statistics.median(x["ms_wall"] for x in per),
                         "operations": per[0]["operations"], "host_reads": per[0]["host_reads"]})
        if args.compare:
            before, after = rows[-2], rows[-1]
            after["ratio_cpu"] = after["ms_cpu"] / before["ms_cpu"]
            after["ratio_cpu_rounds"] = [round(a / b, 3) for a, b in zip(after["ms_cpu_rounds"], before["ms_cpu_rounds"])]
            after["ratio_operations"] = after["operations"] / before["operations"]
    cols = [("kind", "kind"), ("version", "version"), ("count", "clouds"), ("rounds", "rounds"),
            ("ms_cpu", "ms / cloud, CPU (median of round medians)"), ("ms_cpu_rounds", "per round"),
            ("ms_wall", "ms / cloud, wall"), ("operations", "aten ops / call"), ("host_reads", "host reads / call"),
            ("ratio_cpu", "after / before, CPU"), ("ratio_cpu_rounds", "per round"),
            ("ratio_operations", "after / before, ops")]
    notes = (f"The network alone (initial_guess then guess_surface, direction from normals) on world clouds 0..{args.count - 1} "
             "per kind (bench_shapes.py's definition, 2,000 points, 0.5 % noise), one process of one torch thread "
             "per measurement, CPU time (time.process_time) per cloud after a warm-up cloud; operation counts by "
             "nurbskit._opcount (one call, load-independent). "
             + (f"Before = the nurbskit source tree {args.compare}, after = this tree, run alternately "
                f"{args.rounds} times. " if args.compare else "")
             + f"Load average {load_start:.1f} at the start and {os.getloadavg()[0]:.1f} at the end. "
             "Goal (issue 11): <= 10 ms per cloud on the quiet machine.")
    write_results(args.name, rows, cols, meta={"count": args.count, "rounds": args.rounds, "compare": args.compare,
                                               "load_average_start": load_start, "load_average_end": os.getloadavg()[0]},
                  title="Shapes: the network alone, time per cloud", notes=notes)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=40, help="world-pose clouds per kind (the issue: 500)")
    ap.add_argument("--canonical-count", type=int, default=None, help="held-out canonical clouds per model (default --count)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes, one torch thread each")
    ap.add_argument("--no-search", action="store_true", help="skip the direction='search' rows")
    ap.add_argument("--no-refine", action="store_true", help="skip network then refinement")
    ap.add_argument("--search-count", type=int, default=None,
                    help="clouds per kind with the direction='search' rows (the first ones; default --count)")
    ap.add_argument("--refine-count", type=int, default=None,
                    help="clouds per kind refined (the first ones; default --count): 2-3 CPU s each")
    ap.add_argument("--geometric", action="store_true", help="also the geometric start (fit_shape refine=False)")
    ap.add_argument("--name", default="shapes_nets", help="results file name (results/NAME.json, .md)")
    ap.add_argument("--timing-only", action="store_true",
                    help="only the network alone's time per cloud (and op counts), one process, one thread")
    ap.add_argument("--compare", metavar="SRC", default=None,
                    help="--timing-only: also time the nurbskit source tree SRC (before), alternating with this one")
    ap.add_argument("--rounds", type=int, default=3, help="--timing-only --compare: alternations")
    ap.add_argument("--timing-worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.timing_worker:
        import json

        print(json.dumps(time_network_alone(args.count)))
        return
    if args.timing_only:
        timing_only(args)
        return
    torch.set_num_threads(1)
    ccount = args.canonical_count or args.count
    load_start = os.getloadavg()[0]
    models = [(k, i) for k, i in MODELS if model_name(k, i) in shipped_weights()]
    kinds = [k for k in ("revolution", "extrusion") if model_name(k, "points") in shipped_weights()]

    fixed = {"canonical": {model_name(k, i): fixed_canonical(k, i) for k, i in models},
             "world": {k: fixed_world(k) for k in kinds}}
    print("fixed batch:", fixed, flush=True)

    t0 = time.perf_counter()
    raw: list[dict] = []
    canon: dict = {}
    canon_rows: dict = {}

    def write(done: bool) -> None:
        rows = [canon_rows[key] for key in models if key in canon_rows]
        rows += world_rows(raw)
        n = min((sum(x["kind"] == k for x in raw) for k in kinds), default=0)
        notes = (f"{'' if done else 'PARTIAL RUN: '}World rows: {n} clouds per kind from benchmarks/bench_shapes.py's "
                 f"set (seeds 10000+i), {POINTS} points, noise {NOISE:.1%} of the diagonal per coordinate; canonical "
                 f"rows: {ccount} clouds per model from the training generator (data seed {HELD_OUT_SEED}). Goals "
                 "(issue 11): network alone within 2 % of the diagonal, <= 10 ms per cloud. Times: medians per "
                 f"cloud, one torch thread per process, {args.jobs} worker process(es) on a shared 2-core machine, "
                 f"load average {load_start:.1f} at the start and {os.getloadavg()[0]:.1f} now; CPU is "
                 "time.process_time (load-independent up to cache effects), wall is inflated by the load. "
                 "Noise floor: the true surface's own input-to-surface mean.")
        write_results(args.name, rows, COLUMNS + [("status", "status")],
                      meta={"count": n, "canonical_count": ccount, "noise": NOISE, "points": POINTS,
                            "held_out_seed": HELD_OUT_SEED, "jobs": args.jobs, "load_average_start": load_start,
                            "load_average_end": os.getloadavg()[0], "seconds": time.perf_counter() - t0,
                            "complete": done, "fixed_batch": fixed, "per_cloud": raw},
                      title="Shapes: the learned path (DeepSpline 3-D networks)", notes=notes)

    ctx = get_context("spawn")
    light = ("floor", "network")
    scount = 0 if args.no_search else min(args.count, args.count if args.search_count is None else args.search_count)
    heavy = (() if args.no_refine else ("refined",)) + (("geometric",) if args.geometric else ())
    rcount = min(args.count, args.count if args.refine_count is None else args.refine_count)
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=ctx, initializer=_init_worker) as pool:
        # the network-alone rows of every cloud first (cheap), then the canonical sets, then
        # the refinements of the first refine-count clouds: a run stopped early keeps the
        # first two complete
        light_futures = [pool.submit(world_task, k, i, light + (("search",) if i < scount else ()))
                         for i in range(args.count) for k in kinds]
        canon_futures = {(k, i): [pool.submit(canonical_task, k, i, ccount, s) for s in range(0, ccount, CHUNK)]
                         for k, i in models}
        heavy_futures = [pool.submit(world_task, k, i, heavy) for i in range(rcount) for k in kinds] if heavy else []
        merged: dict = {}

        def take(futures, every):
            for j, f in enumerate(futures):
                x = f.result()
                key = (x["kind"], x["cloud"])
                if key in merged:
                    merged[key].update(x)
                else:
                    merged[key] = x
                    raw.append(x)
                print(x["kind"], x["cloud"], {k: round(v["mean"] * 100, 3) for k, v in x.items()
                                              if isinstance(v, dict)}, flush=True)
                if (j + 1) % every == 0:
                    write(False)

        take(light_futures, 100)
        for key, futures in canon_futures.items():
            canon[key] = [r for f in futures for r in f.result()]
            canon_rows[key] = canonical_row(*key, ccount, canon[key])
            print(canon_rows[key], flush=True)
        write(False)
        take(heavy_futures, 20)
    write(True)


if __name__ == "__main__":
    main()
