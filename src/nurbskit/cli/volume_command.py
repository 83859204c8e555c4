"""``nurbskit volume``: a NURBS volume from three drawings (front, left, top).

Writes into ``--out``: ``mesh.obj`` and ``mesh.ply`` (unit-cube coordinates),
``volume.json`` (nurbskit format), ``report.json`` (configuration, costs, per-view IoU,
seconds) and ``views.png`` (each drawing beside the projection of the result). The
directory is built under a temporary name and appears only when complete.

The fitting options are generated from :class:`nurbskit.volume.config.VolumeFitConfig`
(one per field, with its help and range); ``--preset`` picks the values the options
start from (``default``, or ``paper`` for the paper's setting exactly).
"""

from __future__ import annotations

import sys

from ._options import add_config_options, add_device_options, config_from_args, device_and_dtype
from .export_command import add_format_option, check_format_options, write_requested_format

#: The visual hull's IoU against each drawing below which the drawings are said to
#: disagree (consistent drawings: 0.98 to 1.0 at the default grid, docs/volume.md).
CONSISTENT_HULL_IOU = 0.9


def register(subparsers) -> None:
    from ..volume.config import PRESETS, VolumeFitConfig, default_config

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
    p.add_argument("--preset", choices=tuple(PRESETS), default="default",
                   help="the settings the options below start from: 'default' (80^3 grid, hull start) or "
                        "'paper' (the paper's setting exactly: 20^3 grid, zeros start, 100 iterations)")
    add_config_options(p, VolumeFitConfig, default_config())
    add_device_options(p, dtype_default="float32")
    p.add_argument("--overwrite", action="store_true", help="replace an existing non-empty --out directory")
    add_format_option(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def run(args) -> int:
    from .._fs import check_output_dir, output_directory
    from ..volume.config import check_fit_size, get_preset
    from ..volume.drawings import load_drawing
    from ..volume.fit import fit_silhouettes
    from ..volume.outputs import write_outputs

    # Every check before any work: the options, the memory they need, the output folder.
    check_format_options(args)  # --mesh-tolerance, with or without --format
    cfg = config_from_args(args, get_preset(args.preset))
    device, dtype = device_and_dtype(args)
    check_fit_size(cfg, 8 if str(dtype).endswith("64") else 4)
    check_output_dir(args.out, args.overwrite, inputs=[args.front, args.left, args.top])
    drawings = {name: load_drawing(getattr(args, name), name=name).to(device, dtype) for name in ("front", "left", "top")}

    bar = None
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=cfg.iterations, desc="fitting", unit="it", file=sys.stderr, leave=False)

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
        result = fit_silhouettes(drawings, cfg, callback=progress)
    finally:
        if bar is not None:
            bar.close()

    report = result.report()
    report["preset"] = args.preset
    report["inputs"] = {"front": str(args.front), "left": str(args.left), "top": str(args.top)}
    with output_directory(args.out, args.overwrite, inputs=[args.front, args.left, args.top]) as tmp:
        write_outputs(result, tmp, report)
        if not result.mesh.is_empty:
            write_requested_format(args, result.mesh, tmp, "mesh")
    if result.mesh.is_empty:
        sys.stderr.write(f"nurbskit volume: warning: {result.message}; wrote an empty mesh to {args.out}\n")
        return 1
    worst = min(result.hull_iou, key=result.hull_iou.get)
    if result.hull_iou[worst] < CONSISTENT_HULL_IOU:
        # no solid can show every drawing: they disagree (sizes, placement, orientation)
        sys.stderr.write(
            f"nurbskit volume: warning: the drawings disagree: no solid shows the {worst} drawing "
            f"{getattr(args, worst)} better than IoU {result.hull_iou[worst]:.2f} (the visual hull's; consistent "
            f"drawings give {CONSISTENT_HULL_IOU} or more); check that the views share their extents and orientation\n"
        )
    if not args.quiet:
        ious = ", ".join(f"{k} {v:.3f}" for k, v in result.iou.items())
        sys.stderr.write(
            f"nurbskit volume: {len(result.mesh.faces)} triangles, IoU {ious}, "
            f"{result.seconds['total']:.2f} s -> {args.out}\n"
        )
    return 0
