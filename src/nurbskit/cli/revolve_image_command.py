"""``nurbskit revolve-image``: a surface of revolution from the silhouette of a turned object.

Writes to ``--out`` (built under a temporary name and moved into place):

====================  ==========================================================
``surface.json``      the exact rational NURBS (nurbskit JSON), pixel units times
                      ``--pixel-size``, axis ``+z``, ``z = 0`` at the object's bottom
``report.json``       the axis in image coordinates, the symmetry residual, the
                      profile curve (r, z in pixels), the background found
``silhouette.png``    the image with the silhouette's edges, the axis and the fitted
                      profile mirrored on both sides
``surface.png``       the surface rendered (shaded, with its control net)
====================  ==========================================================

The method is :func:`nurbskit.shapes.image.revolve_image`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..shapes.image import PIXEL_SIZE_RANGE
from ._options import number_in


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "revolve-image",
        help="a surface of revolution from the silhouette of a turned object in an image",
        description="Read the silhouette of a turned object (dark on light or light on dark), find its "
                    "symmetry axis, fit the half-width profile and revolve it into an exact NURBS surface; "
                    "write surface.json, report.json and PNG figures to --out.",
    )
    p.add_argument("input", metavar="IMAGE", help="image file (PNG, JPEG, ...)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--axis", choices=("vertical", "principal"), default="vertical",
                   help="symmetry axis: the best vertical mirror line (default), or the silhouette's principal "
                        "axis (for a tilted object)")
    p.add_argument("--symmetry-tolerance", type=number_in(0.0, low_open=True), default=0.02, metavar="T",
                   help="largest RMS distance of the row midpoints from the axis: pixels if >= 1, else that "
                        "fraction of the mean width (default 0.02)")
    p.add_argument("--pixel-size", type=number_in(*PIXEL_SIZE_RANGE), default=1.0, metavar="S",
                   help=f"length of one pixel in the surface's units, in [{PIXEL_SIZE_RANGE[0]:g}, "
                        f"{PIXEL_SIZE_RANGE[1]:g}] (default 1)")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.set_defaults(run=run_revolve_image)


def image_report(res, source: str) -> dict:
    """The JSON report of an :class:`~nurbskit.shapes.image.ImageRevolution`."""
    c = res.profile
    return {
        "input": source,
        "kind": "revolution",
        "coordinates": "image: pixels, x to the right, y down, origin at the top-left corner of the top-left "
                       "pixel; surface: pixel units times pixel_size, axis +z through the origin, z = 0 at "
                       "the object's bottom",
        "axis": res.axis,
        "rotation_degrees": res.rotation,
        "symmetry_residual_px": res.symmetry_residual,
        "symmetry_max_px": res.symmetry_max,
        "profile_residual_px": res.profile_residual,
        "rows": int(res.rows.shape[0]),
        "background": res.background,
        "object_grey": res.levels[0],
        "background_grey": res.levels[1],
        "pixel_size": res.pixel_size,
        "ignored_objects_px": list(res.ignored_objects),
        "height_px": float(res.points[:, 1].max() - res.points[:, 1].min()),
        "max_radius_px": float(res.points[:, 0].max()),
        "profile": {
            "coordinates": ["r", "z"],
            "units": "pixels",
            "degree": c.degree,
            "control_points": c.control_points.tolist(),
            "weights": c.weights.tolist(),
            "knot_vector": c.knot_vector.tolist(),
        },
    }


def plot_silhouette(res, path: Path) -> None:
    """The (turned) image, the edges found, the axis and the profile on both sides."""
    from ..viz.plots import _figure, _save

    H, W = res.grey.shape
    fig = _figure((6, 6 * H / max(W, 1)))
    ax = fig.add_subplot(111)
    ax.imshow(res.grey, cmap="gray", vmin=0, vmax=1, extent=(0, W, H, 0))
    ax.plot(res.rows[:, 1], res.rows[:, 0], ".", c="tab:blue", ms=1.5, label="edges")
    ax.plot(res.rows[:, 2], res.rows[:, 0], ".", c="tab:blue", ms=1.5)
    ax.axvline(res.axis_x, c="tab:orange", lw=1, ls="--", label="axis")
    rz = res.profile.evaluate(np.linspace(*res.profile.domain[0], 400)).numpy()
    y = res.z_origin - rz[:, 1]
    ax.plot(res.axis_x + rz[:, 0], y, c="tab:green", lw=1.2, label="profile")
    ax.plot(res.axis_x - rz[:, 0], y, c="tab:green", lw=1.2)
    title = f"symmetry residual {res.symmetry_residual:.2f} px RMS"
    if res.rotation:
        title += f" (image turned {res.rotation:.1f} deg)"
    ax.set_title(title)
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.legend(loc="lower right", fontsize=7)
    _save(fig, path)


def plot_surface(surface, path: Path, title: str = "surface of revolution") -> None:
    """The surface shaded (matplotlib ``plot_surface``) with its control net."""
    from ..viz.plots import _equal_axes, _figure, _save

    grid = surface.sample((64, 48)).detach().numpy()
    fig = _figure((6, 6))
    ax = fig.add_subplot(111, projection="3d")
    ax.plot_surface(grid[..., 0], grid[..., 1], grid[..., 2], color="tab:blue", alpha=0.85, linewidth=0,
                    shade=True, antialiased=True)
    net = surface.control_points.detach().numpy()
    ax.plot_wireframe(net[..., 0], net[..., 1], net[..., 2], color="tab:red", linewidth=0.4)
    _equal_axes(ax, grid.reshape(-1, 3))
    ax.set_title(title)
    _save(fig, path)


def run_revolve_image(args) -> int:
    from .._fs import atomic_open, check_output_dir, output_directory
    from ..core import save
    from ..shapes.image import revolve_image

    check_output_dir(args.out, args.overwrite, inputs=[args.input])
    path = Path(args.input)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    res = revolve_image(path, axis=args.axis, symmetry_tolerance=args.symmetry_tolerance,
                        pixel_size=args.pixel_size)
    report = image_report(res, str(path))
    files = ["surface.json", "report.json"]
    with output_directory(args.out, args.overwrite, inputs=[args.input]) as tmp:
        save(res.surface, tmp / "surface.json")
        if not args.no_figures:
            plot_silhouette(res, tmp / "silhouette.png")
            plot_surface(res.surface, tmp / "surface.png",
                         title=f"revolved profile ({res.profile.control_points.shape[0]} control points)")
            files += ["silhouette.png", "surface.png"]
        report["files"] = files
        with atomic_open(tmp / "report.json", "w") as fh:
            json.dump(report, fh, indent=2)
    print(f"revolution from {path.name}: axis x = {res.axis['point'][0]:.2f} px, symmetry residual "
          f"{res.symmetry_residual:.2f} px RMS, {res.rows.shape[0]} rows, profile of "
          f"{res.profile.control_points.shape[0]} control points ({res.background} background)")
    print(f"wrote {Path(args.out)}/: " + ", ".join(files))
    if res.ignored_objects:
        n = len(res.ignored_objects)
        sys.stderr.write(
            f"nurbskit revolve-image: note: {path}: {n} other object{'s' if n > 1 else ''} "
            f"({', '.join(map(str, res.ignored_objects))} pixels) ignored; only the largest "
            f"({int(res.mask.sum())} pixels) was revolved\n"
        )
    return 0
