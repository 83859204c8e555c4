"""``nurbskit shape``: a surface of revolution or an extrusion, exact, from a point cloud.

Writes to ``--out`` (built under a temporary name and moved into place):

====================  ==========================================================
``surface.json``      the exact rational NURBS (nurbskit JSON)
``report.json``       ``kind``, ``axis`` {point, direction}, the profile curve, the
                      reason for the choice, and the metrics of ``nurbskit fit``
                      (:func:`nurbskit.metrics.evaluate_fit`: input-to-surface mean
                      and p95 over the bounding-box diagonal, ...)
``cloud.png``         the input with samples of the surface and its control net
``profile.png``       the profile in its plane ((r, z) for a revolution) with the
                      points it was fitted to
``error_map.png``     the input coloured by its distance to the surface (over the
                      bounding-box diagonal)
====================  ==========================================================
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..shapes.fit import MAX_ITERATIONS
from ._options import int_in

POOR_FIT = 5e-3
"""A mean input-to-surface distance above this fraction of the diagonal is reported as poor."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "shape",
        help="fit an exact surface of revolution or extrusion to a point cloud",
        description="Fit a surface of revolution, an extrusion, or (auto) the better one or a free-form "
                    "surface, to the points of INPUT; write surface.json, report.json and PNG figures to --out.",
    )
    p.add_argument("input", metavar="INPUT", help="point cloud or mesh file (its vertices are used)")
    p.add_argument("--kind", choices=("revolution", "extrusion", "auto"), default="auto",
                   help="which shape to fit (default auto: by the residual)")
    p.add_argument("--init", choices=("geometric", "network"), default="geometric",
                   help="where the refinement starts: the geometric estimate (default) or the trained "
                        "network's guess (needs the model made by `nurbskit train revolve`)")
    p.add_argument("--iters", type=int_in(0, MAX_ITERATIONS), default=30, metavar="N",
                   help=f"refinement iterations (L-BFGS), in [0, {MAX_ITERATIONS}] (default 30)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(run=run_shape)


def _profile_dict(fit) -> dict | None:
    if fit.profile is None:
        return None
    c = fit.profile
    coords = ["r", "z"] if fit.kind == "revolution" else ["x", "y"]
    return {
        "coordinates": coords,
        "frame": fit.profile_frame,
        "degree": c.degree,
        "closed": fit.closed,
        "control_points": c.control_points.tolist(),
        "weights": c.weights.tolist(),
        "knot_vector": c.knot_vector.tolist(),
    }


def shape_report(fit, metrics: dict) -> dict:
    """The JSON report of a :class:`~nurbskit.shapes.ShapeFit`."""
    rep = {
        "kind": fit.kind,
        "reason": fit.reason,
        "init": fit.init,
        "axis": fit.axis,
        "profile": _profile_dict(fit),
        "metrics": metrics,
        "seconds": fit.seconds,
        "refinement_evaluations": fit.iterations,
        "candidates": fit.candidates,
        "poor_fit": metrics["to_surface_mean"] > POOR_FIT,
    }
    if fit.angle is not None:
        rep["angle"] = fit.angle
    if fit.extent is not None:
        rep["extent"] = list(fit.extent)
    return rep


def _plot_profile(fit, path: Path) -> None:
    from ..viz.plots import _figure, _save

    fig = _figure((6, 6))
    ax = fig.add_subplot(111)
    pts = fit.profile_points
    if pts is not None:
        ax.scatter(pts[:, 0], pts[:, 1], s=1, c="tab:blue", alpha=0.4, label="points")
    c = fit.profile
    u = np.linspace(*c.domain[0], 400)
    curve = c.evaluate(u).numpy()
    ax.plot(curve[:, 0], curve[:, 1], c="tab:green", label="profile")
    cp = c.control_points.numpy()
    ax.plot(cp[:, 0], cp[:, 1], "o--", c="tab:red", ms=3, lw=0.6, label="control polygon")
    ax.set_aspect("equal")
    if fit.kind == "revolution":  # from the axis: the half-silhouette of the part, not a sliver
        ax.set_xlim(left=0.0)
    labels = ("r (distance to axis)", "z (height)") if fit.kind == "revolution" else ("x", "y")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)  # beside, not over the profile
    ax.set_title(f"{fit.kind} profile")
    _save(fig, path)


def run_shape(args) -> int:
    import torch

    from .._fs import atomic_open, check_output_dir, output_directory
    from ..core import save
    from ..io import read_points
    from ..metrics import evaluate_fit
    from ..shapes import fit_shape

    check_output_dir(args.out, args.overwrite, inputs=[args.input])
    path = Path(args.input)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a point or mesh file")
    cloud = read_points(path)
    points = torch.as_tensor(cloud.points, dtype=torch.float64)
    normals = None if cloud.normals is None else torch.as_tensor(cloud.normals, dtype=torch.float64)
    from ._progress import StageBars

    bars = StageBars(args.quiet, delay=0.5)  # the exact fits take a second: no flicker before a quick answer
    try:
        fit = fit_shape(points, args.kind, normals, iterations=args.iters, refine=args.iters > 0, init=args.init,
                        progress=bars)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    finally:
        bars.close()
    metrics = evaluate_fit(fit.surface, points, (64, 64))
    report = shape_report(fit, metrics)
    files = ["surface.json", "report.json"]
    with output_directory(args.out, args.overwrite, inputs=[args.input]) as tmp:
        save(fit.surface, tmp / "surface.json")
        if not args.no_figures:
            from ..viz.plots import plot_clouds, plot_error_map

            plot_clouds(points, fit.surface.sample((48, 48)), fit.surface.control_points, tmp / "cloud.png",
                        title=f"{fit.kind}: input, surface and control net")
            files.append("cloud.png")
            if fit.profile is not None:
                _plot_profile(fit, tmp / "profile.png")
                files.append("profile.png")
            plot_error_map(points, fit.distances * fit.diagonal, tmp / "error_map.png", scale=fit.diagonal,
                           title=f"{fit.kind}: distance of each input point to the surface")
            files.append("error_map.png")
        report["files"] = files
        with atomic_open(tmp / "report.json", "w") as fh:
            json.dump(report, fh, indent=2)
    m = metrics
    print(f"{fit.kind}: input-to-surface mean {m['to_surface_mean']:.2e}, p95 {m['to_surface_p95']:.2e} "
          f"of the diagonal in {fit.seconds:.2f} s; {fit.reason}")
    if report["poor_fit"]:
        sys.stderr.write(
            f"nurbskit shape: warning: poor fit: mean distance {m['to_surface_mean']:.2e} of the diagonal "
            f"exceeds {POOR_FIT:.0e}; the input may not be a {fit.kind}\n"
        )
    print(f"wrote {Path(args.out)}/: " + ", ".join(files))
    return 0
