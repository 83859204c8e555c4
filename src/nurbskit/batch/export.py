"""``nurbskit batch export``: one output folder per input around :func:`nurbskit.io.export.export_file`.

The single ``nurbskit export INPUT OUTPUT`` writes one file; a batch writes folders
(``DIR/<name>/``, built under a temporary name and renamed into place, then marked
complete). So each item runs this module's ``export`` parser, which only the batch
registers (it is no top-level command):

    nurbskit batch export INPUTS... --out DIR -- --format step [--tolerance T] [--no-check] [--units m]

writes ``DIR/<name>/<input stem>.<format>`` and ``DIR/<name>/report.json`` (the report
of :func:`~nurbskit.io.export.export_file`: ``format``, ``valid`` and the face counts of
a CAD file read back by OpenCASCADE, ``triangles`` of a mesh, ``left_out``; plus
``input``, ``file`` and ``bytes``). The options mean what they mean in
``nurbskit export``; ``--format`` defaults to ``step``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..cli.export_command import UNIT_CHOICES, UNITS_HELP
from ..errors import OptionError

# nurbskit export's output formats (nurbskit.cli.export_command's --format choices)
FORMATS = ("step", "iges", "brep", "3dm", "json", "obj", "ply", "stl", "gltf", "glb", "off")

# What a folder given as INPUT contributes: NURBS and CAD files. Meshes (to a solid of
# triangles) are exported when named explicitly or by a pattern: a folder of results
# holds point-only .off files that are no meshes.
EXTENSIONS = (".json", ".3dm", ".step", ".stp", ".iges", ".igs", ".brep", ".ctrlpts", ".cptw", ".smesh")
# Files of nurbskit's own outputs that are no geometry: a folder search skips them.
NOT_GEOMETRY = ("report.json", "config.json", "summary.json")


def register(subparsers) -> None:
    p = subparsers.add_parser("export", description="one input to DIR/<input stem>.<format> and DIR/report.json")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--format", choices=FORMATS, default="step", help="output format (default step)")
    p.add_argument("--tolerance", type=float, default=None,
                   help="mesh formats: tessellation tolerance in model units (default 1e-3 of the diagonal)")
    p.add_argument("--no-check", action="store_true", help="CAD files: do not read the file back and check it")
    p.add_argument("--units", choices=UNIT_CHOICES, default="mm", help=UNITS_HELP)
    p.set_defaults(run=run_export_item)


def run_export_item(args) -> int:
    """Export ``args.input`` into the folder ``args.out`` (see the module docstring)."""
    from .._fs import atomic_open, output_directory
    from ..io._base import check_readable
    from ..io.export import export_file

    if args.tolerance is not None and not args.tolerance > 0:
        raise OptionError(f"--tolerance must be positive, got {args.tolerance}")
    src = check_readable(args.input)
    name = f"{src.stem}.{args.format}"
    with output_directory(args.out, args.overwrite, inputs=[args.input]) as tmp:
        report = export_file(src, tmp / name, format=args.format, tolerance=args.tolerance, check=not args.no_check,
                             units=args.units)
        report.update(input=os.fspath(src), file=name, bytes=(tmp / name).stat().st_size)
        report["path"] = os.fspath(Path(args.out) / name)  # where it lies once the folder is in place
        with atomic_open(tmp / "report.json", "w", encoding="utf-8") as handle:
            json.dump(report, handle, indent=1)
    return 0


def export_metrics(report: dict) -> dict:
    """``export``'s headline: ``valid`` (1 or 0: OpenCASCADE's check of the file read back;
    NaN when not checked or not a CAD file), ``faces`` read back, ``triangles`` (mesh
    formats) and the file's size in bytes."""
    nan = float("nan")
    valid = report.get("valid")
    return {"valid": float(valid) if isinstance(valid, bool) else nan,
            "faces": float(report["faces"]) if "faces" in report else nan,
            "triangles": float(report["triangles"]) if "triangles" in report else nan,
            "bytes": float(report.get("bytes", nan))}
