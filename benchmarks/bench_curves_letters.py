"""Are capital letters drawn with straight pen strokes read as their strokes by ``nurbskit curves``?

The synthetic benchmark (``bench_curves.py``) draws random cubic curves; people draw
letters, whose strokes meet at T, Y, K and A junctions that random curves seldom make.
This asks how the junction rules read them.

Method:

- Drawings: 14 letters and signs of straight strokes (``LETTERS``: each a few polylines
  in a 100 x 160 box), drawn with ``PIL.ImageDraw.line`` (round joints) black on white,
  20 px margins, at three sizes: scale 0.5, 1 and 2 (letters 80, 160 and 320 px tall,
  pens 2, 4 and 8 px).
- Expected: each letter's range of curve counts a reader would accept (``LETTERS``: an
  "A" is its legs and crossbar, two curves, or three with the legs split at the apex; a
  "4" one to three, its corners being corners or ends).
- Read by the default method (``hybrid``) and by the classical path alone
  (``--method classic``), through ``nurbskit.curves.api.extract``.
- Reported per method and size: the letters read with an accepted count, the ones not
  (with what they were read as), and the mean symmetric Chamfer distance in pixels
  between dense samples of the curves and of the drawn polylines (PIL's point ``(x,
  y)`` is the centre of pixel ``(x, y)``, so the polylines move by half a pixel into
  nurbskit's coordinates). Overlays: ``results/curves_letters_figures/{method}_{scale}.png``.

Run: ``PYTHONPATH=src python benchmarks/bench_curves_letters.py``.
Results: ``results/curves_letters.{json,md}``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import RESULTS, write_results  # noqa: E402

from nurbskit.curves.api import extract  # noqa: E402
from nurbskit.curves.classic import chamfer_points  # noqa: E402
from nurbskit.curves.synthetic import dense_samples  # noqa: E402

# name: (polylines in a 100 x 160 box, (fewest, most) curves accepted)
LETTERS = {
    "A": ([[(0, 160), (50, 0), (100, 160)], [(20, 100), (80, 100)]], (2, 3)),
    "E": ([[(100, 0), (0, 0), (0, 160), (100, 160)], [(0, 80), (80, 80)]], (2, 3)),
    "F": ([[(100, 0), (0, 0), (0, 160)], [(0, 80), (80, 80)]], (2, 3)),
    "H": ([[(0, 0), (0, 160)], [(100, 0), (100, 160)], [(0, 80), (100, 80)]], (3, 3)),
    "K": ([[(0, 0), (0, 160)], [(90, 0), (0, 90)], [(25, 65), (95, 160)]], (2, 3)),
    "N": ([[(0, 160), (0, 0), (100, 160), (100, 0)]], (1, 3)),
    "T": ([[(0, 0), (100, 0)], [(50, 0), (50, 160)]], (2, 2)),
    "V": ([[(0, 0), (50, 160), (100, 0)]], (1, 2)),
    "X": ([[(0, 0), (100, 160)], [(100, 0), (0, 160)]], (2, 2)),
    "Y": ([[(0, 0), (50, 80), (100, 0)], [(50, 80), (50, 160)]], (2, 2)),
    "Z": ([[(0, 0), (100, 0), (0, 160), (100, 160)]], (1, 3)),
    "4": ([[(70, 160), (70, 0), (0, 110), (100, 110)]], (1, 3)),
    "t": ([[(40, 0), (40, 150), (70, 160)], [(10, 50), (80, 50)]], (2, 2)),
    "+": ([[(0, 80), (100, 80)], [(50, 20), (50, 140)]], (2, 2)),
}
SCALES = (0.5, 1.0, 2.0)
# The letters not accepted at commit 95c1c23, before the hairpin rule's straight-on test
# (this benchmark run on that commit's package).
BEFORE_COMMIT = "95c1c23"
BEFORE = {("hybrid", 0.5): "A (1), H (2), Y (1)", ("hybrid", 1.0): "A (1), H (2), Y (1)",
          ("hybrid", 2.0): "H (2), Y (1)", ("classic", 0.5): "A (1), Y (1)",
          ("classic", 1.0): "A (1), K (1), Y (1)", ("classic", 2.0): "A (1), Y (1)"}
METHODS = ("hybrid", "classic")
MARGIN = 20


def drawing(polylines, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """A letter drawn at ``scale`` -> (grey image in [0, 1], dense samples of its strokes (x, y))."""
    from PIL import Image, ImageDraw

    pen = max(2, int(round(4 * scale)))
    image = Image.new("L", (int(100 * scale) + 2 * MARGIN, int(160 * scale) + 2 * MARGIN), 255)
    draw = ImageDraw.Draw(image)
    truth = []
    for line in polylines:
        pts = [(MARGIN + x * scale, MARGIN + y * scale) for x, y in line]
        draw.line(pts, fill=0, width=pen, joint="curve")
        p = np.asarray(pts, dtype=float) + 0.5  # PIL's (x, y) is the centre of pixel (x, y)
        for a, b in zip(p[:-1], p[1:]):
            n = max(2, int(np.ceil(np.linalg.norm(b - a) / 0.25)) + 1)
            truth.append(np.linspace(a, b, n))
    return np.asarray(image, dtype=np.float64) / 255.0, np.concatenate(truth)


def figure(readings: list, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 7, figsize=(21, 8))
    for ax, (name, grey, curves, ok) in zip(axes.flat, readings):
        ax.imshow(grey, cmap="gray", vmin=0, vmax=1)
        for c in curves:
            p = dense_samples(c, 0.5)
            ax.plot(p[:, 0] - 0.5, p[:, 1] - 0.5, lw=2)
        ax.set_title(f"{name}: {len(curves)} curve(s){'' if ok else ' (not accepted)'}", fontsize=11)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=60)
    plt.close(fig)


def main() -> None:
    import torch

    torch.set_num_threads(1)
    figures = RESULTS / "curves_letters_figures"
    figures.mkdir(parents=True, exist_ok=True)
    rows = []
    for method in METHODS:
        for scale in SCALES:
            readings, wrong, chamfers = [], [], []
            for name, (polylines, (lo, hi)) in LETTERS.items():
                grey, truth = drawing(polylines, scale)
                curves, _ = extract(grey, method=method)
                ok = lo <= len(curves) <= hi
                if not ok:
                    wrong.append(f"{name} ({len(curves)})")
                got = np.concatenate([dense_samples(c, 0.25) for c in curves])
                chamfers.append(chamfer_points(got, truth)["symmetric"])
                readings.append((name, grey, curves, ok))
            figure(readings, figures / f"{method}_{scale:g}.png")
            row = {"method": method, "scale": scale, "height_px": int(160 * scale),
                   "pen_px": max(2, int(round(4 * scale))), "letters": len(LETTERS),
                   "accepted": len(LETTERS) - len(wrong), "not_accepted": ", ".join(wrong) or "-",
                   "not_accepted_before": BEFORE.get((method, scale), ""),
                   "chamfer_mean": float(np.mean(chamfers)), "chamfer_max": float(np.max(chamfers))}
            rows.append(row)
            print(row, flush=True)
    columns = [("method", "method"), ("height_px", "letter height (px)"), ("pen_px", "pen (px)"),
               ("letters", "letters"), ("accepted", "read with an accepted count"),
               ("not_accepted", "not (curves read)"), ("not_accepted_before", f"not, at {BEFORE_COMMIT}"),
               ("chamfer_mean", "Chamfer to the strokes, mean (px)"),
               ("chamfer_max", "max (px)")]
    notes = ("Letters of straight strokes drawn with PIL (round joints), read by `nurbskit curves`; accepted "
             "counts per letter in the benchmark's `LETTERS` (e.g. an A: 2 or 3 curves). Overlays: "
             "`curves_letters_figures/`. Method: the module's docstring.")
    write_results("curves_letters", rows, columns, meta={"scales": list(SCALES)},
                  title="Letters of straight pen strokes: are they read as their strokes?", notes=notes)


if __name__ == "__main__":
    main()
