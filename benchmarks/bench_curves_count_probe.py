"""Does the MV network know each curve's number of control points better than it says?

Question: MV reads the right number of control points for about 55 % of the curves
(issue 10 asks 90 %). Is the count in the network's representation and lost in the
decoding (the first stop probability over 1/2), so that a head trained on the shipped,
frozen network could read it, or is it not there?

Method: the shipped MV weights (``nurbskit.curves.nets.predict.load_model("MV")``), the
drawings of its training recipe (``nets.train.batch_maker("MV")``: 128 px, 2 px strokes,
area-averaged to 64 px). Every curve of ``--train`` batches of 100 drawings (seed 424242,
which no training run uses) and of 20 held-out batches (seed 777, the benchmark's) is
decoded for the true number of curves and 6 steps (``model(ink, k, 6)``, as the training
loss runs it), matched to the true curves by the Hungarian helper of the loss
(``nets.train.hungarian`` on the same cost), and labelled with its matched curve's true
count. Features per curve, captured by forward hooks on the point decoder (its loop is
not copied): the GRU state and the attention context at steps 4, 5 and 6, the stop
logits there, and the six predicted points (690 numbers). Probes: logistic regression and
a one-hidden-layer MLP (scikit-learn, standardised features), trained on the training
curves, scored on the held-out ones, beside the network's own decoding
(``nets.train.predicted_count``) on the same curves.

Reading: a probe well above the decoding means the count is there and a head could read
it; a probe at the decoding's level means the representation does not hold it, and the
network itself has to learn it (a larger encoder, more steps, another decoder).

Run: ``PYTHONPATH=src python benchmarks/bench_curves_count_probe.py [--train 100]``.
Results: ``results/curves_count_probe.{json,md}`` (about a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "src"))
from _harness import write_results  # noqa: E402

from nurbskit.curves.nets.models import MIN_POINTS  # noqa: E402
from nurbskit.curves.nets.predict import load_model  # noqa: E402
from nurbskit.curves.nets.train import batch_maker, hungarian, predicted_count  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402

TRAIN_SEED, HELD_OUT_SEED, STEPS, READ = 424242, 777, 6, slice(3, 6)


def curve_features(model, make, seed: int, batches: int, size: int = 100):
    """``(features (C, F), true counts (C,), decoded counts (C,))`` of every true curve."""
    states, contexts = [], []
    hooks = [model.points.cell.register_forward_hook(lambda m, i, out: states.append(out)),
             model.points.attend.register_forward_hook(lambda m, i, out: contexts.append(out[0]))]
    X, Y, decoded = [], [], []
    try:
        for i in range(batches):
            ink, unit, counts, n_curves = make(batch_generator(seed, i), size)
            k = int(n_curves.max())
            states.clear()
            contexts.clear()
            with torch.no_grad():
                pred, stops, _ = model(ink, k, STEPS)  # (B, k, T, 2) each
            b = ink.shape[0]
            h = torch.stack(states, 1).view(b, k, STEPS, -1)
            ctx = torch.stack(contexts, 1).view(b, k, STEPS, -1)
            target, cnt = unit[:, :k, :STEPS], counts[:, :k]
            tmask = (torch.arange(STEPS) < cnt[..., None]).float()
            d = ((pred[:, :, None] - target[:, None]) ** 2).sum(-1)
            cost = (d * tmask[:, None]).sum(-1) / tmask.sum(-1).clamp(min=1)[:, None]  # as loss_mv
            true = cnt.gather(1, hungarian(cost, n_curves))
            read = predicted_count(stops, MIN_POINTS)
            f = torch.cat([h[:, :, READ].flatten(2), ctx[:, :, READ].flatten(2), stops[:, :, READ].flatten(2),
                           pred.flatten(2)], -1)
            valid = torch.arange(k) < n_curves[:, None]
            X.append(f[valid].numpy())
            Y.append(true[valid].numpy())
            decoded.append(read[valid].numpy())
    finally:
        for hook in hooks:
            hook.remove()
    return np.concatenate(X), np.concatenate(Y), np.concatenate(decoded)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=int, default=100, help="batches of 100 training drawings for the probes")
    args = parser.parse_args()
    from sklearn.linear_model import LogisticRegression
    from sklearn.neural_network import MLPClassifier
    from sklearn.preprocessing import StandardScaler

    torch.manual_seed(0)
    model, meta = load_model("MV")
    make = batch_maker("MV", meta["size"])
    start = time.time()
    x_train, y_train, _ = curve_features(model, make, TRAIN_SEED, args.train)
    x_test, y_test, decoded = curve_features(model, make, HELD_OUT_SEED, 20)
    scale = StandardScaler().fit(x_train)
    probes = {"logistic regression": LogisticRegression(max_iter=2000),
              "MLP, 256 hidden units": MLPClassifier(hidden_layer_sizes=(256,), max_iter=200, early_stopping=True,
                                                     random_state=0)}
    rows = [{"reader": "the network's decoding (first stop over 1/2)", "held_out_accuracy": float((decoded == y_test).mean()),
             "train_accuracy": "-"}]
    for name, probe in probes.items():
        probe.fit(scale.transform(x_train), y_train)
        rows.append({"reader": f"probe: {name}",
                     "held_out_accuracy": float((probe.predict(scale.transform(x_test)) == y_test).mean()),
                     "train_accuracy": float((probe.predict(scale.transform(x_train)) == y_train).mean())})
    for row in rows:
        print(row, flush=True)
    counts = {int(c): int((y_test == c).sum()) for c in np.unique(y_test)}
    notes = (f"The shipped MV weights ({meta.get('steps')} steps). Training curves: {len(y_train)} from {args.train} "
             f"batches of seed {TRAIN_SEED}; held-out curves: {len(y_test)} from 20 batches of seed {HELD_OUT_SEED} "
             f"(true counts {counts}; always answering the commonest would score "
             f"{max(counts.values()) / len(y_test):.3f}). Features per curve: {x_train.shape[1]} (method in the "
             f"module docstring). {time.time() - start:.0f} s.")
    print(write_results("curves_count_probe", rows,
                        [("reader", "reader of each curve's count"), ("held_out_accuracy", "held-out accuracy"),
                         ("train_accuracy", "training accuracy")],
                        meta={"train_batches": args.train, "train_curves": len(y_train), "held_out_curves": len(y_test)},
                        title="Is the point count in the MV network's states? (issue 10)", notes=notes))


if __name__ == "__main__":
    main()
