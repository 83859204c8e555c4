"""Does MV count curves worse than M because of its model or because of its drawings?

Question: on their own held-out drawings the shipped M counts the curves right in 98.7 %
of the images and MV in 94.5 % (``results/curves_nets.md``), with the same encoder. The
two recipes differ: M's curves have 5 control points each, MV's 4 to 6 (the paper's
recipes, ``nurbskit.curves.synthetic.mode_config``). Is the gap in the networks or in the
drawings they are asked to count?

Method: both shipped networks (``nurbskit.curves.nets.predict.load_model``) read both
recipes' held-out drawings: ``--count`` drawings each, 128 px, drawn as
``bench_curves_nets.py`` draws table 2's (``make_torch_batch`` from
``batch_generator(777, chunk)``, chunks of 100, area-averaged to the networks' 64 px),
so each network's own recipe repeats table 2's curve count exactly. Each network's
reading is the library's (``predict._raw``: its curve stops for up to three curves), the
count its first STOP over 1/2 (``train.predicted_count``), as table 2 counts. Reported per
network and recipe: the share counted right (and the images read as fewer or more
curves than drawn), split by the number of true curves and, on
MV's drawings, by the largest number of control points among a drawing's curves.

Reading: if MV counts M's drawings about as well as M does, the gap between the two
networks' table-2 numbers is in the drawings (the 6-point curves loop and cross more),
not in MV's model; if M counts MV's drawings as well as it counts its own, the gap is
MV's.

Run: ``PYTHONPATH=src python benchmarks/bench_curves_count_recipes.py [--count 2000]``.
Results: ``results/curves_count_recipes.{json,md}`` (about a minute, one thread).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402
from bench_curves_nets import HELD_OUT_SEED, SIZE  # noqa: E402

from nurbskit.curves.nets.predict import _raw, load_model  # noqa: E402
from nurbskit.curves.nets.train import network_inputs, predicted_count  # noqa: E402
from nurbskit.curves.synthetic import make_torch_batch, mode_config  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402

NETWORKS = RECIPES = ("M", "MV")


def counted(count: int, chunk: int = 100) -> list[dict]:
    """One row per (network, recipe, subset): images and the share of curve counts right."""
    models = {mode: load_model(mode) for mode in NETWORKS}
    rows = []
    for recipe in RECIPES:
        config = mode_config(recipe, SIZE)
        tally: dict[tuple, list[int]] = {}  # (network, subset) -> [right, images]
        done = 0
        while done < count:
            n = min(chunk, count - done)
            batch = make_torch_batch(batch_generator(HELD_OUT_SEED, done // chunk), n, config)
            truth = batch.n_curves
            valid = torch.arange(batch.counts.shape[1]) < truth[:, None]
            most = (batch.counts * valid).amax(1)  # the largest control-point count in each drawing
            for mode, (model, meta) in models.items():
                ink, _ = network_inputs(batch, meta["size"])
                with torch.no_grad():
                    read = predicted_count(_raw(model, ink)[2])
                right, fewer, more = read == truth, read < truth, read > truth
                subsets = [("all", torch.ones_like(right))]
                subsets += [(f"{k} curve(s)", truth == k) for k in (1, 2, 3)]
                if recipe == "MV":
                    subsets += [(f"most control points {p}", most == p) for p in (4, 5, 6)]
                for name, mask in subsets:
                    t = tally.setdefault((mode, name), [0, 0, 0, 0])
                    for i, hit in enumerate((right, fewer, more, torch.ones_like(right))):
                        t[i] += int((hit & mask).sum())
            done += n
        for (mode, name), (right, fewer, more, images) in tally.items():
            rows.append({"network": mode, "recipe": recipe, "drawings": name, "images": images,
                         "curve_acc": right / max(images, 1), "read_fewer": fewer, "read_more": more,
                         "own_recipe": mode == recipe})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=2000, help="held-out drawings per recipe")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = counted(args.count)
    for row in rows:
        print(row)
    notes = ("Both shipped multi-curve networks on both recipes' held-out drawings (128 px, seed 777, as "
             "table 2 of bench_curves_nets.py); curve count: the first curve STOP over 1/2. Recipes: M, "
             "1-3 curves of 5 control points; MV, 1-3 curves of 4-6 control points.")
    columns = [("network", "network"), ("recipe", "drawings of recipe"), ("drawings", "subset"),
               ("images", "images"), ("curve_acc", "curve count right"), ("read_fewer", "read as fewer"),
               ("read_more", "read as more"), ("own_recipe", "own recipe")]
    write_results("curves_count_recipes", rows, columns, meta={"count": args.count, "held_out_seed": HELD_OUT_SEED,
                                                                 "size": SIZE},
                  title="M and MV counting each other's drawings (issue 10)", notes=notes)


if __name__ == "__main__":
    main()
