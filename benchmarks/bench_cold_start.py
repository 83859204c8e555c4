"""How long does a ``nurbskit`` command take from a fresh process, and what of it is imports?

Question: a user runs one command on one small input; the work itself takes a fraction
of a second, so the process's imports can be most of what they wait for. Where does
that time go, and does anything import more than the command needs?

Method: each command runs in a fresh Python process (``subprocess``, the repository's
``src`` first on the path), ``--repeats`` times (default 5) after one warm-up run that
fills the file-system cache; the median wall time is reported, and whether
``torch._dynamo`` and ``sympy`` were imported by the end (``torch.optim.Optimizer``'s constructor imports
the first on first use, 0.75 s with torch 2.13 on the 2-core machine; ``torch.broadcast_shapes``
the second, 0.3 s). "Beyond ``import torch``" is a command's median less that of ``import torch``
alone (``import nurbskit`` imports no torch). Inputs are generated into a temporary
folder: a 3,000-point smooth patch (``bench_fit_goals.smooth_patch``, 0.1 % noise) as
an ``.xyz`` file and a 128 x 128 drawing of two cubic B-splines (the curves recipe, seed
100001, 2 px strokes) as a PNG. Commands go through ``nurbskit.cli.main`` as the console
script does; ``--threads 2`` where the command has it. Rows:

* ``import torch`` and ``import nurbskit`` alone: the floor every command pays.
* ``nurbskit fit cloud.xyz --no-figures``: the default pipeline.
* ``nurbskit curves drawing.png``, without and with ``--refine`` (Chamfer against the ink by
  ``nurbskit.fit.optim.LBFGS``).

Run: ``python benchmarks/bench_cold_start.py [--quick] [--repeats 5] [--before OTHER/src] [--tag NAME]``; writes
``benchmarks/results/cold_start.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(SRC))
from _harness import write_results  # noqa: E402

# Run in the child: the statement, then whether the slow imports happened.
CHILD = """
import sys
sys.path.insert(0, {src!r})
{statement}
print("COLD", "torch._dynamo" in sys.modules, "sympy" in sys.modules)
"""


def run_child(statement: str, src: Path = SRC) -> tuple[float, str]:
    code = CHILD.format(src=str(src), statement=statement)
    env = dict(os.environ, OMP_NUM_THREADS="2")
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - start
    if out.returncode != 0:
        raise SystemExit(f"child failed ({out.returncode}): {out.stderr.strip()[-500:]}")
    line = [x for x in out.stdout.splitlines() if x.startswith("COLD")][-1].split()
    loaded = [name for name, flag in zip(("torch._dynamo", "sympy"), line[1:]) if flag == "True"]
    return wall, ", ".join(loaded) or "neither"


def main_statement(argv: list[str]) -> str:
    return f"from nurbskit.cli import main\nrc = main({argv!r})\nassert rc == 0, rc"


def make_inputs(folder: Path) -> tuple[Path, Path]:
    from PIL import Image

    from bench_fit_goals import smooth_patch
    from nurbskit.curves.synthetic import SyntheticConfig, make_sample

    cloud = folder / "cloud.xyz"
    np.savetxt(cloud, np.asarray(smooth_patch(3000, 0.001, 0)))
    sample = make_sample(100_001, SyntheticConfig(size=(128, 128), curves=(2, 2), width=2.0))
    drawing = folder / "drawing.png"
    Image.fromarray((np.clip(sample.image, 0, 1) * 255).astype(np.uint8)).save(drawing)
    return cloud, drawing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="2 repeats")
    parser.add_argument("--src", type=Path, default=SRC, help="the source tree whose nurbskit the commands run")
    parser.add_argument("--before", type=Path, default=None,
                        help="another checkout's src, run interleaved with --src (before, after, before, ...) "
                             "for a comparison made at the same time")
    parser.add_argument("--before-label", default="", help="what --before is, for the notes (a commit)")
    parser.add_argument("--tag", default="", help="suffix of the results' name (cold_start_TAG)")
    args = parser.parse_args()
    if args.quick:
        args.repeats = 2
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cloud, drawing = make_inputs(folder)
        out = str(folder / "out")
        commands = [
            ("import torch", "import torch"),
            ("import nurbskit", "import nurbskit"),
            ("nurbskit fit cloud.xyz (3,000 points, default pipeline)",
             main_statement(["fit", str(cloud), "--out", out, "--overwrite", "--no-figures", "--quiet",
                             "--threads", "2"])),
            ("nurbskit curves drawing.png (128 px, 2 curves)",
             main_statement(["curves", str(drawing), "--out", out, "--overwrite"])),
            ("nurbskit curves drawing.png --refine",
             main_statement(["curves", str(drawing), "--out", out, "--overwrite", "--refine"])),
        ]
        trees = {"": args.src} | ({"before_": args.before} if args.before else {})
        rows = []
        for label, statement in commands:
            row = {"command": label, "repeats": args.repeats}
            for src in trees.values():
                run_child(statement, src)  # warm-up: the file-system cache
            walls = {key: [] for key in trees}
            loaded = {key: [] for key in trees}
            for _ in range(args.repeats):
                for key, src in trees.items():  # interleaved: the same moment's machine for both
                    wall, slow = run_child(statement, src)
                    walls[key].append(wall)
                    loaded[key].append(slow)
            for key in trees:
                row[key + "wall_s_median"] = statistics.median(walls[key])
                row[key + "wall_s_min"] = min(walls[key])
                row[key + "slow_imports"] = loaded[key][-1]
            rows.append(row)
            print(row, flush=True)
    for key in trees:
        floor = rows[0][key + "wall_s_median"]
        for r in rows[2:]:  # the commands; import nurbskit imports no torch
            r[key + "beyond_import_torch_s"] = r[key + "wall_s_median"] - floor
    columns = [("command", "command"), ("wall_s_median", "wall s, median"), ("wall_s_min", "wall s, min"),
               ("beyond_import_torch_s", "beyond `import torch`, s"),
               ("slow_imports", "torch._dynamo, sympy imported")]
    if args.before:
        columns += [("before_wall_s_median", "before: wall s, median"),
                    ("before_beyond_import_torch_s", "before: beyond `import torch`, s"),
                    ("before_slow_imports", "before: imported")]
    notes = ("Fresh processes, median of the repeats after a warm-up run (method in the module docstring). "
             "`torch._dynamo` is imported by `torch.optim.Optimizer`'s constructor on first use; nurbskit's "
             "one L-BFGS (`nurbskit.fit.optim`: the fitting loop, the curves' Chamfer refinement, the shape and "
             "volume fits) is a plain class since the sixteenth session. `sympy` is imported by "
             "`torch.broadcast_shapes` on first use (the Chamfer loss, a batched evaluation); nurbskit takes "
             "numpy's since the seventeenth. "
             + (f"Before: the commands run from {args.before_label or args.before}, interleaved with these. "
                if args.before else "")
             + "Load averages at the end: " + ", ".join(f"{v:.1f}" for v in os.getloadavg()) + ".")
    name = "cold_start" + (f"_{args.tag}" if args.tag else "")
    meta = {"repeats": args.repeats, "before": args.before_label or (str(args.before) if args.before else None)}
    print(write_results(name, rows, columns, meta=meta,
                        title="nurbskit commands from a fresh process", notes=notes))


if __name__ == "__main__":
    main()
