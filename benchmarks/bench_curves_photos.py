"""Does ``nurbskit curves`` read a photographed drawing as it reads the clean drawing?

Method:

- Drawings: the benchmark's synthetic recipe (``nurbskit.curves.synthetic.make_sample``,
  seeds 100000 + i, 1 to 3 cubic curves, strokes 1, 2, 3 px by i mod 3), ``--count``
  per size, at 128 and 512 px.
- Photographs of each (``nurbskit.curves.synthetic.photograph``): a lamp lighting the
  page from one corner (brightness 0.95 to 0.4), a lens vignette (corners at 0.4), light
  strokes on a dark board under a round glow; each with Gaussian sensor noise of 0.02
  and 0.04 (seeded by the drawing).
- Per set, the default method (``nurbskit.curves.api.extract``, hybrid) on the clean
  drawing and on each photograph: the share of drawings with the right number of curves
  and the mean symmetric Chamfer distance in pixels to the true curves (dense samples
  0.25 px apart, mean nearest distance both ways, then their mean).
- The thresholding itself: the intersection over union of the ink found in the
  photograph with the clean drawing's ink (``classic.ink_mask``), by Otsu's threshold
  alone on the photograph (what ``nurbskit`` did before) and after
  ``classic.even_background``; and the CPU milliseconds of ``even_background`` (median,
  one thread).
- Figure: ``results/curves_photos_figures/photos.png``, the 512 px photographs with the
  curves read from them.

Run: ``PYTHONPATH=src python benchmarks/bench_curves_photos.py [--count 60]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import RESULTS, write_results  # noqa: E402
from bench_curves import figure  # noqa: E402

from nurbskit.curves.api import extract  # noqa: E402
from nurbskit.curves.classic import chamfer_points, even_background, ink_mask, to_grey  # noqa: E402
from nurbskit.curves.synthetic import LIGHTS, SyntheticConfig, dense_samples, make_sample, photograph  # noqa: E402

NOISES = (0.02, 0.04)
SIZES = (128, 512)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _otsu(grey: np.ndarray) -> np.ndarray:
    """The ink by Otsu's threshold alone, the smaller class (``ink_mask`` before lighting and
    noise were taken into account)."""
    from skimage.filters import threshold_otsu

    dark = grey <= threshold_otsu(grey)
    return ~dark if dark.mean() > 0.5 else dark


def _read(image: np.ndarray, truth: np.ndarray, n_curves: int):
    curves, _ = extract(to_grey(image))
    got = np.concatenate([dense_samples(c) for c in curves]) if curves else np.zeros((0, 2))
    return len(curves) == n_curves, chamfer_points(got, truth)["symmetric"], curves


def run(size: int, count: int) -> tuple[list[dict], list]:
    sets: dict[str, dict] = {}
    examples = []
    for i in range(count):
        width = (1.0, 2.0, 3.0)[i % 3]
        sample = make_sample(100_000 + i, SyntheticConfig(size=(size, size), width=width))
        truth = np.concatenate([dense_samples(c) for c in sample.curves()])
        clean_ink, _ = ink_mask(sample.image)
        right, chamfer, _ = _read(sample.image, truth, sample.n_curves)
        s = sets.setdefault("clean", {"right": [], "chamfer": []})
        s["right"].append(right)
        s["chamfer"].append(chamfer)
        for light in LIGHTS:
            for noise in NOISES:
                photo = photograph(sample.image, light, noise, seed=i)
                c = time.process_time()
                even = even_background(photo)
                even_ms = 1000 * (time.process_time() - c)
                right, chamfer, curves = _read(photo, truth, sample.n_curves)
                s = sets.setdefault(f"{light}, noise {noise}", {"right": [], "chamfer": [], "iou_otsu": [],
                                                                "iou_even": [], "even_ms": []})
                s["right"].append(right)
                s["chamfer"].append(chamfer)
                s["iou_otsu"].append(_iou(_otsu(photo), clean_ink))
                s["iou_even"].append(_iou(ink_mask(even)[0], clean_ink))
                s["even_ms"].append(even_ms)
                if size == 512 and i < 2 and noise == NOISES[0]:
                    examples.append((f"{light} #{i}: {len(curves)} curve(s), {chamfer:.2f} px", photo, curves))
    rows = []
    for name, s in sets.items():
        row = {"size": size, "set": name, "drawings": len(s["right"]), "count_right": float(np.mean(s["right"])),
               "chamfer_mean": statistics.fmean(s["chamfer"]), "chamfer_max": max(s["chamfer"])}
        if "iou_otsu" in s:
            row.update(iou_otsu=statistics.fmean(s["iou_otsu"]), iou_even=statistics.fmean(s["iou_even"]),
                       even_ms=statistics.median(s["even_ms"]))
        rows.append(row)
    return rows, examples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=60, help="drawings per size")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows, examples = [], []
    for size in SIZES:
        r, ex = run(size, args.count)
        rows += r
        examples += ex
        print(*r, sep="\n", flush=True)
    figure(examples, RESULTS / "curves_photos_figures" / "photos.png")
    columns = [("size", "px"), ("set", "drawings as"), ("drawings", "drawings"), ("count_right", "right count"),
               ("chamfer_mean", "Chamfer mean px"), ("chamfer_max", "Chamfer max px"),
               ("iou_otsu", "ink IoU, Otsu alone"), ("iou_even", "ink IoU, evened"),
               ("even_ms", "even_background CPU ms")]
    notes = ("Method: `benchmarks/bench_curves_photos.py` (docstring). The default method (hybrid) on each drawing "
             "clean and photographed; Chamfer to the true curves; ink IoU against the clean drawing's ink.")
    write_results("curves_photos", rows, columns, meta={"count": args.count, "noises": NOISES, "sizes": SIZES},
                  title="Curves from photographed drawings: uneven light and sensor noise", notes=notes)


if __name__ == "__main__":
    main()
