"""``nurbskit export INPUT OUTPUT``: NURBS geometry to CAD files and meshes.

Examples::

    nurbskit export fit/surface.json surface.step        # read back and checked by OpenCASCADE
    nurbskit export patches/patches.json model.iges      # trimmed patches: trimmed surfaces (IGES 144)
    nurbskit export part.step part.json                  # every face: {"surfaces": [...]} with its trim
    nurbskit export part.step part.stl --tolerance 0.01  # tessellated (OBJ, PLY, STL, glTF, GLB, OFF)
    nurbskit export vol/mesh.obj vol.step                # a closed mesh: a solid of triangles
    nurbskit export vase/report.json vase.step           # `nurbskit shape`: SURFACE_OF_REVOLUTION
    nurbskit export vase vase.step --bspline             # (its folder works too) as the exact NURBS
    nurbskit export fit fit.step                         # an output folder: its patches.json, surface.json or volume.json

Inputs: nurbskit JSON (one object, ``{"patches": [...]}`` or ``{"surfaces": [...]}``),
``.3dm``, STEP, IGES, BREP, the other NURBS files of ``nurbskit convert``, triangle
meshes (to CAD formats, as a triangulated solid), and the ``report.json`` (or folder) of
``nurbskit shape``: its surface of revolution or extrusion goes to STEP as
``SURFACE_OF_REVOLUTION`` / ``SURFACE_OF_LINEAR_EXTRUSION`` over the exact B-spline
profile (IGES 120 / 122, BREP likewise; ``--bspline``: the exact NURBS instead; other
formats always get the NURBS). Outputs: by OUTPUT's extension or
``--format``. STEP, IGES and BREP need the ``[cad]`` extra (OpenCASCADE), ``.3dm`` too
(rhino3dm). ``--units`` (default mm) is the unit of the coordinates: STEP, IGES and
``.3dm`` outputs declare it (the numbers are written unchanged), STEP, IGES and ``.3dm``
inputs are converted into it; BREP holds no unit.

For the ``fit``, ``patches`` and ``volume`` commands: :func:`add_format_option` adds
``--format``, ``--mesh-tolerance`` and ``--units``, and :func:`write_result` writes their
result in that format.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ._options import number_in

FORMAT_CHOICES = ("step", "iges", "brep", "3dm", "obj", "ply", "stl", "gltf")
#: the keys of :data:`nurbskit.io.cad.exchange.UNITS` (not imported from there: building the
#: parser imports no I/O module)
UNIT_CHOICES = ("mm", "cm", "m", "in", "ft", "um")
UNITS_HELP = ("the length unit of the coordinates (default mm): STEP, IGES and .3dm files declare it, "
              "the numbers written unchanged; STEP, IGES and .3dm inputs are converted into it; BREP holds no unit")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export", help="write NURBS geometry as STEP, IGES, BREP, .3dm, JSON or a mesh",
        description="Read INPUT (nurbskit JSON or a patch set, .3dm, STEP, IGES, BREP, another NURBS file, "
                    "or a triangle mesh) and write OUTPUT in the format of its extension or --format: "
                    "CAD files (.step/.stp, .iges/.igs, .brep: read back and checked by OpenCASCADE), "
                    ".3dm, nurbskit .json, or a tessellation (.obj, .ply, .stl, .gltf, .glb, .off).")
    p.add_argument("input", metavar="INPUT", help="file to read")
    p.add_argument("output", metavar="OUTPUT", help="file to write")
    p.add_argument("--format", choices=FORMAT_CHOICES + ("json", "glb", "off"), default=None,
                   help="output format (default: OUTPUT's extension)")
    p.add_argument("--tolerance", type=float, default=None, metavar="T",
                   help="tessellation: largest distance from a triangle to the surface, in model units "
                        "(default 1e-3 of the bounding-box diagonal)")
    p.add_argument("--units", choices=UNIT_CHOICES, default="mm", help=UNITS_HELP)
    p.add_argument("--bspline", action="store_true",
                   help="a `nurbskit shape` report: write its exact NURBS, not the analytic surface of "
                        "revolution / extrusion")
    p.add_argument("--no-check", action="store_true",
                   help="CAD files: do not read the file back and check it (not recommended)")
    p.set_defaults(run=run_export)


def add_format_option(parser) -> None:
    """``--format step|iges|brep|3dm|obj|ply|stl|gltf``, ``--mesh-tolerance`` and ``--units`` for a
    result command (not ``--tolerance``: the fitting commands use that name for their stopping rule)."""
    parser.add_argument("--format", dest="export_format", choices=FORMAT_CHOICES, default=None,
                        help="also write the result in this format (CAD files are read back and checked)")
    parser.add_argument("--mesh-tolerance", dest="export_tolerance", type=number_in(0, low_open=True), default=None,
                        metavar="T",
                        help="with --format obj/ply/stl/gltf: tessellation tolerance in model units "
                             "(default 1e-3 of the bounding-box diagonal)")
    parser.add_argument("--units", dest="export_units", choices=UNIT_CHOICES, default="mm",
                        help="with --format step/iges/3dm: the length unit of the coordinates, which the file "
                             "declares (default mm; the numbers are written unchanged)")


def check_format_options(args) -> None:
    """Check ``--mesh-tolerance`` (see :func:`add_format_option`) before a command's work
    starts: one line naming the option when it is not a tolerance OpenCASCADE can mesh to.
    (Whether the mesh fits in memory depends on the result: checked when it is written.)"""
    from ..io.cad.exchange import check_tolerance

    check_tolerance(getattr(args, "export_tolerance", None), "--mesh-tolerance")


def write_requested_format(args, obj, folder, stem: str) -> None:
    """With ``--format F`` (see :func:`add_format_option`), write ``obj`` as ``folder/stem.F``
    (and say what that format cannot store, as ``nurbskit export`` does)."""
    if args.export_format:
        name = f"{stem}.{args.export_format}"
        report = write_result(obj, Path(folder) / name, format=args.export_format,
                              tolerance=args.export_tolerance, tolerance_option="--mesh-tolerance",
                              units=getattr(args, "export_units", "mm"))
        say_left_out(report, name, f"nurbskit {args.command}")


def say_left_out(report: dict, name, command: str) -> None:
    """One line on stderr when the written format left something out (``report["left_out"]``)."""
    if report.get("left_out"):
        suffix = Path(name).suffix
        sys.stderr.write(f"{command}: note: {suffix} cannot store {', '.join(report['left_out'])}; "
                         f"left out of {name}\n")


def write_result(obj, path, format: str | None = None, tolerance: float | None = None, *,
                 tolerance_option: str = "--mesh-tolerance", units: str = "mm", units_option: str = "--units",
                 **kwargs) -> dict:
    """Write a result in any format (see :func:`nurbskit.io.cad.write_result`); messages about
    ``tolerance`` name ``tolerance_option``, about ``units`` ``units_option``."""
    from ..io.cad import write_result as _write

    return _write(obj, path, format=format, tolerance=tolerance, tolerance_option=tolerance_option, units=units,
                  units_option=units_option, **kwargs)


def run_export(args) -> int:
    from ..io.export import export_file

    out = Path(args.output)
    report = export_file(args.input, out, format=args.format, tolerance=args.tolerance, check=not args.no_check,
                         analytic=not args.bspline, units=args.units)
    parts = [f"wrote {out} ({report['format']}"]
    if "faces" in report:
        faces = f"{report['faces']} face" + ("" if report["faces"] == 1 else "s")
        if report.get("solids"):
            faces += f", {report['solids']} solid" + ("" if report["solids"] == 1 else "s")
        parts.append(f", {faces}, OpenCASCADE check {'passed' if report.get('valid') else 'skipped'}")
    if "triangles" in report:
        parts.append(f", {report['triangles']:,} triangles")
    sys.stderr.write("nurbskit export: " + "".join(parts) + ")\n")
    say_left_out(report, out, "nurbskit export")
    return 0


__all__ = ["register", "run_export", "add_format_option", "check_format_options", "write_result", "FORMAT_CHOICES",
           "UNIT_CHOICES"]
