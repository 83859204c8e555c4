"""``nurbskit curves``: B-spline curves from a drawing (issue 10; DeepSpline, 2D).

Writes to ``--out`` (built under a temporary name and moved into place):

====================  ==========================================================
``curves.json``       ``{"coordinates": ..., "curves": [nurbskit curve objects]}``
                      in pixel coordinates: x to the right, y down, the origin at
                      the top-left corner of the top-left pixel
``curves.svg``        the image with the curves over it (exact cubic Bezier paths)
``overlay.png``       the image in grey with the curves in red
``report.json``       counts, Chamfer between the curves and the ink pixels both
                      ways (mean distance in pixels), polarity, stroke width, seconds
====================  ==========================================================

Examples::

    nurbskit curves digit.png --out out/digit
    nurbskit curves sketch.jpg --out out/sketch --tolerance 2 --refine
    nurbskit curves phone_photo.jpg --out out/photo
    nurbskit curves splines.png --out out/net --method network --mode MV --refine
"""

from __future__ import annotations

import base64
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import OptionError
from ._options import int_in, number_in


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "curves", help="B-spline curves from a drawing (handwriting, sketches, line art, photographs of them)",
        description="Trace the strokes of IMAGE (dark on light or light on dark, detected; a photograph's uneven "
                    "lighting is evened first) and fit a cubic B-spline to each; write curves.json, curves.svg, "
                    "overlay.png and report.json to --out.",
    )
    p.add_argument("image", metavar="IMAGE", help="image file (PNG, JPEG, BMP, TIFF, ...)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--method", choices=("hybrid", "classic", "network", "auto"), default="hybrid",
                   help="hybrid: skeleton, strokes, least squares, with the MV network's vote on the number of "
                        "curves (default); classic: the same without the network; network: the shipped DeepSpline "
                        "network of --mode; auto: both (the network refined), the one closer to the ink kept")
    p.add_argument("--mode", choices=("V", "M", "MV"), default=None,
                   help="network of --method network: V one curve of 4-6 control points, M 1-3 curves of 5, "
                        "MV 1-3 curves of 4-6 (default); hybrid and auto use MV, classic no network")
    p.add_argument("--tolerance", type=number_in(0, 1000, low_open=True), default=1.0, metavar="PX",
                   help="largest distance in pixels from a stroke's skeleton to its curve (default 1)")
    p.add_argument("--refine", action="store_true",
                   help="refine the control points by Chamfer against the ink pixels (L-BFGS); with --method "
                        "network the network's readings in four views are the starts, the one closest to the ink "
                        "kept")
    p.add_argument("--refine-iters", type=int_in(1, 1000), default=20, metavar="N",
                   help="L-BFGS iterations of --refine (default 20)")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars (shown on stderr for stages that last over a second)")
    p.set_defaults(run=run_curves)


def _svg_path(curve) -> str:
    """An SVG path of a polynomial curve of degree <= 3: its Bezier pieces (exact)."""
    from ..core.ops import decompose_bezier, elevate_degree

    while curve.degree < 3:
        curve = elevate_degree(curve)
    pieces = decompose_bezier(curve)
    start = pieces[0].control_points[0].tolist()
    parts = [f"M {start[0]:.3f} {start[1]:.3f}"]
    for piece in pieces:
        b = piece.control_points.tolist()
        parts.append("C " + " ".join(f"{x:.3f} {y:.3f}" for x, y in b[1:]))
    return " ".join(parts)


def _png_bytes(grey: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.round(255 * np.clip(grey, 0, 1)).astype(np.uint8), mode="L").save(buf, format="PNG")
    return buf.getvalue()


def write_svg(path: Path, grey: np.ndarray, curves: list) -> None:
    """The image (embedded PNG) with the curves as red paths; one SVG unit = one pixel."""
    from .._fs import atomic_open

    h, w = grey.shape
    stroke = max(0.5, min(h, w) / 200)
    image = base64.b64encode(_png_bytes(grey)).decode("ascii")
    lines = [f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
             f'width="{w}" height="{h}" viewBox="0 0 {w} {h}">',
             f'<image x="0" y="0" width="{w}" height="{h}" style="image-rendering:pixelated" '
             f'xlink:href="data:image/png;base64,{image}"/>',
             f'<g fill="none" stroke="#e6194b" stroke-width="{stroke:.2f}" stroke-linecap="round">']
    lines += [f'<path d="{_svg_path(c)}"/>' for c in curves]
    lines += ["</g>", "</svg>"]
    with atomic_open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_curves_json(path: Path, curves: list, size: tuple[int, int]) -> None:
    """``{"coordinates", "size": [w, h], "curves": [nurbskit curve objects]}``, in pixel coordinates."""
    from .._fs import atomic_open
    from ..core.serialize import to_dict
    from ..curves.api import COORDINATES

    with atomic_open(path, "w") as fh:
        json.dump({"coordinates": COORDINATES, "size": [int(size[0]), int(size[1])],
                   "curves": [to_dict(c) for c in curves]}, fh, indent=1)


def write_overlay(path: Path, grey: np.ndarray, curves: list) -> None:
    """The image in grey (scaled up to at least 512 px) with the curves in red and control points in blue."""
    from PIL import Image, ImageDraw

    from .._fs import atomic_path
    from ..curves.synthetic import dense_samples

    h, w = grey.shape
    scale = max(1, int(np.ceil(512 / max(h, w)))) if max(h, w) < 512 else 1
    base = Image.fromarray(np.round(255 * (0.35 + 0.65 * np.clip(grey, 0, 1))).astype(np.uint8), mode="L")
    base = base.resize((w * scale, h * scale), Image.NEAREST).convert("RGB")
    draw = ImageDraw.Draw(base)
    width = max(1, scale // 2)
    for c in curves:
        pts = dense_samples(c, spacing=1.0 / scale) * scale
        draw.line([tuple(p) for p in pts], fill=(230, 25, 75), width=width)
        for x, y in c.control_points.detach().numpy() * scale:
            r = max(1.5, scale / 2)
            draw.ellipse([x - r, y - r, x + r, y + r], outline=(0, 90, 200))
    with atomic_path(path) as tmp:
        base.save(tmp, format="PNG")


def run_curves(args) -> int:
    from .._fs import atomic_open, check_output_dir, output_directory
    from ..curves.api import COORDINATES, extract, read_image, thick_note
    from ..curves.classic import chamfer_to_ink
    from ._progress import StageBars

    uses = {"network": args.mode or "MV", "hybrid": "MV", "auto": "MV"}.get(args.method)
    if args.mode is not None and args.mode != uses:
        raise OptionError(f"--mode {args.mode}: --method {args.method} reads "
                          + (f"with the {uses} network" if uses else "without a network")
                          + "; choose the network with --method network --mode " + args.mode)
    check_output_dir(args.out, args.overwrite, inputs=[args.image])
    start = time.perf_counter()
    grey = read_image(args.image)
    bars = StageBars(args.quiet, delay=1.0)  # a large drawing's stages; quick ones print nothing
    try:
        curves, strokes = extract(grey, method=args.method, mode=uses or "MV", tolerance=args.tolerance,
                                  refine=args.refine, refine_iterations=args.refine_iters, source=str(args.image),
                                  progress=bars)
    finally:
        bars.close()
    seconds = time.perf_counter() - start
    # No curve (a dot, a filled blob: no stroke longer than its width): no distances (null).
    chamfer = chamfer_to_ink(curves, strokes.ink) if curves else {k: None for k in
                                                                  ("curves_to_ink", "ink_to_curves", "symmetric")}
    h, w = grey.shape
    report = {
        "image": str(args.image),
        "size": [w, h],
        "method": args.method,
        "chosen": strokes.chosen,
        "mode": uses,
        "tolerance": args.tolerance,
        "refined": bool(args.refine),
        "polarity": "light on dark" if strokes.inverted else "dark on light",
        "stroke_width": strokes.width,
        "curves": len(curves),
        "control_points": [int(c.control_points.shape[0]) for c in curves],
        "ink_pixels": int(strokes.ink.sum()),
        "chamfer_px": chamfer,
        "seconds": seconds,
        "coordinates": COORDINATES,
        "files": ["curves.json", "curves.svg", "overlay.png", "report.json"],
    }
    note = thick_note(strokes)
    if note:
        report["notes"] = [note]
    with output_directory(args.out, args.overwrite, inputs=[args.image]) as tmp:
        try:
            bars("writing", 0, 3)
            write_curves_json(tmp / "curves.json", curves, (w, h))
            bars("writing", 1, 3)
            write_svg(tmp / "curves.svg", grey, curves)
            bars("writing", 2, 3)
            write_overlay(tmp / "overlay.png", grey, curves)
            with atomic_open(tmp / "report.json", "w") as fh:
                json.dump(report, fh, indent=2)
        finally:
            bars.close()
    if note:
        sys.stderr.write(f"nurbskit curves: note: {args.image}: {note}\n")
    if not curves:
        why = (f"no stroke longer than its width ({strokes.width:.1f} px) in the ink" if strokes.width is not None
               else "the network found none")
        print(f"0 curves from {args.image} ({w} x {h}, {report['polarity']}): {why}; wrote {Path(args.out)}",
              file=sys.stdout)
        return 0
    print(f"{len(curves)} curve(s) from {args.image} ({w} x {h}, {report['polarity']}): Chamfer curves->ink "
          f"{chamfer['curves_to_ink']:.2f} px, ink->curves {chamfer['ink_to_curves']:.2f} px in {seconds:.2f} s; "
          f"wrote {Path(args.out)}", file=sys.stdout)
    return 0
