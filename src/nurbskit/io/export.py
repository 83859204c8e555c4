"""One file in, one file out: what ``nurbskit export INPUT OUTPUT`` does, as a library call.

:func:`export_file` reads any input ``nurbskit export`` accepts and writes it in the
output format through :func:`nurbskit.io.cad.write_result` (CAD files read back and
checked by OpenCASCADE). ``nurbskit export`` and ``nurbskit batch export`` are thin
command lines over it.

Example:
    >>> from nurbskit.io.export import export_file
    >>> export_file("fit/surface.json", "surface.step")["valid"]  # doctest: +SKIP
    True
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError, OptionError

MESH_INPUTS = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")
"""Extensions read as triangle meshes (unless the file is a NURBS file of that extension)."""


def read_exportable(path: str | os.PathLike, *, units: str = "mm") -> list:
    """The objects of ``path``: ``[mesh]`` for a triangle mesh, else the NURBS objects
    (nurbskit JSON or a patch set, ``.3dm``, STEP, IGES, BREP, the other NURBS files).
    STEP and IGES coordinates are converted into ``units``; the rest are read as they are."""
    from .cad import read_objects
    from .nurbs import is_nurbs_file

    path = Path(path)
    if path.suffix.lower() in MESH_INPUTS and not is_nurbs_file(path):
        from .mesh import read_mesh

        return [read_mesh(path)]
    return read_objects(path, units=units)


def _elements(obj) -> list:
    """A batch of splines as its elements (in order, every batch axis flattened), so that
    each is written as one face or curve; anything else as it is."""
    if not getattr(obj, "batch_shape", ()):
        return [obj]
    return [e for i in range(obj.batch_shape[0]) for e in _elements(obj[i])]


#: The geometry file of each kind of nurbskit output folder, in the order looked for:
#: `nurbskit patches` (patches.json), `fit` and `shape` (surface.json), `volume` (volume.json).
FOLDER_FILES = ("patches.json", "surface.json", "volume.json")


def folder_input(folder: Path) -> Path:
    """The file to export from an output folder of a nurbskit command.

    A `nurbskit shape` folder gives its ``report.json`` (the analytic surface of
    revolution or extrusion; a free-form result its ``surface.json``); the other commands'
    folders give the first of :data:`FOLDER_FILES` they hold. Any other folder is an
    InputError naming the files looked for.
    """
    from ._json import load_json

    report = folder / "report.json"
    if report.is_file():
        data = load_json(report)
        if isinstance(data, dict) and data.get("kind") in ("revolution", "extrusion") and "profile" in data:
            return report
    for name in FOLDER_FILES:
        if (folder / name).is_file():
            return folder / name
    raise InputError(
        f"{folder}: a folder was given, holding none of {', '.join(FOLDER_FILES)}; "
        f"pass the file to export, e.g. {folder / 'surface.json'}"
    )


def export_file(input: str | os.PathLike, output: str | os.PathLike, *, format: str | None = None,
                tolerance: float | None = None, check: bool = True, analytic: bool = True,
                tolerance_option: str = "--tolerance", units: str = "mm", units_option: str = "--units") -> dict:
    """Read ``input`` and write it to ``output`` (format: ``format`` or the extension).

    Args:
        input: a file, or the output folder of a nurbskit command (see :func:`folder_input`).
        tolerance: tessellation tolerance in model units for mesh outputs (default 1e-3
            of the bounding-box diagonal); refused before any work when the mesh it asks
            for would not fit in memory.
        check: read CAD files back and check them with OpenCASCADE (a failure raises).
        analytic: a ``nurbskit shape`` result (its ``report.json`` or its folder) goes to
            STEP / IGES / BREP as a surface of revolution or extrusion over the exact
            B-spline profile; False writes the exact NURBS instead.
        tolerance_option: the name of ``tolerance`` in messages.
        units: the length unit of the coordinates (``mm``, ``cm``, ``m``, ``in``, ``ft``,
            ``um``; default ``mm``): a STEP, IGES or ``.3dm`` input is converted into it from
            the unit it declares, and STEP, IGES and ``.3dm`` outputs declare it (the numbers
            written unchanged). BREP, JSON, meshes and the other inputs hold no unit.
        units_option: the name of ``units`` in messages.

    Returns:
        The report of :func:`nurbskit.io.cad.write_result` (``format``, ``path``; for CAD
        files ``valid`` and the counts of faces, shells...; for meshes ``triangles``;
        ``left_out`` where the format cannot store everything).

    Raises:
        InputError: ``input`` is missing, empty or unreadable. OptionError: a bad
        ``format``, ``tolerance``, ``units`` or ``output`` name, or ``output`` is ``input``.
    """
    from ._base import check_not_input, check_readable
    from .cad import write_result
    from .cad.exchange import CAD_FORMATS, check_tolerance, check_units, result_format

    src = Path(input)
    if src.is_dir():
        src = folder_input(src)
    src, out = check_readable(src), Path(output)
    if out.is_dir():
        raise OptionError(f"{out}: is a directory, expected an output file name")
    check_not_input(out, [src])
    check_tolerance(tolerance, tolerance_option)
    check_units(units, units_option)
    if src.suffix.lower() in CAD_FORMATS and result_format(out, format) in CAD_FORMATS.values():
        return _cad_to_cad(src, out, result_format(out, format), check, units)
    obj = [element for o in read_exportable(src, units=units) for element in _elements(o)]
    try:
        return write_result(obj, out, format=format, tolerance=tolerance, check=check,
                            analytic=analytic, tolerance_option=tolerance_option, units=units,
                            units_option=units_option)
    except (InputError, OptionError) as exc:  # what the geometry cannot be written as: name the file it came from
        if str(exc).startswith((str(src), str(out), "--")):
            raise
        raise type(exc)(f"{src}: {exc}") from None


def _cad_to_cad(src: Path, out: Path, fmt: str, check: bool, units: str) -> dict:
    """A CAD file to another: OCC's shape as it was read (solids, shells, shared edges,
    analytic faces), not its faces as nurbskit reads them (B-splines with polyline trims,
    sewn again, which lost the solids and most shared edges of the ABC model). The check
    reads the file back healed, as the input was read."""
    from .cad.exchange import read_shape, write_shape

    report = write_shape(read_shape(src, units=units), out, format=fmt, check=check, units=units, heal_check=True)
    return {**report, "path": str(out)}


__all__ = ["export_file", "read_exportable", "folder_input", "MESH_INPUTS", "FOLDER_FILES"]
