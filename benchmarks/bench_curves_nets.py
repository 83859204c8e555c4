"""The shipped DeepSpline curve networks (issue 10): the paper's tables 1 and 2, speed, MNIST.

Method:

- Held-out synthetic set: per mode (V, M, MV), ``--count`` drawings of the paper's recipe
  at 128 x 128 (``nurbskit.curves.synthetic.make_torch_batch`` with ``mode_config(mode,
  128)``), drawn in chunks of 100 from ``nurbskit.learn.batch_generator(777, chunk)``:
  seeds no training run uses (training draws ``batch_generator(1, step)``). The networks
  see the images area-averaged to their input size (64), as in training.
- Table 2 (the paper's measures): control-point MSE in the unit square (the training
  loss's term: mean over the true points' coordinates, predicted curves matched to the true
  ones by the Hungarian algorithm for M and MV, each curve decoded for its true number of
  points), point-count accuracy (V: per image; MV: per true curve, matched), curve-count
  accuracy (the first STOP > 1/2), and the symmetric Chamfer distance in pixels between
  the predicted curves (free-running: counts from the stop probabilities) and the true
  curves (mean nearest distance between dense samples both ways, then the mean of the
  two), at 128 px. The paper's numbers stand beside ours. V is reported twice: read once
  (``network``) and as ``nurbskit`` reads it by default, four flipped views averaged
  (``network, 4 views``: ``nurbskit.curves.nets.predict.read_views``; ``DEFAULT_VIEWS``).
  For the latter the MSE decodes every view for the true number of points (a view
  flipped left to right emits the sequence backwards, so its first n points are reversed)
  and the point accuracy is the count read from the averaged stop probabilities.
  For an MV with a sketch (``--sketch S``) also how far its sketch points lie from the
  true curve's points at the same parameters (``train.sketch_targets``), in pixels at
  128 px, each sketch matched to a true curve by the Hungarian algorithm on that
  distance: the mean over all curves and per number of curves in the drawing.
- Table 1: on the first ``--refine`` images per mode, the Chamfer to the true curves of
  the network alone, of the network's curves refined by Chamfer against the ink pixels
  (``nurbskit.curves.classic.refine``, 20 L-BFGS iterations; the network read as table 2
  reads it: one start, the paper's protocol), of that refinement followed by the search
  of each curve's control-point count (``nurbskit.curves.classic.refine_counts``: a count
  stepped by one while the Chamfer to the ink falls), of the network's reading in each
  of the four views refined the same way, the one closest to the ink kept and its counts
  searched (``refined_curves``, what ``--method network --refine`` does), of a random
  start refined the same way (the true number of curves, each with n = 4, 5 and 6
  control points uniform in the image, the best of the three kept by Chamfer to the ink:
  the paper's protocol; the starts drawn from ``default_rng((777, mode))``, so ``--modes``
  alone draws what a full run does), of that random start with its counts searched as well, and of
  the classical path (``fit_image``) on the same images. Beside them, the share of
  drawings whose counts are all right (the number of curves and, sorted, each curve's
  number of control points): the network's reading as table 2 reads it, and the
  four views refined with the count search.
- Speed: median milliseconds of ``network_curves`` (one 128 x 128 image: resize, forward
  in the default views, curves in pixels) over 30 runs after warm-up, one torch thread,
  wall-clock and CPU
  (``time.process_time``: what the process itself used, less sensitive to the other
  processes on this shared, loaded machine; the load average is recorded beside it).
- MNIST: the first ``--mnist`` test digits of ``../shared/data/mnist`` (IDX read by
  ``bench_curves.read_idx_images``), upsampled 4x; per method (each network alone and
  refined as ``--method network --refine`` refines it, ``refined_curves``; classical)
  the Chamfer from the curves to the ink and from the ink to the curves; one overlay figure per mode in ``results/curves_nets_figures/``.

Run: ``PYTHONPATH=src python benchmarks/bench_curves_nets.py [--count 2000] [--refine 40] [--mnist 30]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import RESULTS, write_results  # noqa: E402
from bench_curves import MNIST, figure, read_idx_images, upsample  # noqa: E402

from nurbskit.curves.classic import (  # noqa: E402
    chamfer_points, chamfer_to_ink, fit_image, ink_mask, refine, refine_counts)
from nurbskit.curves.nets.models import MAX_POINTS, MIN_POINTS  # noqa: E402
from nurbskit.curves.nets.predict import (  # noqa: E402
    DEFAULT_VIEWS, load_model, network_curves, predict_unit, read_views, refined_curves, to_curves)
from nurbskit.curves.nets.train import LOSSES, _mse, hungarian, network_inputs, sketch_targets  # noqa: E402
from nurbskit.curves.synthetic import curve_of, dense_samples, make_torch_batch, mode_config  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402

PAPER = {"V": {"cp_mse": 0.0130, "point_acc": 0.946}, "M": {"cp_mse": 0.0270, "curve_acc": 0.9985},
         "MV": {"cp_mse": 0.0374, "point_acc": 0.828, "curve_acc": 0.995}}
GOAL_MSE = {m: 1.5 * PAPER[m]["cp_mse"] for m in PAPER}
HELD_OUT_SEED = 777
SIZE = 128
REFINE_ITERS = 20


def _samples(curves) -> np.ndarray:
    return np.concatenate([dense_samples(c, 0.5) for c in curves]) if curves else np.zeros((0, 2))


def _chamfer(curves, truth) -> float:
    return chamfer_points(_samples(curves), _samples(truth))["symmetric"]


def table2(mode: str, count: int, chunk: int = 100, views: int = 1):
    if views != 1 and mode != "V":
        raise ValueError("several views are measured for V only (DEFAULT_VIEWS)")
    model, meta = load_model(mode)
    config = mode_config(mode, SIZE)
    sums = {}
    chamfers, images = [], []
    sketch_px = {1: [], 2: [], 3: []}
    done = 0
    while done < count:
        n = min(chunk, count - done)
        batch = make_torch_batch(batch_generator(HELD_OUT_SEED, done // chunk), n, config)
        ink, unit = network_inputs(batch, meta["size"])
        if views == 1:
            with torch.no_grad():
                _, parts = LOSSES[mode](model, (ink, unit, batch.counts, batch.n_curves))
        else:  # V read in several views: MSE decoded for the true counts, the counts as read
            steps = int(batch.counts.max())
            true = batch.counts[:, :1]
            points, _, read = read_views(model, ink, views, counts=true)
            points = points[:, 0, :steps]
            valid = (torch.arange(steps) < true).float()
            parts = {"mse": _mse(points, unit[:, 0, :steps].to(points.dtype), valid),
                     "point_acc": (read == true).float().mean()}
        for k, v in parts.items():
            sums[k] = sums.get(k, 0.0) + float(v) * n
        if getattr(model, "sketch", 0):
            for k, d in _sketch_distances(model, ink, unit, batch).items():
                sketch_px[k] += d
        predicted = predict_unit(model, ink, views)
        for b, s in enumerate(batch.samples()):
            curves = to_curves(predicted[b], SIZE, SIZE)
            chamfers.append(_chamfer(curves, s.curves()))
            if len(images) < 200:
                images.append((s, curves))
        done += n
    row = {"mode": mode, "method": "network" if views == 1 else f"network, {views} views", "views": views,
           "images": count, "cp_mse": sums["mse"] / count,
           "paper_cp_mse": PAPER[mode]["cp_mse"], "goal_cp_mse": GOAL_MSE[mode],
           "chamfer_px": statistics.fmean(chamfers), "chamfer_px_median": statistics.median(chamfers)}
    for key in ("point_acc", "curve_acc"):
        if key in sums:
            row[key] = sums[key] / count
            row[f"paper_{key}"] = PAPER[mode].get(key)
    if sketch_px[1]:
        row["sketch_px"] = statistics.fmean(sketch_px[1] + sketch_px[2] + sketch_px[3])
        for k, d in sketch_px.items():
            row[f"sketch_px_{k}_curves"] = statistics.fmean(d)
    row["steps"] = meta.get("steps")
    return row, images


def _sketch_distances(model, ink, unit, batch) -> dict[int, list[float]]:
    """Pixels from each sketch point to the true curve's point at its parameter, sketches
    matched to true curves (Hungarian on the mean squared distance), by curves per drawing."""
    k = int(batch.n_curves.max())
    with torch.no_grad():
        _, codes, _ = model.curve_codes(ink, k)
    sketch = model.sketch_points(codes)  # (B, k, S, 2)
    true = sketch_targets(unit[:, :k], batch.counts[:, :k], sketch.shape[-2])
    perm = hungarian(((sketch[:, :, None] - true[:, None]) ** 2).sum(-1).mean(-1), batch.n_curves)
    matched = true.gather(1, perm[..., None, None].expand_as(true))
    px = ((sketch - matched) ** 2).sum(-1).sqrt().mean(-1) * SIZE  # (B, k): mean over a sketch's points
    out = {1: [], 2: [], 3: []}
    for b, n in enumerate(batch.n_curves.tolist()):
        out[n] += px[b, :n].tolist()
    return out


def _counts_right(curves, truth) -> bool:
    """Whether ``curves`` have the true number of curves and, sorted, the true numbers of
    control points (the drawing's counts, whichever curve carries them)."""
    def counts(cs):
        return sorted(int(c.control_points.shape[0]) for c in cs)
    return len(curves) == len(truth) and counts(curves) == counts(truth)


def table1(mode: str, images: list, count: int, rng: np.random.Generator):
    rows = []
    for s, net in images[:count]:
        truth = s.curves()
        ink, _ = ink_mask(s.image)
        t = time.perf_counter()
        refined = refine(net, ink, REFINE_ITERS) if net else net
        t_ref = time.perf_counter() - t
        counted = refine_counts(refined, ink, REFINE_ITERS, MIN_POINTS, MAX_POINTS)
        t = time.perf_counter()
        views = refined_curves(s.image, ink, mode, False, REFINE_ITERS)
        t_views = time.perf_counter() - t
        best, best_score = None, float("inf")
        for n in (4, 5, 6):
            start = [curve_of(np.stack([rng.uniform(0, SIZE, n), rng.uniform(0, SIZE, n)], 1))
                     for _ in range(s.n_curves)]
            r = refine(start, ink, REFINE_ITERS)
            score = chamfer_to_ink(r, ink)["symmetric"]
            if score < best_score:
                best, best_score = r, score
        best_counted = refine_counts(best, ink, REFINE_ITERS, MIN_POINTS, MAX_POINTS)
        classic, _ = fit_image(s.image)
        rows.append({"network": _chamfer(net, truth), "network_refined": _chamfer(refined, truth),
                     "network_counts_refined": _chamfer(counted, truth),
                     "network_views_refined": _chamfer(views, truth),
                     "random_refined": _chamfer(best, truth), "random_counts_refined": _chamfer(best_counted, truth),
                     "classic": _chamfer(classic, truth),
                     "refine_seconds": t_ref, "views_refine_seconds": t_views,
                     "counts_right_network": _counts_right(net, truth),
                     "counts_right_views": _counts_right(views, truth)})
    out = {"mode": mode, "images": len(rows)}
    for key in ("network", "network_refined", "network_counts_refined", "network_views_refined", "random_refined",
                "random_counts_refined", "classic"):
        vals = [r[key] for r in rows]
        out[f"{key}_mean"] = statistics.fmean(vals)
        out[f"{key}_median"] = statistics.median(vals)
    out["ratio_net_refined_to_random"] = out["network_refined_mean"] / out["random_refined_mean"]
    out["ratio_counts_refined_to_random"] = out["network_counts_refined_mean"] / out["random_refined_mean"]
    out["ratio_views_refined_to_random"] = out["network_views_refined_mean"] / out["random_refined_mean"]
    out["ratio_views_to_random_counts"] = out["network_views_refined_mean"] / out["random_counts_refined_mean"]
    out["counts_right_network"] = statistics.fmean(r["counts_right_network"] for r in rows)
    out["counts_right_views"] = statistics.fmean(r["counts_right_views"] for r in rows)
    out["refine_seconds_median"] = statistics.median(r["refine_seconds"] for r in rows)
    out["views_refine_seconds_median"] = statistics.median(r["views_refine_seconds"] for r in rows)
    return out


def speed(mode: str) -> tuple[float, float]:
    """Median wall-clock and CPU (process) milliseconds of one image through ``network_curves``."""
    s = make_torch_batch(batch_generator(HELD_OUT_SEED + 1, 0), 1, mode_config(mode, SIZE)).samples()[0]
    for _ in range(3):
        network_curves(s.image, mode)
    wall, cpu = [], []
    for _ in range(30):
        t, c = time.perf_counter(), time.process_time()
        network_curves(s.image, mode)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return 1000 * statistics.median(wall), 1000 * statistics.median(cpu)


def mnist(digits: np.ndarray, modes: list[str]):
    rows, examples = [], {m: [] for m in modes}
    for i, d in enumerate(digits):
        image = upsample(d, 4)
        ink, inverted = ink_mask(image)
        methods = {}
        classic, _ = fit_image(image)
        methods["classic"] = classic
        for m in modes:
            net = network_curves(image, m, inverted)
            methods[f"network {m}"] = net
            methods[f"network {m} refined"] = refined_curves(image, ink, m, inverted, REFINE_ITERS)
            if i < 8:
                examples[m].append((f"#{i} {m}: {len(net)} curve(s)", image, net))
                examples[m].append((f"#{i} {m} refined", image, methods[f"network {m} refined"]))
        for name, curves in methods.items():
            ch = chamfer_to_ink(curves, ink) if curves else {"curves_to_ink": float("nan"),
                                                              "ink_to_curves": float("nan")}
            rows.append({"digit": i, "method": name, "curves_to_ink": ch["curves_to_ink"],
                         "ink_to_curves": ch["ink_to_curves"], "curves": len(curves)})
    summary = []
    for name in dict.fromkeys(r["method"] for r in rows):
        rs = [r for r in rows if r["method"] == name]
        summary.append({"method": name, "digits": len(rs),
                        "curves_to_ink_mean": float(np.nanmean([r["curves_to_ink"] for r in rs])),
                        "ink_to_curves_mean": float(np.nanmean([r["ink_to_curves"] for r in rs])),
                        "curves_mean": statistics.fmean(r["curves"] for r in rs)})
    return summary, examples


def _mode_of(row: dict) -> str | None:
    if row.get("table") == "mnist":
        parts = row["method"].split()
        return parts[1] if len(parts) > 1 else None
    return row.get("mode")


def _merged(rows: list[dict], modes: list[str]) -> list[dict]:
    """This run's rows plus the committed results' rows of the modes not run now (``--modes`` runs a subset)."""
    import json

    path = RESULTS / "curves_nets.json"
    if not path.exists():
        return rows
    old = [r for r in json.loads(path.read_text())["rows"] if _mode_of(r) is not None and _mode_of(r) not in modes]
    order = {"2": 0, "1": 1, "mnist": 2}
    return sorted(rows + old, key=lambda r: (order[r["table"]], _mode_of(r) or "", r.get("method", "")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=2000, help="held-out images per mode (table 2)")
    parser.add_argument("--refine", type=int, default=40, help="images per mode for table 1 (refinements)")
    parser.add_argument("--mnist", type=int, default=30, help="MNIST test digits")
    parser.add_argument("--modes", default="V,M,MV")
    args = parser.parse_args()
    torch.set_num_threads(1)
    modes = args.modes.split(",")
    load = os.getloadavg()[0]
    t2, t1, rows = [], [], []
    for mode in modes:
        row, images = table2(mode, args.count, views=DEFAULT_VIEWS[mode])
        row["inference_ms"], row["inference_cpu_ms"] = speed(mode)
        row["load_average"] = os.getloadavg()[0]
        if DEFAULT_VIEWS[mode] != 1:  # the network read once, beside its default reading
            t2.append(table2(mode, args.count, views=1)[0])
        t2.append(row)
        rng = np.random.default_rng((HELD_OUT_SEED, ("V", "M", "MV").index(mode)))  # a mode alone draws the same starts
        t1.append(table1(mode, images, args.refine, rng))
        print(row, t1[-1], flush=True)
    digits_summary, examples = ([], {})
    if MNIST.exists() and args.mnist:
        digits_summary, examples = mnist(read_idx_images(MNIST, args.mnist), modes)
        for m, ex in examples.items():
            figure(ex, RESULTS / "curves_nets_figures" / f"mnist_{m.lower()}.png")
    rows = ([dict(r, table="2") for r in t2] + [dict(r, table="1", method="refinement") for r in t1]
            + [dict(r, table="mnist") for r in digits_summary])
    rows = _merged(rows, modes)
    notes = ("Table 2: held-out synthetic drawings, 128 px, seed 777; the paper's numbers in the paper_ columns, "
             "goal: MSE <= 1.5 x the paper's, MV point accuracy >= 0.90 and curve accuracy >= 0.995. "
             "Table 1: Chamfer in pixels to the true curves; goal: network-initialised refinement <= 0.5 x the "
             "random start. MNIST: Chamfer in pixels to the ink of the 4x upsampled digits. "
             f"Load average at the start: {load:.1f} on {os.cpu_count()} cores (shared machine).")
    columns = [("table", "table"), ("mode", "mode"), ("method", "method"), ("images", "images"),
               ("cp_mse", "CP MSE"), ("paper_cp_mse", "paper"), ("point_acc", "point acc"),
               ("paper_point_acc", "paper"), ("curve_acc", "curve acc"), ("paper_curve_acc", "paper"),
               ("chamfer_px", "Chamfer px"), ("inference_ms", "ms/image"), ("inference_cpu_ms", "CPU ms/image"),
               ("network_mean", "net"), ("network_refined_mean", "net+refine"),
               ("network_counts_refined_mean", "net+refine, counts searched"),
               ("network_views_refined_mean", "net (4 views)+refine, counts searched"),
               ("random_refined_mean", "random+refine"),
               ("random_counts_refined_mean", "random+refine, counts searched"), ("classic_mean", "classic"),
               ("ratio_net_refined_to_random", "net+refine / random"),
               ("ratio_counts_refined_to_random", "net+refine, counts searched / random"),
               ("ratio_views_refined_to_random", "net (4 views)+refine, counts searched / random"),
               ("ratio_views_to_random_counts", "the same / random, counts searched"),
               ("counts_right_network", "all counts right: network"),
               ("counts_right_views", "all counts right: net (4 views)+refine, counts searched"),
               ("digits", "digits"), ("curves_to_ink_mean", "curves->ink"), ("ink_to_curves_mean", "ink->curves")]
    write_results("curves_nets", rows, columns, meta={"count": args.count, "refine": args.refine,
                                                      "mnist": args.mnist, "held_out_seed": HELD_OUT_SEED,
                                                      "load_average": load, "size": SIZE},
                  title="DeepSpline curve networks: tables 1 and 2, speed, MNIST", notes=notes)


if __name__ == "__main__":
    main()
