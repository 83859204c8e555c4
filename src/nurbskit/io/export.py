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

from ..errors import OptionError

MESH_INPUTS = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")
"""Extensions read as triangle meshes (unless the file is a NURBS file of that extension)."""


def read_exportable(path: str | os.PathLike) -> list:
    """The objects of ``path``: ``[mesh]`` for a triangle mesh, else the NURBS objects
    (nurbskit JSON or a patch set, ``.3dm``, STEP, IGES, BREP, the other NURBS files)."""
    from .cad import read_objects
    from .nurbs import is_nurbs_file

    path = Path(path)
    if path.suffix.lower() in MESH_INPUTS and not is_nurbs_file(path):
        from .mesh import read_mesh

        return [read_mesh(path)]
    return read_objects(path)


def export_file(input: str | os.PathLike, output: str | os.PathLike, *, format: str | None = None,
                tolerance: float | None = None, check: bool = True, analytic: bool = True) -> dict:
    """Read ``input`` and write it to ``output`` (format: ``format`` or the extension).

    Args:
        tolerance: tessellation tolerance in model units for mesh outputs (default 1e-3
            of the bounding-box diagonal).
        check: read CAD files back and check them with OpenCASCADE (a failure raises).
        analytic: a ``nurbskit shape`` result (its ``report.json`` or its folder) goes to
            STEP / IGES / BREP as a surface of revolution or extrusion over the exact
            B-spline profile; False writes the exact NURBS instead.

    Returns:
        The report of :func:`nurbskit.io.cad.write_result` (``format``, ``path``; for CAD
        files ``valid`` and the counts of faces, shells...; for meshes ``triangles``;
        ``left_out`` where the format cannot store everything).

    Raises:
        InputError: ``input`` is missing, empty or unreadable. OptionError: a bad
        ``format``, ``tolerance`` or ``output`` name.
    """
    from ._base import check_readable
    from .cad import write_result

    src = Path(input)
    if src.is_dir() and (src / "report.json").is_file():  # a `nurbskit shape` folder
        src = src / "report.json"
    src, out = check_readable(src), Path(output)
    if out.is_dir():
        raise OptionError(f"{out}: is a directory, expected an output file name")
    if tolerance is not None and not tolerance > 0:
        raise OptionError(f"--tolerance must be positive, got {tolerance}")
    return write_result(read_exportable(src), out, format=format, tolerance=tolerance, check=check,
                        analytic=analytic)


__all__ = ["export_file", "read_exportable", "MESH_INPUTS"]
