"""Surfaces of revolution and extrusions from clouds: the geometric path of issue 11.

Question: on a held-out synthetic set, how close are the recovered axis / direction and
the surface, and how long does one cloud take?

Method: ``--count`` clouds per kind (fixed seeds 10_000 + i, disjoint from the tests'
seeds 0-12), 2,000 points each, Gaussian noise of ``--noise`` (default 0.5 %) of the
bounding-box diagonal per coordinate. Revolution: random vases
(:func:`nurbskit.shapes.synthetic.vase_cloud`, random axis). Extrusion: alternately a
smooth cubic wave and an L profile, random direction. Each cloud is fitted with its kind
given (``fit_shape(points, kind, init=--init)``, defaults: normals by PCA, 30 L-BFGS
iterations on up to 2,000 points, i.e. all of them). Per cloud: the axis angle error of
the geometric estimate and after refinement (degrees), input-to-surface mean and p95
over the diagonal (the metrics module's projection), the **noise floor** (the same mean
for the true surface), the **analytic floor** ``sigma sqrt(2 / pi)`` (the mean absolute
value of the noise's component along the surface normal, ``sigma`` = ``--noise`` times
the clean cloud's diagonal, over the noisy cloud's diagonal): for noise much smaller
than the curvature radii no surface does better on average, so the measured floor must
equal it (checked: ``floor_over_analytic``), truth-to-fit mean (samples of the true
surface to the fitted one: the error of the surface itself, which can go below the
floor), CPU seconds (``time.process_time`` around ``fit_shape`` in the process that runs
it, one torch thread: time spent waiting for a loaded CPU is not counted) and wall
seconds, after a warm-up cloud, and the refinement's projection count (load-free).
The geometric axis error is that of the refinement's start (``ShapeFit.start_direction``).
``--jobs J`` runs the clouds in J worker processes (each ``--threads`` threads). The kinds
alternate cloud by cloud and the results are rewritten every 20 clouds, so a run stopped
early still leaves a consistent table. Reported: medians (and the 95th percentile of the
axis error and of the CPU seconds).

Run: ``PYTHONPATH=src nice -n 10 python benchmarks/bench_shapes.py --count 500 --jobs 2``;
split over processes with ``--start I --count K --name shapes_partJ`` and combine with
``--merge benchmarks/results/shapes_part*.json --name shapes``. Real data:
``--real ../shared/data`` runs ``nurbskit shape --kind auto`` on the cases of
:func:`real_clouds` (figures under ``results/shapes_figures/``, table ``shapes_real``).
The committed run has 500 clouds per kind (the results' ``count``). The notes of the markdown state
the noise floor (:func:`floor_statement`): the analytic ``sigma sqrt(2/pi)`` and the measured one (the
true surface's own mean), next to the fits' mean; rewritten from the stored per-cloud results with
``--merge benchmarks/results/shapes.json --jobs 2 --name shapes`` (same numbers).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

from nurbskit.metrics import surface_distances  # noqa: E402
from nurbskit.shapes import axis_angle_degrees, fit_shape  # noqa: E402
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud  # noqa: E402


def one(kind: str, seed: int, noise: float, n: int, init: str = "geometric") -> dict:
    if kind == "revolution":
        c = vase_cloud(n, noise, seed)
    else:
        c = extrusion_cloud(n, noise, seed, "L" if seed % 2 else "smooth")
    wall, cpu = time.perf_counter(), time.process_time()
    fit = fit_shape(c.points, kind, init=init)
    cpu = time.process_time() - cpu
    seconds = time.perf_counter() - wall
    floor = surface_distances(c.surface, c.points)["to_surface_mean"]
    # sigma is noise times the clean cloud's diagonal (the generator's scale; approximated
    # by a dense grid on the true surface); the metrics divide by the noisy cloud's diagonal
    noisy_diag = float((c.points.amax(0) - c.points.amin(0)).norm())
    grid = c.surface.sample((60, 60)).reshape(-1, 3)
    clean_diag = float((grid.amax(0) - grid.amin(0)).norm())
    analytic = noise * math.sqrt(2 / math.pi) * clean_diag / noisy_diag
    truth = c.surface.sample((40, 40)).reshape(-1, 3)
    truth_to_fit = surface_distances(fit.surface, truth)["to_surface_mean"]
    return {
        "kind": kind,
        "seed": seed,
        "axis_deg_geometric": axis_angle_degrees(fit.start_direction, c.axis_direction),
        "axis_deg": axis_angle_degrees(fit.axis["direction"], c.axis_direction),
        "mean": fit.distance_mean,
        "p95": fit.distance_p95,
        "noise_floor": floor,
        "analytic_floor": analytic,
        "floor_over_analytic": floor / analytic if analytic > 0 else float("nan"),
        "truth_to_fit": truth_to_fit,
        "seconds": seconds,
        "cpu_seconds": cpu,
        "projections": fit.iterations,
        "closed": fit.closed,
    }


def _worker_init(threads: int) -> None:
    torch.set_num_threads(threads)
    one("revolution", 9999, 0.005, 500)  # warm-up (imports, first projection)


def _task(job: tuple) -> dict:
    return one(*job)


def floor_statement(rows: list[dict], noise: float) -> str:
    """The notes' sentence on the noise floor: why the issue's 0.2 % goal for the input-to-surface
    mean cannot be met at this noise, with the analytic and the measured floors of ``rows``."""
    analytic = noise * math.sqrt(2 / math.pi)
    measured = "; ".join(f"{r['kind']} {100 * r['noise_floor_median']:.3f} % (analytic on those clouds "
                         f"{100 * r['analytic_floor_median']:.3f} %, ratio {r['floor_over_analytic_median']:.3f}), "
                         f"fits at {100 * r['mean_median']:.3f} %, truth-to-fit {100 * r['truth_to_fit_median']:.3f} %"
                         for r in rows)
    return (f"NOISE FLOOR. The issue's goal of an input-to-surface mean <= 0.2 % of the diagonal is below "
            f"the noise floor at {noise:.1%} noise: Gaussian noise of sigma = {noise:.1%} of the diagonal per "
            "coordinate puts each point |n . e| off a locally flat surface, whose mean is the ANALYTIC floor "
            f"sigma sqrt(2/pi) = {100 * analytic:.3f} % of the diagonal; the MEASURED floor is the true "
            f"surface's own input-to-surface mean on the same clouds (medians: {measured}). No surface can "
            "be much closer to the points on average than the true one; what the fit gets wrong is the "
            "truth-to-fit distance.")


def summarise(raw: list, args) -> None:
    rows = []
    for kind in ("revolution", "extrusion"):
        r = [x for x in raw if x["kind"] == kind]
        if not r:
            continue
        keys = {k for x in r for k, v in x.items() if isinstance(v, (int, float)) and k != "seed"}
        med = {k: statistics.median(x[k] for x in r if k in x) for k in keys}
        rows.append({
            "kind": kind, "count": len(r),
            "axis_deg_median": med["axis_deg"],
            "axis_deg_p95": float(np.percentile([x["axis_deg"] for x in r], 95)),
            "axis_deg_geometric_median": med["axis_deg_geometric"],
            "mean_median": med["mean"], "mean_mean": statistics.fmean(x["mean"] for x in r),
            "p95_median": med["p95"],
            "noise_floor_median": med["noise_floor"], "analytic_floor_median": med["analytic_floor"],
            "floor_over_analytic_median": med["floor_over_analytic"],
            "mean_over_floor_median": statistics.median(x["mean"] / x["noise_floor"] for x in r),
            "truth_to_fit_median": med["truth_to_fit"],
            "seconds_median": med["seconds"], "cpu_seconds_median": med.get("cpu_seconds", float("nan")),
            "cpu_seconds_mean": statistics.fmean(x.get("cpu_seconds", float("nan")) for x in r),
            "cpu_seconds_p95": float(np.percentile([x.get("cpu_seconds", float("nan")) for x in r], 95)),
            "projections_median": med["projections"],
        })
    cols = [("kind", "kind"), ("count", "clouds"), ("axis_deg_median", "axis err median (deg)"),
            ("axis_deg_p95", "axis err p95"), ("axis_deg_geometric_median", "geometric axis err median"),
            ("mean_median", "in-to-surface mean / diag (median)"), ("mean_mean", "(mean over clouds)"),
            ("p95_median", "p95 / diag"),
            ("noise_floor_median", "noise floor: true surface's mean / diag"),
            ("analytic_floor_median", "analytic floor sigma sqrt(2/pi) / diag"),
            ("floor_over_analytic_median", "floor / analytic"),
            ("mean_over_floor_median", "mean / floor"),
            ("truth_to_fit_median", "truth-to-fit mean / diag"),
            ("cpu_seconds_median", "CPU s / cloud (median)"), ("cpu_seconds_mean", "CPU s (mean)"),
            ("cpu_seconds_p95", "CPU s (p95)"), ("seconds_median", "wall s / cloud (median)"),
            ("projections_median", "projections")]
    done = min(r["count"] for r in rows)
    asked = "" if done >= 500 else " (the issue asks for 500)"
    notes = (f"{done} clouds per kind{asked}, {args.points} points, noise "
             f"{args.noise:.3%} of the diagonal per coordinate, init {args.init}, {args.threads} torch thread(s) "
             f"per process, {args.jobs} worker process(es), on a shared 2-core machine. CPU seconds "
             "(time.process_time around fit_shape, in the worker) do not count time spent waiting for the "
             "CPU; wall seconds do (inflated by the load). Projections (the refinement's evaluations) "
             "is the load-free count. "
             + floor_statement(rows, args.noise))
    write_results(args.name, rows, cols, meta={"count": done, "noise": args.noise, "points": args.points,
                                              "init": args.init, "per_cloud": raw},
                  title="Shapes: revolution and extrusion, geometric path", notes=notes)


def real_clouds(data: Path, n: int = 2000) -> dict:
    """The real-data cases (``--real``): name -> (points (n, 3), what it is).

    * ``cylinder``: ``classic_meshes/cylinder.obj`` (a capped cylinder), ``n`` area-uniform samples;
    * ``cylinder_vertices``: the same mesh's raw vertices (11 rings of 20 points, no cap
      vertices): sparse, evenly spaced; run with ``--kind extrusion`` too (``--real-kinds``)
      so that the closed circle shows;
    * ``kinect31_obj20/30/40``: the three objects of ``kinect_scans/test31.pcd`` (the
      "cylindric objects" test scene), each cropped by its segmentation label (seen from one
      side: partial revolutions), ``n`` of its points (fixed seed);
    * ``teapot_body``: ``classic_meshes/teapot.obj`` sampled, cropped to the body (below the
      rim, within the body's radius 2 of the vertical axis: the spout's and the handle's
      roots stay): the hard case.
    """
    from nurbskit.geometry.sampling import sample_mesh
    from nurbskit.io import read_mesh, read_points

    rng = np.random.default_rng(0)
    out = {}
    mesh = read_mesh(data / "classic_meshes" / "cylinder.obj")
    out["cylinder"] = (np.asarray(sample_mesh(mesh.vertices, mesh.faces, n, "uniform", seed=0)),
                       "classic_meshes/cylinder.obj, capped, 2,000 samples")
    out["cylinder_vertices"] = (np.asarray(mesh.vertices, dtype=np.float64),
                                f"classic_meshes/cylinder.obj, its {len(mesh.vertices)} raw vertices "
                                "(rings of 20: sparse, evenly spaced)")
    scan = read_points(data / "kinect_scans" / "test31.pcd")
    for label in (20, 30, 40):
        pts = np.asarray(scan.points)[np.asarray(scan.labels) == label]
        pick = rng.choice(pts.shape[0], size=min(n, pts.shape[0]), replace=False)
        out[f"kinect31_obj{label}"] = (pts[pick], f"kinect_scans/test31.pcd label {label} ({pts.shape[0]} points)")
    mesh = read_mesh(data / "classic_meshes" / "teapot.obj")
    pts = np.asarray(sample_mesh(mesh.vertices, mesh.faces, 6 * n, "uniform", seed=0))
    keep = (pts[:, 1] < 2.25) & (np.hypot(pts[:, 0], pts[:, 2]) < 2.0)
    pts = pts[keep][:n]
    out["teapot_body"] = (pts, "classic_meshes/teapot.obj sampled, cropped to the body (y < 2.25, r < 2)")
    return out


def real(args) -> None:
    """Each real case through ``nurbskit shape --kind auto`` (figures kept under
    ``benchmarks/results/shapes_figures/<case>/``), and a table."""
    import json
    import shutil
    import tempfile

    from nurbskit.cli import main as cli

    data = Path(args.real)
    figs = Path(__file__).resolve().parent / "results" / "shapes_figures"
    figs.mkdir(parents=True, exist_ok=True)
    rows = []
    cases = [(name, pts, what, args.kind) for name, (pts, what) in real_clouds(data, args.points).items()]
    # the raw vertices as an extrusion too: the sparse rings' circle must close
    cases += [(name + "_extrusion", pts, what, "extrusion") for name, pts, what, _ in cases
              if name == "cylinder_vertices"]
    for name, pts, what, kind in cases:
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / f"{name}.npy"
            np.save(src, pts)
            out = figs / name
            t, cpu = time.perf_counter(), time.process_time()
            rc = cli(["shape", str(src), "--kind", kind, "--out", str(out), "--overwrite"])
            seconds, cpu = time.perf_counter() - t, time.process_time() - cpu
        rep = json.loads((out / "report.json").read_text())
        (out / "surface.json").unlink(missing_ok=True)  # figures and report only: keep the repository small
        shutil.rmtree(out / "__pycache__", ignore_errors=True)
        m = rep["metrics"]
        rows.append({"case": name, "what": what, "rc": rc, "asked": kind, "kind": rep["kind"],
                     "candidates": ", ".join(f"{k} {v:.2e}" for k, v in rep["candidates"].items()),
                     "axis_direction": [round(x, 4) for x in rep["axis"]["direction"]] if rep["axis"] else None,
                     "angle_deg": round(math.degrees(rep["angle"]), 1) if "angle" in rep else None,
                     "closed": rep["profile"]["closed"] if rep["profile"] else None,
                     "mean": m["to_surface_mean"], "p95": m["to_surface_p95"], "seconds": seconds, "cpu_seconds": cpu,
                     "poor_fit": rep["poor_fit"]})
        print(rows[-1], flush=True)
    cols = [("case", "case"), ("what", "input"), ("asked", "--kind"), ("kind", "kind found"), ("candidates", "auto: mean / diag per kind"),
            ("axis_direction", "axis / direction"), ("angle_deg", "angle (deg)"), ("closed", "closed profile"),
            ("mean", "in-to-surface mean / diag"), ("p95", "p95 / diag"), ("poor_fit", "poor fit warned"),
            ("cpu_seconds", "CPU s"), ("seconds", "wall s")]
    write_results("shapes_real", rows, cols, meta={"points": args.points, "kind": args.kind},
                  title="Shapes on real data: nurbskit shape",
                  notes="Figures (cloud.png, profile.png, error_map.png, report.json) under "
                        "benchmarks/results/shapes_figures/<case>/. CPU seconds (the whole command: fits, "
                        "report, figures) in the process; wall seconds on a shared, contended machine.")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--noise", type=float, default=0.005)
    ap.add_argument("--points", type=int, default=2000)
    ap.add_argument("--threads", type=int, default=1, help="torch threads per process")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (each with --threads threads)")
    ap.add_argument("--init", choices=("geometric", "network"), default="geometric")
    ap.add_argument("--start", type=int, default=0, help="first cloud index (to split a run over processes)")
    ap.add_argument("--name", default="shapes", help="results name (benchmarks/results/NAME.json/.md)")
    ap.add_argument("--merge", nargs="+", metavar="JSON", default=None,
                    help="summarise the per-cloud results of these result files into --name and exit")
    ap.add_argument("--real", metavar="DATA", default=None,
                    help="run the real-data cases from this ../shared/data folder instead (figures and a table)")
    ap.add_argument("--kind", default="auto", help="--real: the kind asked of nurbskit shape")
    args = ap.parse_args(argv)
    if args.real:
        real(args)
        return
    if args.merge:
        import json

        raw, seen = [], set()
        for path in args.merge:
            for x in json.loads(Path(path).read_text())["meta"]["per_cloud"]:
                if (x["kind"], x["seed"]) not in seen:
                    seen.add((x["kind"], x["seed"]))
                    raw.append(x)
        summarise(raw, args)
        return
    torch.set_num_threads(args.threads)
    jobs = [(kind, 10_000 + i, args.noise, args.points, args.init)
            for i in range(args.start, args.start + args.count) for kind in ("revolution", "extrusion")]
    raw = []

    def record(x: dict) -> None:
        raw.append(x)
        print(x["kind"], x["seed"], {k: round(v, 5) for k, v in x.items() if isinstance(v, float)}, flush=True)
        if len(raw) % 20 == 0 or len(raw) == len(jobs):
            raw.sort(key=lambda y: (y["seed"], y["kind"]))
            summarise(raw, args)

    if args.jobs <= 1:
        _worker_init(args.threads)
        for job in jobs:
            record(one(*job))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        # the kinds interleave cloud by cloud and results are written every 20 clouds: a run
        # stopped early still leaves a consistent table
        with ProcessPoolExecutor(args.jobs, mp_context=mp.get_context("spawn"), initializer=_worker_init,
                                 initargs=(args.threads,)) as pool:
            for x in pool.map(_task, jobs, chunksize=1):
                record(x)


if __name__ == "__main__":
    main()
