"""CAD exchange: STEP, IGES and BREP through OpenCASCADE (OCP), Rhino ``.3dm`` through
rhino3dm. Both are the ``[cad]`` extra (``pip install 'nurbskit[cad]'``), imported on
first use: importing this package needs neither.

- :mod:`.occ`: curves and surfaces to ``Geom_BSplineCurve`` / ``Geom_BSplineSurface``
  and back, exactly (knots with multiplicities, weights, degrees, periodic flags).
- :mod:`.shapes`: trimmed surfaces to faces with trimming wires, patch sets to sewn
  shells, meshes to triangulated solids; any shape back to nurbskit objects.
- :mod:`.exchange`: the files (written, read back, checked with ``BRepCheck_Analyzer``),
  ``cad_info`` for ``nurbskit info``, and ``write_result`` for every output format.
- :mod:`.rhino`: ``.3dm``.

- :mod:`.analytic`: :class:`RevolvedSurface` / :class:`ExtrudedSurface` (a profile and its
  sweep, e.g. from ``nurbskit shape``'s report), written as STEP's
  ``SURFACE_OF_REVOLUTION`` / ``SURFACE_OF_LINEAR_EXTRUSION``; ``to_nurbs()`` is the exact
  NURBS. Reading converts such faces to B-splines (OCC's ``BRepBuilderAPI_NurbsConvert``).

Example:
    >>> import torch, nurbskit
    >>> from nurbskit.io.cad import write_cad, read_cad
    >>> s = nurbskit.NURBSSurface(torch.rand(5, 5, 3, dtype=torch.float64), (3, 3))
    >>> write_cad(s, "patch.step")["valid"]  # doctest: +SKIP
    True
    >>> read_cad("patch.step").faces[0].surface.sizes  # doctest: +SKIP
    (5, 5)
"""

from .analytic import ExtrudedSurface, RevolvedSurface, swept_from_report
from .exchange import (
    CAD_FORMATS,
    RESULT_FORMATS,
    cad_format,
    cad_info,
    objects_to_json,
    read_cad,
    read_objects,
    read_shape,
    result_format,
    tessellate_objects,
    write_cad,
    write_result,
    write_shape,
)
from .occ import curve_from_occ, curve_to_occ, is_periodic, surface_from_occ, surface_to_occ
from .rhino import read_3dm, read_3dm_all, write_3dm, write_3dm_objects
from .shapes import CadModel, check_shape, face_of, mesh_solid, shape_to_model, tessellate_shape, to_shape

__all__ = [
    "CadModel", "write_cad", "read_cad", "cad_info", "write_result", "read_objects", "objects_to_json",
    "write_shape", "read_shape", "cad_format", "result_format", "tessellate_objects", "CAD_FORMATS",
    "RESULT_FORMATS", "curve_to_occ", "curve_from_occ", "surface_to_occ", "surface_from_occ", "is_periodic",
    "to_shape", "face_of", "mesh_solid", "shape_to_model", "check_shape", "tessellate_shape",
    "read_3dm", "read_3dm_all", "write_3dm", "write_3dm_objects", "RevolvedSurface", "ExtrudedSurface",
    "swept_from_report",
]
