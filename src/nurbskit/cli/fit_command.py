"""``nurbskit fit``: fit a NURBS surface to a point cloud (or a supervised target).

Examples::

    nurbskit fit horse_2500.off --out fits/horse                      # our default pipeline
    nurbskit fit horse_2500.off --pipeline UCDL --ctrl 20x20 --out fits/horse_ucdl
    nurbskit fit duck.json --pipeline SC --resolution 64x64 --out fits/duck_sc   # supervised
    nurbskit fit grid.npy --pipeline SB --out fits/grid_sb            # ordered (R, S, 3) grid

INPUT is a point or mesh file (its vertices are the points), a NURBS file (sampled on
a uniform ``--resolution`` grid: the supervised target, or the points of an
unsupervised pipeline), or a ``.npy`` array shaped ``(R, S, 3)`` (an ordered grid) or
``(N, 3)``. Everything goes into ``--out`` at once (built under a temporary name), so
an interrupted fit leaves nothing half-written.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError
from ..fit.config import CLOSED, INIT_KINDS, LAPLACIAN_ON, LR_RANGE, MAX_ITERS, FitConfig, InitConfig, LossWeights
from ._options import add_device_options, device_and_dtype, int_in, number_in
from .export_command import add_format_option, check_format_options, write_requested_format


def _help(cls, name: str) -> str:
    return next(f.metadata.get("help", "") for f in dataclasses.fields(cls) if f.name == name)


def parse_pair(text: str, what: str, low: int = 1) -> tuple[int, int]:
    """``"15x15"``, ``"15,15"`` or ``"15"`` -> ``(15, 15)``; an OptionError otherwise."""
    parts = str(text).lower().replace(",", "x").split("x")
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        raise OptionError(f"--{what}: expected two integers like 15x15, got {text!r}") from None
    if len(values) == 1:
        values = values * 2
    if len(values) != 2 or min(values) < low:
        raise OptionError(f"--{what}: expected two integers >= {low} like 15x15, got {text!r}")
    return values


def register(subparsers) -> None:
    from ..fit.pipelines import PIPELINES

    names = ", ".join(f"{k}{' (supervised)' if p.supervised else ''}" for k, p in PIPELINES.items())
    p = subparsers.add_parser(
        "fit", help="fit a NURBS surface to a point cloud",
        description="Fit a NURBS surface to INPUT and write surface.json, points.off, control_points.off, "
                    "report.json, config.json and PNG figures to --out. Pipelines: " + names + ".",
    )
    p.add_argument("input", metavar="INPUT", help="points / mesh file, NURBS file, or .npy (R, S, 3) ordered grid")
    p.add_argument("--pipeline", default="default", metavar="NAME",
                   help="pipeline preset (default: ours; see docs/fitting.md): " + names)
    p.add_argument("--ctrl", default=None, metavar="NUxNV", help=_help(FitConfig, "ctrl") + " (e.g. 15x15)")
    p.add_argument("--degree", default=None, metavar="PxQ", help=_help(FitConfig, "degree") + " (e.g. 3 or 3x3)")
    p.add_argument("--resolution", default="64x64", metavar="RxS", help=_help(FitConfig, "resolution") + " (default 64x64)")
    p.add_argument("--iters", type=int_in(0, MAX_ITERS), default=None, metavar="N",
                   help="total gradient iterations, shared by the pipeline's stages in its proportions (default: the preset's)")
    p.add_argument("--init", choices=INIT_KINDS, default=None, help=_help(InitConfig, "kind") + " (default: the preset's)")
    p.add_argument("--closed", choices=CLOSED, default=None, help=_help(InitConfig, "closed"))
    p.add_argument("--laplacian-on", choices=LAPLACIAN_ON, default=None, help=_help(LossWeights, "laplacian_on"))
    p.add_argument("--lr", type=number_in(*LR_RANGE, low_open=True), default=None,
                   help=f"learning rate of every stage, in ({LR_RANGE[0]:g}, {LR_RANGE[1]:g}] (default: the preset's)")
    add_device_options(p, dtype_default="float64")
    p.add_argument("--seed", type=int_in(0, 2**63 - 1), default=0, help=_help(FitConfig, "seed"))
    p.add_argument("--max-points", type=int_in(0), default=None, metavar="N",
                   help=_help(FitConfig, "max_points") + " (default 20000)")
    p.add_argument("--threads", type=int_in(1, 4096), default=None, metavar="N",
                   help="torch CPU threads (default: torch's choice); 1 is often fastest for small clouds on a busy machine")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    add_format_option(p)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures (faster)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run_fit)


def load_input(path: str | Path, resolution: tuple[int, int]):
    """What INPUT holds: ``("surface", NURBSSurface)``, ``("grid", (R, S, 3))`` or ``("points", (N, 3))``."""
    from ..io import read_points
    from ..io.nurbs import is_nurbs_file, read_nurbs

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a point, mesh, NURBS or .npy file")
    if path.suffix.lower() == ".npy":
        # A supervised target grid (R, S, 3) is read here; anything else goes to the io
        # reader, which checks counts, memory and non-finite values like every format.
        try:
            header = np.load(path, mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise InputError(f"{path}: not a readable .npy array ({exc})") from None
        if header.ndim == 3 and header.shape[-1] == 3:
            grid = np.array(header, dtype=np.float64)  # a copy: the memory map is read-only
            if grid.size == 0 or not np.isfinite(grid).all():
                raise InputError(f"{path}: a target grid must be non-empty and finite, got shape {grid.shape}")
            return "grid", grid
        if header.ndim != 2 or header.shape[-1] != 3:
            raise InputError(f"{path}: expected an array shaped (R, S, 3) or (N, 3), got {header.shape}")
        del header
    if is_nurbs_file(path):
        surface = read_nurbs(path)
        if getattr(surface, "para_dim", None) != 2 or surface.dim != 3:
            raise InputError(f"{path}: expected a NURBS surface in 3D, got a {surface.kind} in {surface.dim}D")
        return "surface", surface
    cloud = read_points(path)
    return "points", cloud.points


def run_fit(args) -> int:
    from .._fs import output_directory
    from ..fit import fit_surface
    from ..fit.api import resolve_config
    from ..fit.outputs import write_fit_outputs

    import torch

    from ..fit.checks import check_resolution

    check_format_options(args)  # --mesh-tolerance, before any work
    resolution = parse_pair(args.resolution, "resolution", 2)
    ctrl = parse_pair(args.ctrl, "ctrl", 2) if args.ctrl else None
    degree = parse_pair(args.degree, "degree", 1) if args.degree else None
    device, dtype = device_and_dtype(args)
    check_resolution(resolution, torch.finfo(dtype).bits // 8)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    # Refuse a bad --out before the (possibly long) fit.
    from .._fs import check_output_dir

    check_output_dir(args.out, args.overwrite, inputs=[args.input])

    kind, data = load_input(args.input, resolution)
    supervised_input = kind in ("surface", "grid")
    cfg = resolve_config(args.pipeline, supervised_input)
    if cfg.supervised and not supervised_input:
        raise OptionError(
            f"--pipeline {cfg.pipeline} is supervised: INPUT must be a NURBS file or an ordered .npy grid "
            f"(R, S, 3), got a point cloud ({args.input})"
        )
    cfg = dataclasses.replace(cfg, resolution=resolution, seed=args.seed)
    if args.max_points is not None:
        cfg.max_points = args.max_points
    if ctrl is not None:
        cfg.ctrl = ctrl
    if degree is not None:
        cfg.degree = degree
    if args.iters is not None:
        cfg = cfg.with_iters(args.iters)
    if args.init is not None:
        cfg.init = dataclasses.replace(cfg.init, kind=args.init)
    if args.closed is not None:
        cfg.init = dataclasses.replace(cfg.init, closed=args.closed)
    for s in cfg.stages:
        if args.lr is not None:
            s.lr = args.lr
        if args.laplacian_on is not None:
            s.loss.laplacian_on = args.laplacian_on
    cfg.validate()
    if cfg.init.kind == "target" and not cfg.supervised:
        raise OptionError(f"--init target (the target's knots and weights) needs a supervised pipeline; {cfg.pipeline} is not")

    # --device and --dtype move the input; the fit then runs on the input's device and dtype.
    if kind == "surface":
        data = data.to(dtype=dtype, device=device)
    else:
        given = torch.as_tensor(data)
        data = given.to(dtype=dtype, device=device)
        if bool(torch.isfinite(given).all()) and not bool(torch.isfinite(data).all()):
            raise InputError(f"{args.input}: coordinates up to {float(given.abs().max()):.3g} exceed "
                             f"{str(dtype).replace('torch.', '')}; use --dtype float64")
    kwargs = {}
    if cfg.supervised:
        kwargs = {"target_surface": data} if kind == "surface" else {"target_grid": data}
        points = None
    else:
        if kind == "surface":
            with torch.no_grad():
                points = data.sample(resolution).reshape(-1, 3)
        elif kind == "grid":
            points = data.reshape(-1, 3)
        else:
            points = data

    bar = None
    if not args.quiet and cfg.progress_steps:
        from tqdm import tqdm

        bar = tqdm(total=cfg.progress_steps, desc=f"fit {cfg.pipeline}", unit="step", file=sys.stderr, leave=False)

    def progress(p):
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"{p.stage} loss={p.loss:.3e}", refresh=False)

    try:
        result = fit_surface(points, cfg, callback=progress, **kwargs)
    except InputError as exc:  # the data cannot be fitted: name the file it came from
        raise InputError(f"{args.input}: {exc}") from None
    finally:
        if bar is not None:
            bar.close()
    with output_directory(args.out, args.overwrite, inputs=[args.input]) as tmp:
        report = write_fit_outputs(result, tmp, figures=not args.no_figures)
        write_requested_format(args, result.surface, tmp, "surface")
    m = report["metrics"]
    line = (
        f"{cfg.pipeline}: {report['iterations']} iterations in {report['seconds']:.2f} s; "
        f"input-to-surface mean {m['to_surface_mean']:.2e}, p95 {m['to_surface_p95']:.2e} of the diagonal; "
        f"combined metric {report['metrics_normalized']['combined']:.4g} (at a unit diagonal)"
    )
    if "rms_normalized" in report:
        line += f"; RMS to target {report['rms_normalized']:.2e} of the diagonal"
    print(line)
    print(f"wrote {Path(args.out)}/: " + ", ".join(report["files"]))
    return 0
