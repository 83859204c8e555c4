"""How often does the count vote of ``nurbskit curves`` (hybrid) name the right number of curves?

Method:

- Held-out drawings: ``--count`` drawings (default 2,000) of the MV recipe (1 to 3 cubic
  curves of 4 to 6 control points, 128 px) as the hybrid method hands them to the MV
  network (``nurbskit.curves.nets.train.redrawn_batch_maker``: stroke width drawn per
  batch in [1, 3] px, a quarter of the drawings seen as large drawings are; each
  drawing's ink mask and skeleton from the classical path, redrawn at 2 px, area-averaged
  to the network's 64 px), in chunks of 100 from
  ``nurbskit.learn.batch_generator(777, chunk)``: seeds no training run uses (training
  draws ``batch_generator(seed, step)`` with seeds 1 to 5).
- Voters, on the same inputs: the MV network's curve-stop probabilities
  (``P(k) = s_k prod_{j<k} (1 - s_j)``, the vote of ``nets.predict.count_probabilities``)
  with the weights trained on redrawn drawings (``curves_mv_redrawn``, the hybrid
  method's since the ninth session) and with those trained on the drawings themselves
  (``curves_mv`` as shipped now; the voter before was this network's seventh-session
  weights, 86.7 % right on 300 such drawings of another seed).
- Measures: accuracy of the most probable count among 1 to 3 (overall and per true
  count), the mean negative log-likelihood of the true count in nats (the vote enters
  the pairing search as ``2 x -ln P``, so how sure it is when wrong matters as much as
  how often it is right), and the CPU milliseconds of one vote (one drawing, one torch
  thread, median of 30 after warm-up).

Run: ``PYTHONPATH=src python benchmarks/bench_curves_count.py [--count 2000]``.
Results: ``results/curves_count.{json,md}``; ``tests/test_curves_redrawn.py`` checks the
shipped weights against the accuracy recorded here.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch
from torch.nn import functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

from nurbskit.curves.nets.models import MAX_CURVES  # noqa: E402
from nurbskit.curves.nets.predict import load_model  # noqa: E402
from nurbskit.curves.nets.train import redrawn_batch_maker  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402

HELD_OUT_SEED = 777


def vote_log_probabilities(input: str, ink: torch.Tensor) -> torch.Tensor:
    """ink ``(B, 1, 64, 64)`` -> log P(1, 2, 3 curves) ``(B, 3)`` by the MV weights trained on ``input``."""
    model, _ = load_model("MV", input)
    with torch.no_grad():
        s = model.curve_codes(ink, MAX_CURVES)[2].softmax(-1)[..., 1].double()
    s[:, -1] = 1.0
    alive = torch.cumprod(torch.cat([s.new_ones(len(s), 1), 1.0 - s[:, :-1]], 1), 1)
    return (alive * s)[:, :3].clamp(min=1e-9).log()


def cpu_ms(voter: str, ink: torch.Tensor, runs: int = 30) -> float:
    one = ink[:1]
    vote_log_probabilities(voter, one)
    times = []
    for _ in range(runs):
        c = time.process_time()
        vote_log_probabilities(voter, one)
        times.append(time.process_time() - c)
    return 1e3 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=2000, help="held-out drawings")
    args = parser.parse_args()
    torch.set_num_threads(1)
    make = redrawn_batch_maker("MV", load_model("MV", "redrawn")[1]["size"])
    inputs = ("redrawn", "image")
    logp = {v: [] for v in inputs}
    truth, inks, done = [], None, 0
    while done < args.count:
        n = min(100, args.count - done)
        ink, _, _, n_curves = make(batch_generator(HELD_OUT_SEED, done // 100), n)
        inks = ink if inks is None else inks
        for v in inputs:
            logp[v].append(vote_log_probabilities(v, ink))
        truth.append(n_curves)
        done += n
    truth = torch.cat(truth)
    rows = []
    for v in inputs:
        lp = torch.cat(logp[v])
        right = lp.argmax(-1) + 1 == truth
        meta = load_model("MV", v)[1]
        row = {"weights": meta["name"], "trained_on": v, "images": len(truth),
               "accuracy": float(right.double().mean()),
               "nll_nats": float(-lp.gather(1, (truth - 1)[:, None]).mean()),
               "cpu_ms": cpu_ms(v, inks), "steps": meta.get("steps")}
        for k in (1, 2, 3):
            row[f"accuracy_{k}"] = float(right[truth == k].double().mean())
        rows.append(row)
        print(row, flush=True)
    columns = [("weights", "MV weights"), ("trained_on", "trained on"), ("images", "drawings"),
               ("accuracy", "right count"), ("accuracy_1", "1 curve"), ("accuracy_2", "2 curves"),
               ("accuracy_3", "3 curves"), ("nll_nats", "-ln P(true), nats"), ("cpu_ms", "CPU ms/vote"),
               ("steps", "training steps (this run)")]
    notes = ("Held-out drawings (seed 777) of 1 to 3 curves, 128 px, strokes 1 to 3 px, redrawn from their "
             "skeletons as the hybrid method hands them to MV (a quarter as large drawings are); see the "
             "module's docstring for the method.")
    write_results("curves_count", rows, columns, meta={"count": args.count, "held_out_seed": HELD_OUT_SEED},
                  title="The count vote of nurbskit curves: MV trained on redrawn drawings against MV trained "
                        "on the drawings", notes=notes)


if __name__ == "__main__":
    main()
