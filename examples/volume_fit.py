"""Fit a NURBS volume to the paper's three drawings from Python, and save the results.

    python examples/volume_fit.py OUTDIR [--preset default|paper]

The same fit and the same files as ``nurbskit volume front.png left.png top.png --out
OUTDIR`` on those drawings (``nurbskit.volume.outputs.write_outputs``).

The drawings are made by code (square front, circle left, heart top: no solid matches
all three); see docs/volume.md for the view convention and the costs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nurbskit.volume import fit_silhouettes, get_preset
from nurbskit.volume.outputs import write_outputs
from nurbskit.volume.shapes import paper_drawings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--preset", choices=("default", "paper"), default="default")
    args = parser.parse_args()

    d = paper_drawings(256)

    def progress(stage, done, total, cost):
        if stage == "fit" and done % 10 == 0:
            print(f"  iteration {done}/{total}  cost {cost:.3g}", file=sys.stderr)

    result = fit_silhouettes(d, get_preset(args.preset), callback=progress)
    args.outdir.mkdir(parents=True, exist_ok=True)
    report = {**result.report(), "preset": args.preset, "inputs": "nurbskit.volume.shapes.paper_drawings(256)"}
    print("wrote", ", ".join(write_outputs(result, args.outdir, report)))
    print("IoU", {k: round(v, 3) for k, v in result.iou.items()},
          "visual hull", {k: round(v, 3) for k, v in result.hull_iou.items()},
          f"{result.seconds['total']:.1f} s")


if __name__ == "__main__":
    main()
