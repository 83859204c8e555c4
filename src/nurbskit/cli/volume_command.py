"""``nurbskit volume``: a NURBS volume from three drawings (front, left, top).

Writes into ``--out``: ``mesh.obj`` and ``mesh.ply`` (unit-cube coordinates),
``volume.json`` (nurbskit format), ``report.json`` (configuration, costs, per-view IoU,
seconds) and ``views.png`` (each drawing beside the projection of the result). The
directory is built under a temporary name and appears only when complete.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..errors import OptionError


def _int_at_least(low: int):
    """An argparse type: an integer >= ``low``, with a one-line message otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {value}")
        return value

    return parse


_positive_int = _int_at_least(1)
_count = _int_at_least(0)


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "volume",
        help="fit a NURBS volume to front, left and top drawings",
        description=(
            "Fit a scalar NURBS volume whose solid {f >= isovalue} matches three drawings "
            "(W. Li, Multi-view NURBS Volume). Drawings: PNG or JPEG, dark on light or the "
            "reverse, any size; front looks along -z (x right, y up), left along +x (z right, "
            "y up), top along -y (x right, z down)."
        ),
    )
    p.add_argument("--front", required=True, metavar="IMAGE", help="front drawing (x right, y up)")
    p.add_argument("--left", required=True, metavar="IMAGE", help="left drawing (z right, y up)")
    p.add_argument("--top", required=True, metavar="IMAGE", help="top drawing (x right, z down)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--control-size", type=_positive_int, default=50, help="control values per axis (default 50)")
    p.add_argument("--grid", type=_positive_int, default=20, help="grid points per axis for the costs (default 20)")
    p.add_argument("--iters", type=_count, default=100, help="maximum L-BFGS iterations (default 100)")
    p.add_argument("--isovalue", type=_number, default=0.5, help="isovalue of the surface (default 0.5)")
    p.add_argument("--degree", type=_positive_int, default=2, help="B-spline degree (default 2, the paper's order 3)")
    p.add_argument("--loss", choices=("paper", "silhouette"), default="paper", help="shape cost (default paper)")
    p.add_argument("--shape-weight", type=_number, default=0.1, help="weight of the shape cost (default 0.1)")
    p.add_argument("--smooth-weight", type=_number, default=0.9, help="weight of the smoothness cost (default 0.9)")
    p.add_argument("--mesh-resolution", type=_positive_int, default=None, help="marching-cubes grid (default: --grid)")
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda (default cpu)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing non-empty --out directory")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def _device(name: str):
    import torch

    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        raise OptionError(f"--device: expected a torch device such as cpu or cuda, got {name!r}") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise OptionError("--device cuda: no CUDA device is available on this machine")
    return device


def run(args) -> int:
    from .._fs import check_output_dir, output_directory
    from ..core.serialize import save
    from ..volume.drawings import load_drawing
    from ..volume.figure import write_comparison_png
    from ..volume.fit import fit_silhouettes
    from ..volume.mesh import write_mesh

    check_output_dir(args.out, args.overwrite)  # fail before the fit, not after it
    if args.grid < 2:
        raise OptionError(f"--grid must be at least 2, got {args.grid}")
    if args.control_size < args.degree + 1:
        raise OptionError(f"--control-size {args.control_size} is too small for --degree {args.degree}; it needs at least {args.degree + 1}")
    if args.mesh_resolution is not None and args.mesh_resolution < 2:
        raise OptionError(f"--mesh-resolution must be at least 2, got {args.mesh_resolution}")
    device = _device(args.device)
    drawings = {name: load_drawing(getattr(args, name), name=name) for name in ("front", "left", "top")}

    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=args.iters, desc="fitting", unit="it", file=sys.stderr, leave=False)

    def progress(stage, done, total, cost):
        if bar is None:
            return
        if stage == "fit":
            bar.n = min(done, total)
            if cost is not None:
                bar.set_postfix(cost=f"{cost:.3g}", refresh=False)
            bar.refresh()
        else:
            bar.set_description("meshing")

    try:
        result = fit_silhouettes(
            drawings["front"],
            drawings["left"],
            drawings["top"],
            control_size=args.control_size,
            grid=args.grid,
            degree=args.degree,
            iterations=args.iters,
            isovalue=args.isovalue,
            shape_weight=args.shape_weight,
            smooth_weight=args.smooth_weight,
            loss=args.loss,
            mesh_resolution=args.mesh_resolution,
            device=device,
            callback=progress,
        )
    finally:
        if bar is not None:
            bar.close()

    report = result.report()
    report["inputs"] = {"front": str(args.front), "left": str(args.left), "top": str(args.top)}
    with output_directory(args.out, args.overwrite) as tmp:
        write_mesh(tmp / "mesh.obj", result.mesh)
        write_mesh(tmp / "mesh.ply", result.mesh)
        save(result.volume, tmp / "volume.json")
        write_comparison_png(tmp / "views.png", result.drawings, result.projections, result.iou)
        with open(tmp / "report.json", "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
            fh.write("\n")
    if result.mesh.is_empty:
        sys.stderr.write(f"nurbskit volume: warning: {result.message}; wrote an empty mesh to {args.out}\n")
        return 1
    if not args.quiet:
        ious = ", ".join(f"{k} {v:.3f}" for k, v in result.iou.items())
        sys.stderr.write(
            f"nurbskit volume: {len(result.mesh.faces)} triangles, IoU {ious}, "
            f"{result.seconds['total']:.2f} s -> {args.out}\n"
        )
    return 0
