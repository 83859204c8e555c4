"""How long does a curve network's training step take, and how much of it is making the drawings? (issue 10)

Method: the batch makers of ``nurbskit train curves`` (MV on the drawings themselves, and
``--input redrawn``), 32 drawings a batch at the recipe's 128 px, one torch thread. Per
maker: the mean over ``--steps`` batches (after 3 warm-up batches, seeds by step as the
training loop draws them) of the time to make the batch and of the time of one AdamW step
on it (forward, loss, backward) of a freshly built MV network. ``--before PATH/src``
renders the same batches with another tree's ``synthetic.render_batch`` in the same
process and checks that the images are equal to the bit; the ratio is before / now.

Usage: OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/bench_curves_training_data.py [--steps N]
       [--before OTHER/src --before-label COMMIT]   (e.g. git worktree add /tmp/old 6f624a1)
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

from nurbskit.curves import synthetic  # noqa: E402
from nurbskit.curves.nets.models import build  # noqa: E402
from nurbskit.curves.nets.train import LOSSES, TRAIN_SPACING, batch_maker, redrawn_batch_maker  # noqa: E402
from nurbskit.learn import batch_generator  # noqa: E402


def other_render(src: Path):
    """``render_batch`` of another tree's ``synthetic.py`` (its relative imports pointed at this nurbskit)."""
    path = src / "nurbskit" / "curves" / "synthetic.py"
    spec = importlib.util.spec_from_file_location("nurbskit.curves._synthetic_before", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module.render_batch


def timed(maker, steps: int, render) -> dict:
    synthetic.render_batch = render
    model = build("MV")
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-3)
    data_s = step_s = 0.0
    for i in range(steps + 3):
        t0 = time.perf_counter()
        data = maker(batch_generator(12, i), 32)
        t1 = time.perf_counter()
        loss, _ = LOSSES["MV"](model, data)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if i >= 3:
            data_s += t1 - t0
            step_s += time.perf_counter() - t1
    return {"data_ms": data_s / steps * 1e3, "network_ms": step_s / steps * 1e3,
            "step_ms": (data_s + step_s) / steps * 1e3}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--before", type=Path, help="another tree's src/, timed beside this one")
    parser.add_argument("--before-label", help="how the results name that tree (a commit); default its path")
    args = parser.parse_args()
    torch.set_num_threads(1)
    now = synthetic.render_batch
    before = other_render(args.before) if args.before else None
    if before is not None:
        config = synthetic.mode_config("MV", 128)
        for seed in range(5):
            synthetic.render_batch = before
            a = synthetic.make_torch_batch(batch_generator(12, seed), 32, config, spacing=TRAIN_SPACING)
            synthetic.render_batch = now
            b = synthetic.make_torch_batch(batch_generator(12, seed), 32, config, spacing=TRAIN_SPACING)
            assert torch.equal(a.image, b.image), "the two renderers differ"
    rows = []
    for name, maker in (("MV, drawings", batch_maker("MV", 64)), ("MV, redrawn", redrawn_batch_maker("MV", 64))):
        row = {"batches": name, **timed(maker, args.steps, now)}
        if before is not None:
            old = timed(maker, args.steps, before)
            row.update({f"before_{k}": v for k, v in old.items()})
            row["data_x"] = old["data_ms"] / row["data_ms"]
            row["step_x"] = old["step_ms"] / row["step_ms"]
        synthetic.render_batch = now
        print(row, flush=True)
        rows.append(row)
    columns = [("batches", "batches"), ("data_ms", "make a batch, ms"), ("network_ms", "network step, ms"),
               ("step_ms", "training step, ms")]
    if before is not None:
        columns += [("before_data_ms", "before: make a batch, ms"), ("before_step_ms", "before: training step, ms"),
                    ("data_x", "batch x faster"), ("step_x", "step x faster")]
    notes = (f"32 drawings a batch, one torch thread, mean of {args.steps} steps after 3 warm-up steps"
             + (f"; before = `{args.before_label or args.before}` in the same process, its images equal to the bit" if before else "") + ".")
    print(write_results("curves_training_data", rows, columns, meta={"steps": args.steps},
                        title="Training steps of the curve networks: making the drawings and the network", notes=notes))


if __name__ == "__main__":
    main()
