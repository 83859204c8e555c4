"""How many control points can a network read off one curve of a drawing of several? (issue 10)

Question: the MV network reads the right number of control points for 57 % of the curves
of its held-out drawings (issue 10 asks 90 %); V, reading drawings of one curve, for
86-89 %. Is the gap MV's decoder, or the other curves of the drawing?

Method: the held-out drawings of table 2 (``bench_curves_nets.py``: the MV recipe, 128 px,
2 px strokes, ``batch_generator(777, chunk)``), the shipped weights. MV is decoded for the
true number of curves and 6 points (as its loss runs it), its curves matched to the true
ones by the loss's Hungarian helper (``nets.train.hungarian``, mean squared control-point
distance), and each matched curve's count read as ``predicted_count`` reads it: MV's
point-count accuracy of table 2. Then, for every true curve, V (four views, its default
reading, ``predict.read_views``) reads:

- the true curve drawn alone (``synthetic.render_batch``, the same 2 px stroke): what V
  counts when nothing else is in the drawing;
- the drawing with every pixel farther than ``r`` px from the true curve blanked (``r``
  2.5, 4, 8): the curve in its drawing, with the pieces of the other curves that cross
  or pass within ``r``;
- the same, masked around MV's own matched curve (its control points, its count) instead
  of the true one: what a pipeline "MV finds the curves, V counts each" would get.

Each reading is scored against the true count; by the number of curves in the drawing.

Run: ``PYTHONPATH=src python benchmarks/bench_curves_count_isolated.py [--count 2000]``.
Results: ``results/curves_count_isolated.{json,md}`` (about 3 minutes on one core).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch.nn import functional as F

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "src"))
from _harness import write_results  # noqa: E402

from nurbskit.curves.nets.models import MAX_POINTS, MIN_POINTS  # noqa: E402
from nurbskit.curves.nets.predict import load_model, read_views  # noqa: E402
from nurbskit.curves.nets.train import hungarian, network_inputs, predicted_count  # noqa: E402
from nurbskit.curves.synthetic import curve_samples, make_torch_batch, mode_config, render_batch  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402

HELD_OUT_SEED, SIZE, CHUNK, RADII = 777, 128, 100, (2.5, 4.0, 8.0)


def _samples(points: np.ndarray) -> np.ndarray:
    """Dense samples (0.25 px apart) of the cubic with control points ``(n, 2)`` in pixels."""
    pts, _ = curve_samples(torch.as_tensor(points)[None, None], torch.tensor([[len(points)]]), 3, 0.25)
    return pts.numpy()


def _v_counts(model, inks: list[np.ndarray], size: int) -> np.ndarray:
    """V's count (four views) of each ``(128, 128)`` ink image."""
    x = F.interpolate(torch.as_tensor(np.asarray(inks), dtype=torch.float32)[:, None], size=(size, size), mode="area")
    with torch.no_grad():
        return read_views(model, x, 4)[2][:, 0].numpy()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=2000, help="held-out drawings (default 2000)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    start = time.time()
    mv, mv_meta = load_model("MV")
    v, v_meta = load_model("V")
    config = mode_config("MV", SIZE)
    centres = np.stack(np.meshgrid(np.arange(SIZE) + 0.5, np.arange(SIZE) + 0.5), -1).reshape(-1, 2)
    readers = ["mv", "alone"] + [f"true_{r}" for r in RADII] + [f"mv_{r}" for r in RADII]
    right = {name: [] for name in readers}
    curves_in_drawing = []
    done = 0
    while done < args.count:
        n = min(CHUNK, args.count - done)
        batch = make_torch_batch(batch_generator(HELD_OUT_SEED, done // CHUNK), n, config)
        ink, unit = network_inputs(batch, mv_meta["size"])
        k, p = int(batch.n_curves.max()), int(batch.counts.max())
        with torch.no_grad():
            tokens, codes, _ = mv.curve_codes(ink, k)
            pred, stops = mv.decode_points(tokens, codes, MAX_POINTS)
        target, cnt = unit[:, :k, :p], batch.counts[:, :k]
        tmask = (torch.arange(p) < cnt[..., None]).float()
        cost = (((pred[:, :, None, :p] - target[:, None]) ** 2).sum(-1) * tmask[:, None]).sum(-1)
        perm = hungarian(cost / tmask.sum(-1).clamp(min=1)[:, None], batch.n_curves)  # true curve of prediction i
        mv_count = predicted_count(stops, MIN_POINTS)
        drawing = (1.0 - batch.image).numpy()
        truth, alone, masked = [], [], {name: [] for name in readers[2:]}
        for b in range(n):
            for i in range(int(batch.n_curves[b])):
                j = int(perm[b, i])
                true_points = batch.points[b, j, : int(cnt[b, j])].numpy()
                truth.append(len(true_points))
                curves_in_drawing.append(int(batch.n_curves[b]))
                right["mv"].append(int(mv_count[b, i]) == len(true_points))
                s = _samples(true_points)
                alone.append(render_batch(torch.as_tensor(s), torch.zeros(len(s), dtype=torch.long), 1,
                                          (SIZE, SIZE), config.width)[0].numpy())
                near_true = cKDTree(s).query(centres)[0].reshape(SIZE, SIZE)
                own = pred[b, i, : int(mv_count[b, i])].numpy() * SIZE
                near_mv = cKDTree(_samples(own)).query(centres)[0].reshape(SIZE, SIZE)
                for r in RADII:
                    masked[f"true_{r}"].append(drawing[b] * (near_true <= r))
                    masked[f"mv_{r}"].append(drawing[b] * (near_mv <= r))
        truth = np.array(truth)
        right["alone"] += list(_v_counts(v, alone, v_meta["size"]) == truth)
        for name, inks in masked.items():
            right[name] += list(_v_counts(v, inks, v_meta["size"]) == truth)
        done += n
        print(f"{done} drawings, {time.time() - start:.0f} s", flush=True)
    per = np.array(curves_in_drawing)
    labels = {"mv": "MV, its own decoding (table 2's point-count accuracy)",
              "alone": "V, the true curve drawn alone"}
    labels.update({f"true_{r}": f"V, the drawing within {r:g} px of the true curve" for r in RADII})
    labels.update({f"mv_{r}": f"V, the drawing within {r:g} px of MV's curve" for r in RADII})
    rows = []
    for name in readers:
        ok = np.array(right[name])
        row = {"reader": labels[name], "accuracy": float(ok.mean())}
        for c in (1, 2, 3):
            row[f"curves_{c}"] = float(ok[per == c].mean())
        rows.append(row)
        print(row, flush=True)
    notes = (f"{args.count} held-out drawings (seed {HELD_OUT_SEED}), {len(per)} curves "
             f"({', '.join(f'{int((per == c).sum())} in drawings of {c}' for c in (1, 2, 3))}); the shipped MV "
             f"({mv_meta.get('steps')} steps) and V ({v_meta.get('steps')} steps). Method in the module docstring. "
             f"{time.time() - start:.0f} s.")
    print(write_results("curves_count_isolated", rows,
                        [("reader", "what reads each true curve's count"), ("accuracy", "right"),
                         ("curves_1", "in drawings of 1 curve"), ("curves_2", "of 2"), ("curves_3", "of 3")],
                        meta={"count": args.count, "curves": len(per)},
                        title="One curve of several: how well its control points are counted (issue 10)",
                        notes=notes))


if __name__ == "__main__":
    main()
