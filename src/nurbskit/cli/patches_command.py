"""``nurbskit patches``: a point cloud (or a scan, or a sampled mesh) as a few trimmed NURBS patches.

Examples::

    nurbskit patches ../shared/data/abc/abc_00470.xyzc --out out/abc_00470
    nurbskit patches scan.pcd --eps 0.02 --weights 0.3,0.4,0.3 --out out/scan
    nurbskit patches part.obj --sample 10000 --out out/part          # a mesh, sampled
    nurbskit patches cloud.ply --init cloud.vg --out out/cloud       # a GoCoPP planar start

Writes one nurbskit JSON per patch (``patches/NNN.json``, trimming loops under ``trim``),
``patches.json``, ``patches.ply`` and ``meshes/NNN.ply`` (trimmed meshes), ``labels.txt``,
``report.json``, ``config.json`` and figures into ``--out``, all at once (built under a
temporary name). Labels in the input (``.xyzc``) are the ground truth of the IoU metric.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError
from ..patches.config import MAX_SEED, PatchConfig
from ._options import int_in
from .export_command import add_format_option, check_format_options, write_requested_format


def _help(name: str) -> str:
    # argparse formats help with %: a literal percent sign in a field's help is doubled
    return next(f.metadata.get("help", "") for f in dataclasses.fields(PatchConfig) if f.name == name).replace("%", "%%")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "patches", help="fit a few trimmed NURBS patches to a point cloud (NURBSFit)",
        description="Segment INPUT into a few trimmed NURBS patches: a planar start, merges in the order of a "
                    "quadric error kept when the energy of fidelity, simplicity and completeness falls, "
                    "trimming in (u, v). See docs/patches.md.",
    )
    p.add_argument("input", metavar="INPUT", help="point cloud or mesh file (.xyzc labels are used as ground truth)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--eps", type=float, default=0.01, help=_help("eps") + " (default 0.01)")
    p.add_argument("--weights", default="0.3,0.4,0.3", metavar="F,S,C", help=_help("weights") + " (default 0.3,0.4,0.3)")
    p.add_argument("--max-ctrl", type=int, default=12, metavar="N", help=_help("max_ctrl") + " (default 12)")
    p.add_argument("--init", default="auto", metavar="auto|FILE.vg", help=_help("init") + " (default auto)")
    p.add_argument("--sample", type=int, default=None, metavar="N",
                   help="INPUT is a mesh: fit N points sampled uniformly on its area instead of its vertices")
    p.add_argument("--max-points", type=int, default=20_000, metavar="N", help=_help("max_points") + " (default 20000)")
    p.add_argument("--crease-seam", type=float, default=75.0, metavar="DEG",
                   help=_help("crease_seam") + " (default 75)")
    p.add_argument("--leftover", type=float, default=0.05, metavar="F",
                   help=_help("leftover") + " (default 0.05)")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help=_help("seed"))
    p.add_argument("--device", default="cpu", help=_help("device"))
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    add_format_option(p)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(run=run_patches)


def parse_weights(text: str) -> tuple[float, float, float]:
    """``"0.3,0.4,0.3"`` -> ``(0.3, 0.4, 0.3)``; an OptionError otherwise."""
    try:
        values = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        raise OptionError(f"--weights: expected three numbers like 0.3,0.4,0.3, got {text!r}") from None
    if len(values) != 3 or any(not v >= 0 for v in values) or sum(values) <= 0:
        raise OptionError(f"--weights: expected three non-negative numbers with a positive sum like 0.3,0.4,0.3, got {text!r}")
    return values


def load_cloud(path: str | Path, sample: int | None, seed: int):
    """``(points (N, 3), normals or None, labels or None)`` from a point or mesh file."""
    from ..io import read_mesh, read_points

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a point cloud or mesh file")
    if sample is not None:
        from ..geometry.sampling import sample_mesh

        if sample < 20:
            raise OptionError(f"--sample must be at least 20, got {sample}")
        mesh = read_mesh(path)
        if len(mesh.faces) == 0:
            raise InputError(f"{path}: --sample needs a mesh with faces, found none")
        return np.asarray(sample_mesh(mesh.vertices, mesh.faces, sample, method="uniform", seed=seed)), None, None
    cloud = read_points(path)
    return cloud.points, cloud.normals, cloud.labels


def run_patches(args) -> int:
    from .._fs import check_output_dir, output_directory
    from ..patches import fit_patches
    from ..patches.outputs import write_patch_outputs
    from ..patches.planar import read_vg
    from ._options import parse_device

    check_format_options(args)  # --mesh-tolerance, before any work
    weights = parse_weights(args.weights)
    parse_device(args.device)  # the one device parser: a device that exists here, or one line
    cfg = PatchConfig(eps=args.eps, weights=weights, max_ctrl=args.max_ctrl, seed=args.seed, device=args.device,
                      init=args.init, max_points=args.max_points, crease_seam=args.crease_seam,
                      leftover=args.leftover)
    try:
        cfg.validate()
    except OptionError as exc:
        raise OptionError(f"--{str(exc).split(':')[0].replace('_', '-')}:{str(exc).split(':', 1)[1]}") from None
    check_output_dir(args.out, args.overwrite, inputs=[args.input])  # refuse a bad --out before the work
    points, normals, labels = load_cloud(args.input, args.sample, args.seed)
    from ..patches.driver import check_patch_memory

    check_patch_memory(len(points), str(args.input))  # one line naming INPUT and the estimate, before the work
    init_labels = None
    if args.init != "auto":
        vg = Path(args.init)
        if not vg.is_file():
            raise OptionError(f"--init: expected 'auto' or an existing .vg file, got {args.init!r}")
        _, init_labels = read_vg(vg, n_points=len(points))
    from ._progress import StageBars

    bars = StageBars(args.quiet)
    try:
        result = fit_patches(points, normals, cfg, init_labels=init_labels, truth=labels, progress=bars)
    except InputError as exc:  # the cloud cannot be fitted: name the file it came from
        raise InputError(f"{args.input}: {exc}") from None
    finally:
        bars.close()
    if not result.patches:
        raise InputError(
            f"{args.input}: no patch holds its points within eps = {cfg.eps:g} of the diagonal "
            f"({result.planar['planes']} planar regions, {len(points)} points); nothing was written; "
            f"a larger --eps accepts a coarser fit"
        )
    with output_directory(args.out, args.overwrite, inputs=[args.input]) as tmp:
        report = write_patch_outputs(result, tmp, figures=not args.no_figures, extra={"input": str(args.input)})
        if result.faces:
            write_requested_format(args, result.faces, tmp, "patches")
    m = report["metrics"]
    line = (
        f"{m['N']} patches from {result.planar['planes']} planes in {report['seconds']:.1f} s; "
        f"completeness {m['completeness']:.1f} %, P_cov^i {m['P_cov_i']:.1f} %, P_cov^o {m['P_cov_o']:.1f} %, "
        f"E_fid {m['E_fid']:.1f} % of eps"
    )
    if "iou" in m:
        line += f", IoU {m['iou']:.1f} %"
    print(line)
    print(f"wrote {Path(args.out)}/: " + ", ".join(report["files"]))
    return 0
