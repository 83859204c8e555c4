"""Curves from images by the classical path (issue 10): synthetic drawn splines and MNIST digits.

Question: how close are the curves ``nurbskit.curves_from_image(method="classic")`` reads
from drawings, to the true curves (synthetic) and to the ink (MNIST), how often is the
number of curves right, and how long does one image take?

Method:

- Synthetic: ``--count`` images per number of curves (1, 2, 3) from
  :func:`nurbskit.curves.synthetic.make_sample` (the DeepSpline recipe: cubic,
  clamped uniform, 4-6 control points uniform in the image), seeds 100_000 + i (disjoint
  from the tests'), stroke width 1, 2 or 3 px by seed, at 128 x 128 and at 512 x 512.
  Per image: the symmetric Chamfer to the true curves (mean nearest distance between
  dense samples, 0.25 px apart, of the fitted and of the true curves, each way, and their
  mean), whether the number of curves is right, seconds (wall clock, after a warm-up).
- MNIST: the first ``--mnist`` test digits of ``../shared/data/mnist`` (IDX read with
  numpy; white on black, detected), upsampled 4x (bilinear, 112 x 112). Chamfer between
  the curves and the ink pixels (Otsu), both ways, in pixels of the upsampled image.
- Reported: per set the median and the 90th percentile of the symmetric Chamfer, the
  mean of each direction, the curve-count accuracy, the median seconds. The 128 px sets
  are run again with ``--refine`` (20 L-BFGS iterations on the Chamfer to the ink). One overlay
  figure (``results/curves_figures/overlays.png``) of synthetic and MNIST examples.

The issue's goals for the default method: <= 1 px for one curve and <= 1.5 px for two or
three, >= 90 % right counts, <= 2 px at 512 x 512, <= 2.5 px on MNIST to the ink; <= 300
ms for a 512 x 512 drawing. Timings are noisy on the shared machine.

Run: ``PYTHONPATH=src python benchmarks/bench_curves.py [--count 20] [--mnist 100]``.
"""

from __future__ import annotations

import argparse
import gzip
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import RESULTS, write_results  # noqa: E402

from nurbskit.curves.classic import chamfer_points, chamfer_to_ink, fit_image  # noqa: E402
from nurbskit.curves.synthetic import SyntheticConfig, dense_samples, make_sample  # noqa: E402

MNIST = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mnist" / "t10k-images-idx3-ubyte.gz"


def read_idx_images(path: Path, count: int) -> np.ndarray:
    """The first ``count`` images ``(count, 28, 28)`` uint8 of an IDX3 file (magic 2051)."""
    with gzip.open(path, "rb") as fh:
        header = np.frombuffer(fh.read(16), dtype=">i4")
        if header[0] != 2051:
            raise ValueError(f"{path}: not an IDX3 image file (magic {header[0]})")
        n, rows, cols = (int(v) for v in header[1:])
        count = min(count, n)
        data = np.frombuffer(fh.read(count * rows * cols), dtype=np.uint8)
    return data.reshape(count, rows, cols)


def upsample(image: np.ndarray, factor: int) -> np.ndarray:
    from skimage.transform import resize

    h, w = image.shape
    return resize(image.astype(np.float64) / 255.0, (h * factor, w * factor), order=1, anti_aliasing=False)


def synthetic_row(seed: int, n_curves: int, size: int, refine: int = 0) -> tuple[dict, object, list]:
    width = (1.0, 2.0, 3.0)[seed % 3]
    config = SyntheticConfig(size=(size, size), curves=(n_curves, n_curves), width=width)
    sample = make_sample(100_000 + seed, config)
    t = time.perf_counter()
    curves, strokes = fit_image(sample.image, refine_iterations=refine)
    seconds = time.perf_counter() - t
    truth = np.concatenate([dense_samples(c) for c in sample.curves()])
    got = np.concatenate([dense_samples(c) for c in curves]) if curves else np.zeros((0, 2))
    ch = chamfer_points(got, truth)
    label = f"synthetic {size}px, {n_curves} curve(s)" + (f", refined ({refine} L-BFGS)" if refine else "")
    return ({"set": label, "seed": 100_000 + seed, "width": width,
             "fit_to_truth": ch["curves_to_ink"], "truth_to_fit": ch["ink_to_curves"], "symmetric": ch["symmetric"],
             "curves": len(curves), "true_curves": n_curves, "count_right": len(curves) == n_curves,
             "seconds": seconds}, sample.image, curves)


def mnist_row(index: int, digit: np.ndarray) -> tuple[dict, np.ndarray, list]:
    image = upsample(digit, 4)
    t = time.perf_counter()
    curves, strokes = fit_image(image)
    seconds = time.perf_counter() - t
    ch = chamfer_to_ink(curves, strokes.ink)
    return ({"set": "MNIST test x4", "seed": index, "fit_to_truth": ch["curves_to_ink"],
             "truth_to_fit": ch["ink_to_curves"], "symmetric": ch["symmetric"], "curves": len(curves),
             "inverted": strokes.inverted, "seconds": seconds}, image, curves)


def summarise(rows: list[dict]) -> list[dict]:
    out = []
    for name in dict.fromkeys(r["set"] for r in rows):
        rs = [r for r in rows if r["set"] == name]
        sym = sorted(r["symmetric"] for r in rs)
        row = {
            "set": name, "images": len(rs),
            "symmetric_median": statistics.median(sym),
            "symmetric_p90": float(np.percentile(sym, 90)),
            "fit_to_truth_mean": statistics.fmean(r["fit_to_truth"] for r in rs),
            "truth_to_fit_mean": statistics.fmean(r["truth_to_fit"] for r in rs),
            "seconds_median": statistics.median(r["seconds"] for r in rs),
        }
        if "count_right" in rs[0]:
            row["count_accuracy"] = sum(r["count_right"] for r in rs) / len(rs)
        out.append(row)
    return out


def figure(examples: list, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = 4
    rows = (len(examples) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3 * cols, 3 * rows))
    for ax, (title, image, curves) in zip(np.ravel(axes), examples):
        h, w = image.shape
        ax.imshow(image, cmap="gray", extent=(0, w, h, 0), interpolation="nearest")
        for c in curves:
            p = dense_samples(c, 0.5)
            ax.plot(p[:, 0], p[:, 1], c="#e6194b", lw=1.2)
            cp = c.control_points.numpy()
            ax.plot(cp[:, 0], cp[:, 1], "o", c="#1f77b4", ms=2)
        ax.set_title(title, fontsize=8)
        ax.set_axis_off()
    for ax in np.ravel(axes)[len(examples):]:
        ax.set_axis_off()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=20, help="synthetic images per curve count and size")
    parser.add_argument("--large", type=int, default=5, help="synthetic 512 x 512 images per curve count")
    parser.add_argument("--mnist", type=int, default=100, help="MNIST test digits")
    args = parser.parse_args()
    torch.set_num_threads(1)
    synthetic_row(0, 1, 128)  # warm-up: imports, first-call costs
    rows, examples = [], []
    for n_curves in (1, 2, 3):
        for i in range(args.count):
            row, image, curves = synthetic_row(i, n_curves, 128)
            rows.append(row)
            if i < 2:
                examples.append((f"synthetic {n_curves}: {row['curves']} found, {row['symmetric']:.2f} px", image, curves))
    for n_curves in (1, 2, 3):  # the same images with Chamfer refinement against the ink
        for i in range(args.count):
            rows.append(synthetic_row(i, n_curves, 128, refine=20)[0])
    for n_curves in (1, 2, 3):
        for i in range(args.large):
            rows.append(synthetic_row(i, n_curves, 512)[0])
    if MNIST.exists():
        digits = read_idx_images(MNIST, args.mnist)
        for i, d in enumerate(digits):
            row, image, curves = mnist_row(i, d)
            rows.append(row)
            if i < 6:
                examples.append((f"MNIST #{i}: {row['curves']} curves, {row['symmetric']:.2f} px", image, curves))
    summary = summarise(rows)
    figure(examples, RESULTS / "curves_figures" / "overlays.png")
    columns = [("set", "set"), ("images", "images"), ("symmetric_median", "Chamfer sym. median (px)"),
               ("symmetric_p90", "p90 (px)"), ("fit_to_truth_mean", "curves->truth mean (px)"),
               ("truth_to_fit_mean", "truth->curves mean (px)"), ("count_accuracy", "curve count right"),
               ("seconds_median", "seconds median")]
    write_results("curves", summary, columns, meta={"per_image": rows, "count": args.count, "large": args.large,
                                                    "mnist": args.mnist},
                  title="Curves from images: the classical path (issue 10)",
                  notes="Synthetic: Chamfer to the true curves; MNIST: to the ink pixels (truth = ink). "
                        "Mean nearest distances in pixels. See benchmarks/bench_curves.py for the method.")
    print((RESULTS / "curves.md").read_text())


if __name__ == "__main__":
    main()
