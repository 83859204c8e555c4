"""Write example drawings for `nurbskit volume` as PNG files.

    python examples/volume_drawings.py OUTDIR [--size 256]

Writes two sets: the paper's inconsistent set (square front, circle left, heart top)
as dark shapes on white paper, and the three consistent silhouettes of a sphere joined
to a box as white shapes on black (the command detects either polarity). Then:

    nurbskit volume --front OUTDIR/paper_front.png --left OUTDIR/paper_left.png \\
        --top OUTDIR/paper_top.png --out OUTDIR/paper_fit
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

from nurbskit.volume.shapes import paper_drawings, solid_drawings, sphere_and_box


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--size", type=int, default=256)
    args = parser.parse_args()
    args.outdir.mkdir(parents=True, exist_ok=True)
    for view, mask in paper_drawings(args.size).items():
        # dark ink on white paper
        Image.fromarray(((1 - mask.numpy()) * 255).astype(np.uint8)).save(args.outdir / f"paper_{view}.png")
    for view, mask in solid_drawings(sphere_and_box, args.size).items():
        # light shape on black, to show the polarity detection
        Image.fromarray((mask.numpy() * 255).astype(np.uint8)).save(args.outdir / f"spherebox_{view}.png")
    print(f"wrote 6 drawings to {args.outdir}")


if __name__ == "__main__":
    main()
