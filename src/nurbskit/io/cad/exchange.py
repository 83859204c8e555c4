"""STEP, IGES and BREP files through OpenCASCADE: written, read back and checked.

Writing (:func:`write_cad`): nurbskit objects become an OCC shape
(:func:`~nurbskit.io.cad.shapes.to_shape`), OCC's own translator writes the file, and the
file is then read back with OCC, without its shape healing (:data:`CHECK_READ_FIXES`: the
check is of the file as written), and checked with ``BRepCheck_Analyzer`` (and its face
count compared): a failing check is a :class:`~nurbskit.errors.NurbskitError` and the
file is not left behind (writes are atomic).

Precision: OCC's STEP writer prints reals with 12 decimals (``%14.12f`` between 0.1 and
1000, ``%14.12E`` elsewhere), which loses up to 5e-13 of every coordinate and knot. Here
the same writer (``StepData_StepWriter``, fed the model that ``STEPControl_Writer``
translated) prints 17 significant digits, so a STEP file round-trips bit for bit (tested).
IGES the same way: OCC's ``IGESControl_Writer`` translates (trimmed surfaces, entity 144
over 128, with 126 curves) and ``IGESData_IGESWriter`` prints 17 significant digits
instead of OCC's 9 (``%11.9E``, which loses about 1e-8 of the diagonal, measured in
tests/test_io_cad.py). BREP, OCC's own format, keeps every bit as it is.

Units (:data:`UNITS`): ``units`` names the length unit nurbskit's coordinates are in
(default ``"mm"``). STEP, IGES and ``.3dm`` files are written with the numbers as they are
(bit for bit) and declare that unit; reading STEP and IGES converts from the unit the file
declares into ``units`` (OCC's readers). BREP holds no unit: written and read as it is.
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import numpy as np
import torch

from ..._fs import atomic_path
from ...core.trim import TrimmedSurface
from ...errors import InputError, NurbskitError, OptionError
from .occ import ocp
from .shapes import CadModel, check_shape, count_shapes, shape_to_model, tessellate_shape, to_shape

CAD_FORMATS = {".step": "step", ".stp": "step", ".iges": "iges", ".igs": "iges", ".brep": "brep",
               ".brp": "brep"}
MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".stl": "stl", ".gltf": "gltf", ".glb": "glb", ".off": "off"}

_QUIET = False


def _quiet() -> None:
    """OCC's translators print progress, statistics and their parsers' errors (in colour)
    on stdout; library code never prints: the default printers are removed, and every
    failure is reported by the caller in one line of its own."""
    global _QUIET
    if _QUIET:
        return
    ocp()
    from OCP.Message import Message

    messenger = Message.DefaultMessenger_s()
    for printer in list(messenger.Printers()):
        messenger.RemovePrinter(printer)
    _QUIET = True


def cad_format(path: str | os.PathLike, format: str | None = None) -> str:
    """'step', 'iges' or 'brep' for ``path`` (by ``format``, else by extension)."""
    path = Path(path)
    if format is not None:
        name = format.lower().lstrip(".")
        name = {"stp": "step", "igs": "iges", "brp": "brep"}.get(name, name)
        if name not in ("step", "iges", "brep"):
            raise OptionError(f"CAD format must be step, iges or brep, got {format!r}")
        return name
    ext = path.suffix.lower()
    if ext not in CAD_FORMATS:
        raise OptionError(f"{path}: not a CAD file name; expected .step/.stp, .iges/.igs or .brep")
    return CAD_FORMATS[ext]


# ---- units --------------------------------------------------------------------------------

#: The length units nurbskit's coordinates can be in: nurbskit's name -> (OCC's STEP name,
#: as the ``Interface_Static`` settings ``xstep.cascade.unit`` / ``write.step.unit`` take
#: it; IGES name, as ``IGESControl_Writer`` takes it; millimetres per unit; rhino3dm's
#: ``UnitSystem`` member).
UNITS = {
    "mm": ("MM", "MM", 1.0, "Millimeters"),
    "cm": ("CM", "CM", 10.0, "Centimeters"),
    "m": ("M", "M", 1000.0, "Meters"),
    "in": ("INCH", "IN", 25.4, "Inches"),
    "ft": ("FT", "FT", 304.8, "Feet"),
    "um": ("UM", "UM", 0.001, "Microns"),
}


def check_units(units, option: str = "units") -> str:
    """``units`` if it is a key of :data:`UNITS`, else an OptionError naming ``option`` and
    the units allowed."""
    if isinstance(units, str) and units in UNITS:
        return units
    raise OptionError(f"{option} must be one of {', '.join(UNITS)}, got {units!r}")


# ---- writing ------------------------------------------------------------------------------

def _write_step(shape, path: Path, units: str = "mm") -> None:
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_StepModelType, STEPControl_Writer
    from OCP.StepData import StepData_StepWriter

    name = UNITS[units][0]
    # the shape's unit (xstep.cascade.unit) and the file's (write.step.unit) the same: the
    # numbers are written unchanged and the file declares that unit (with write.step.unit
    # alone OCC would scale from millimetres)
    statics = {**STEP_WRITE_STATICS, "xstep.cascade.unit": name, "write.step.unit": name}
    with _TRANSLATOR_LOCK:  # the settings are global to the process
        writer = STEPControl_Writer()
        with _statics(statics):
            status = writer.Transfer(shape, STEPControl_StepModelType.STEPControl_AsIs)
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise NurbskitError(f"{path}: OpenCASCADE could not translate the shape to STEP ({status})")
    model = writer.Model()
    # 17 significant digits (see the module docstring)
    _print_model(StepData_StepWriter(model), model.Protocol(), MID_RANGE_FORMAT, path, "STEP")


#: STEP holds one uncertainty for the whole file (no tolerance per edge, as BREP has): it is
#: written as the shape's largest tolerance (``write.precision.mode`` 1), not OCC's default
#: (the average), so that a reader keeps the exact pcurves of edges whose 3-D curve
#: approximates the trim within that edge's tolerance (with the average, OCC's reader
#: re-derived such pcurves from the 3-D curve: trims read back moved by 0.14 mm on a
#: patch of 874 mm, where IGES and BREP read back exactly)
STEP_WRITE_STATICS = {"write.precision.mode": 1}


#: how reals between 0.1 and 1000 are printed (the others: ``%.16E``): 17 significant
#: digits, which give back every double exactly; ``#`` keeps the decimal point that STEP
#: and IGES reals need ('%.17f' printed up to 20 digits: 3 more characters per number
#: between 100 and 1000)
MID_RANGE_FORMAT = "%#.17G"


def _print_model(out, protocol, mid_range_format: str, path: Path, what: str) -> None:
    """Send ``protocol``'s model to OCC's text writer ``out`` with 17 significant digits
    (OCC's default keeps 12 in STEP, 9 in IGES) and write the text to ``path``."""
    out.FloatWriter().SetFormat("%.16E")
    out.FloatWriter().SetFormatForRange(mid_range_format, 0.1, 1000.0)
    out.SendModel(protocol)
    with open(path, "wb") as handle:  # straight to the file: through a BytesIO took twice as long
        if not out.Print(handle):
            raise NurbskitError(f"{path}: OpenCASCADE could not write the {what} text")


def _write_iges(shape, path: Path, units: str = "mm") -> None:
    from OCP.IGESControl import IGESControl_Writer
    from OCP.IGESData import IGESData_IGESWriter
    from OCP.IGESSolid import IGESSolid

    _, name, mm_per_unit, _ = UNITS[units]
    with _TRANSLATOR_LOCK:  # the writer reads the global xstep.cascade.unit when it is made
        writer = IGESControl_Writer(name, 0)  # 0: faces as trimmed surfaces (144), not B-rep entities
        # the shape is in the file's unit: the numbers are written unchanged (left to the
        # global setting, OCC would scale them from millimetres)
        model = writer.Model()
        section = model.GlobalSection()
        section.SetCascadeUnit(mm_per_unit)
        model.SetGlobalSection(section)
        if not writer.AddShape(shape):
            raise NurbskitError(f"{path}: OpenCASCADE could not translate the shape to IGES")
        writer.ComputeModel()
    # 17 significant digits instead of OCC's 9 ('%11.9E'); see the module docstring
    _print_model(IGESData_IGESWriter(writer.Model()), IGESSolid.Protocol_s(), MID_RANGE_FORMAT, path, "IGES")


def _write_brep(shape, path: Path) -> None:
    from OCP.BRepTools import BRepTools

    if not BRepTools.Write_s(shape, str(path)):
        raise NurbskitError(f"{path}: OpenCASCADE could not write the BREP file")


def write_shape(shape, path: str | os.PathLike, *, format: str | None = None, check: bool = True,
                units: str = "mm", heal_check: bool = False) -> dict:
    """Write an OCC shape as STEP, IGES or BREP, atomically, then read it back and check it.

    ``units``: the unit of the shape's coordinates (a key of :data:`UNITS`); STEP and IGES
    files declare it, and the numbers are written unchanged. BREP holds no unit.
    ``heal_check``: read the file back for the check as any reader would, with OCC's
    healing (a shape read from a CAD file that is itself valid only healed: the ABC
    model), rather than as written (:data:`CHECK_READ_FIXES`, the default for nurbskit's
    own geometry).

    Returns:
        The check report: ``format``, ``valid`` (``BRepCheck_Analyzer`` on the shape read
        back), counts of ``solids``, ``shells``, ``faces``, ``edges`` read back, and
        ``faces_written``, ``solids_written``, ``shells_written``; for IGES of a shape with
        solids or shells, ``left_out`` (:data:`IGES_LEFT_OUT`).

    Raises:
        NurbskitError: OCC could not write the file, or the file read back is invalid or
        lost faces (the file is then not written).
    """
    _quiet()
    path = Path(path)
    fmt = cad_format(path, format)
    check_units(units)
    written = count_shapes(shape)
    with atomic_path(path) as tmp:
        if fmt == "brep":
            _write_brep(shape, tmp)
        else:
            (_write_step if fmt == "step" else _write_iges)(shape, tmp, units)
        report = {"format": fmt, **{f"{k}_written": written[k] for k in ("faces", "solids", "shells")}}
        if fmt == "iges" and (written["solids"] or written["shells"]):
            report["left_out"] = [IGES_LEFT_OUT]
        if check:
            back = read_shape(tmp, format=fmt, heal=heal_check, units=units)
            found = check_shape(back)
            report.update(found)
            if not found["valid"]:
                raise NurbskitError(f"{path}: the {fmt.upper()} file read back fails OpenCASCADE's check "
                                    "(BRepCheck_Analyzer); not written")
            if found["faces"] != written["faces"]:
                raise NurbskitError(f"{path}: wrote {written['faces']} faces but read back {found['faces']}; not written")
    return report


#: What an IGES file (faces as trimmed surfaces, entity 144) does not hold of a shape.
IGES_LEFT_OUT = "solids and shells (IGES trimmed surfaces: the faces only)"


def write_cad(obj, path: str | os.PathLike, *, format: str | None = None, sew_tolerance: float | None = 1e-6,
              check: bool = True, analytic: bool = True, units: str = "mm") -> dict:
    """Write nurbskit objects to a STEP (.step/.stp), IGES (.iges/.igs) or BREP (.brep) file.

    Args:
        obj: a NURBSSurface, TrimmedSurface, NURBSCurve, a mesh (``vertices`` and
            ``faces``, written as a solid of triangles), or a list of them (a compound;
            surfaces sharing edges within ``sew_tolerance`` are sewn into shells).
        path: the file; its extension picks the format unless ``format`` is given.
        check: read the file back with OCC and check it (default; a failure raises).
        analytic: write :class:`~nurbskit.io.cad.analytic.RevolvedSurface` /
            ``ExtrudedSurface`` as STEP's ``SURFACE_OF_REVOLUTION`` /
            ``SURFACE_OF_LINEAR_EXTRUSION`` (IGES 120 / 122; default), else as their
            exact NURBS.
        units: the unit of the coordinates (``"mm"``, ``"cm"``, ``"m"``, ``"in"``, ``"ft"``,
            ``"um"``): written unchanged, and STEP / IGES declare it (BREP holds no unit).

    Returns:
        The check report of :func:`write_shape`.

    Example:
        >>> import torch, nurbskit
        >>> s = nurbskit.NURBSSurface(torch.rand(4, 4, 3, dtype=torch.float64), (3, 3))
        >>> write_cad(s, "patch.step")["valid"]  # doctest: +SKIP
        True
    """
    check_units(units)
    fmt = cad_format(path, format)
    # closed shells as solids, except in IGES, whose trimmed surfaces hold faces only
    shape = to_shape(obj, sew_tolerance=sew_tolerance, analytic=analytic, solids=fmt != "iges")
    try:
        return write_shape(shape, path, format=fmt, check=check, units=units)
    except NurbskitError:
        shells = to_shape(obj, sew_tolerance=sew_tolerance, analytic=analytic, solids=False)
        if count_shapes(shells)["solids"] == count_shapes(shape)["solids"]:
            raise
    # a closed shell made a solid that the format's reader does not read back valid, though
    # the shell alone is (a random doubly periodic net, seen in STEP): the shell as it was
    return write_shape(shells, path, format=fmt, check=check, units=units)


# ---- reading ------------------------------------------------------------------------------

def read_shape(path: str | os.PathLike, *, format: str | None = None, heal: bool = True, units: str = "mm"):
    """The OCC shape of a STEP, IGES or BREP file.

    ``heal``: let OCC's reader run its shape healing (``ShapeFix_Shape``, the default, as
    for any file from elsewhere); ``False`` reads the file as it is written, which is how
    :func:`write_shape` checks its own files (see :data:`CHECK_READ_FIXES`).
    ``units``: the unit (a key of :data:`UNITS`) that STEP and IGES coordinates are
    converted into from the unit the file declares; a BREP file is read as it is.
    """
    return _read_shape(path, format, heal, units)[0]


def _read_shape(path, format: str | None, heal: bool, units: str):
    """:func:`read_shape`, and the length unit the file declares (None for BREP)."""
    _quiet()
    from .._base import check_readable

    check_units(units)
    path = check_readable(path)
    fmt = cad_format(path, format)
    if fmt == "brep":
        from OCP.BRep import BRep_Builder
        from OCP.BRepTools import BRepTools
        from OCP.TopoDS import TopoDS_Shape

        shape = TopoDS_Shape()
        ok = BRepTools.Read_s(shape, str(path), BRep_Builder())
        if not ok or shape.IsNull():
            raise InputError(f"{path}: OpenCASCADE could not read it as a BREP file")
        return shape, None
    from OCP.IFSelect import IFSelect_ReturnStatus

    if fmt == "step":
        from OCP.STEPControl import STEPControl_Reader as Reader
    else:
        from OCP.IGESControl import IGESControl_Reader as Reader
    reader = Reader()
    status = reader.ReadFile(str(path))
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise InputError(f"{path}: OpenCASCADE could not read it as {fmt.upper()} ({status.name})")
    if not reader.WS().ModelCheckList(False).IsEmpty(True):
        # failures while loading the entities (a truncated file's unresolved references):
        # what translates is part of the model, and it would pass for the whole
        raise InputError(f"{path}: the {fmt.upper()} file has load failures (unresolved references or damaged "
                         "entities: truncated or corrupt?); refusing to read part of it")
    _convert_into(reader, fmt, units)
    with _TRANSLATOR_LOCK:
        transferred = _transfer(reader, fmt, heal)
    if transferred == 0:
        raise InputError(f"{path}: the {fmt.upper()} file holds no shape OpenCASCADE can translate")
    shape = reader.OneShape()
    if shape.IsNull():
        raise InputError(f"{path}: the {fmt.upper()} file holds no shape")
    return shape, _file_units(reader, fmt)


def _convert_into(reader, fmt: str, units: str) -> None:
    """Make ``reader`` (a file read, not yet transferred) convert the file's coordinates
    from the unit it declares into ``units``."""
    mm_per_unit = UNITS[units][2]
    if fmt == "step":
        reader.SetSystemLengthUnit(mm_per_unit)
        return
    # IGES's reader has no such call: it converts into the unit of its model's global
    # section, taken from the global setting xstep.cascade.unit when the file was read
    # (set around the transfer it changes nothing; measured)
    model = reader.IGESModel()
    section = model.GlobalSection()
    section.SetCascadeUnit(mm_per_unit)
    model.SetGlobalSection(section)


def _file_units(reader, fmt: str) -> str | None:
    """The length unit a STEP or IGES file declares, as the file names it (STEP:
    ``METRE``, ``MILLIMETRE``, ``INCH``...; IGES: its global section's unit name, ``MM``,
    ``M``, ``IN``...), or None when it names none."""
    if fmt == "step":
        from OCP.collections import Sequence_TCollection_AsciiString as Names

        length, angle, solid_angle = Names(), Names(), Names()
        reader.FileUnits(length, angle, solid_angle)
        names = sorted({length.Value(i).ToCString() for i in range(1, length.Length() + 1)})
        return ", ".join(names) or None
    name = reader.IGESModel().GlobalSection().UnitName()
    return name.ToCString() if name is not None and not name.IsEmpty() else None


#: OCC's translator settings are global to a process (the shape-fix parameters of a
#: format's shared actor, ``Interface_Static``): a check's unhealed read and a user's
#: healed one on another thread (the studio's) must not see each other's.
_TRANSLATOR_LOCK = threading.Lock()


def _transfer(reader, fmt: str, heal: bool) -> int:
    """``reader.TransferRoots()``, healed as OCC does by default or, for the check, not."""
    if heal:
        return reader.TransferRoots()
    # the parameters live in the translator's actor, which OCC shares between readers
    # of a format: put the previous ones back, or later reads would not heal either
    from OCP.collections import DataMap_TCollection_AsciiString_TCollection_AsciiString as ParameterMap

    saved = ParameterMap()
    saved.Assign(reader.GetShapeFixParameters())
    reader.SetShapeFixParameters(_check_fix_parameters(fmt))
    try:
        with _statics(CHECK_READ_STATICS[fmt]):
            return reader.TransferRoots()
    finally:
        reader.SetShapeFixParameters(saved)


#: Reading back a file just written (the check of :func:`write_shape`), OCC's shape
#: healing is reduced to what any reader of such a file must do: the check is of the file
#: as written, not as OCC would repair it (healing could hide a defect), and healing was
#: most of the reading time (STEP: 0.55 -> 0.2 s CPU for benchmarks/bench_cad.py's 100
#: patches; IGES: 1.8 -> 0.4 s). Every ``FixShape`` operator is off (``0``) except
#: (``-1``: OCC decides, its default) for STEP, putting a pcurve into the period of its
#: face on a periodic surface (``FixShiftedMode``, under ``FixEdgeCurvesMode`` of
#: ``FixWireMode`` of ``FixFaceMode`` of ``FixFreeShellMode``: STEP's reader places a seam's
#: pcurves one period off), and for IGES, joining a face's boundary curves into closed
#: wires: IGES trimmed surfaces (entity 144) hold curves without vertices (and where a
#: boundary passes through a surface's pole, as on a sphere, the degenerate edge there;
#: a seam that IGES keeps only as a curve in (u, v) gets its 3-D curve). STEP has no
#: degenerate edge either: a face bounded by a pole (a closed fit's pole rows) is written
#: with a loop of its seam edges alone, so the reader adds the degenerate edge that closes
#: the loop in (u, v) (``FixLackingMode``, ``ClosedWireMode``), as for IGES; without it the
#: demo's fit of the duck (periodic in v, two poles, rational) was refused as invalid.
CHECK_READ_FIXES = {
    "step": ("FixFreeShellMode", "FixFaceMode", "FixWireMode", "FixEdgeCurvesMode", "FixShiftedMode",
             "FixLackingMode", "ClosedWireMode"),
    "iges": ("FixFreeFaceMode", "FixWireMode", "FixConnectedMode", "ClosedWireMode", "FixLackingMode",
             "FixEdgeCurvesMode", "FixAddCurve3dMode"),
}
#: and for IGES, B-spline curves are not split at their C0 knots into C1 pieces
#: (``read.iges.bspline.continuity`` 1, OCC's default, made 4 edges of each edge of 4
#: polyline segments: 9,600 edges instead of 2,400 to check)
CHECK_READ_STATICS = {"step": {}, "iges": {"read.iges.bspline.continuity": 0}}

_FIX_OPERATORS = (
    "FixFreeShellMode FixFreeFaceMode FixFreeWireMode FixSameParameterMode FixSolidMode FixShellOrientationMode "
    "CreateOpenSolidMode FixShellMode FixFaceOrientationMode FixFaceMode FixWireMode FixOrientationMode "
    "FixAddNaturalBoundMode FixMissingSeamMode FixSmallAreaWireMode RemoveSmallAreaFaceMode "
    "FixIntersectingWiresMode FixLoopWiresMode FixSplitFaceMode AutoCorrectPrecisionMode ModifyTopologyMode "
    "ModifyGeometryMode ClosedWireMode PreferencePCurveMode FixReorderMode FixSmallMode FixConnectedMode "
    "FixEdgeCurvesMode FixDegeneratedMode FixLackingMode FixSelfIntersectionMode RemoveLoopMode FixReversed2dMode "
    "FixRemovePCurveMode FixRemoveCurve3dMode FixAddPCurveMode FixAddCurve3dMode FixSeamMode FixShiftedMode "
    "FixEdgeSameParameterMode FixNotchedEdgesMode FixTailMode FixSelfIntersectingEdgeMode FixIntersectingEdgesMode "
    "FixNonAdjacentIntersectingEdgesMode FixVertexPositionMode FixVertexToleranceMode").split()


def _check_fix_parameters(fmt: str):
    """OCC's shape-processing parameters for reading back a file just written
    (:data:`CHECK_READ_FIXES`); the tolerances are OCC's defaults for both formats."""
    from OCP.collections import DataMap_TCollection_AsciiString_TCollection_AsciiString as ParameterMap
    from OCP.TCollection import TCollection_AsciiString as Text

    keep = CHECK_READ_FIXES[fmt]
    values = {f"FixShape.{name}": ("1" if name == "ClosedWireMode" else "-1") if name in keep else "0"
              for name in _FIX_OPERATORS}
    values.update({"FixShape.Tolerance3d": "1e-06", "FixShape.MaxTolerance3d": "1", "FixShape.MinTolerance3d": "1e-07",
                   "DetalizationLevel": "7" if fmt == "step" else "6", "NonManifold": "0"})
    parameters = ParameterMap()
    for key, value in values.items():
        parameters.Bind(Text(key), Text(value))
    return parameters


class _statics:
    """Set OCC's global translator settings (``Interface_Static``: ints with ``SetIVal``,
    strings, such as an enumeration's value name, with ``SetCVal``) for one transfer and put
    the previous values back afterwards. Callers hold :data:`_TRANSLATOR_LOCK`."""

    def __init__(self, values: dict):
        self.values, self.saved = values, {}

    def __enter__(self):
        from OCP.Interface import Interface_Static

        for name, value in self.values.items():
            if isinstance(value, str):
                saved, ok = Interface_Static.CVal_s(name), Interface_Static.SetCVal_s(name, value)
            else:
                saved, ok = Interface_Static.IVal_s(name), Interface_Static.SetIVal_s(name, value)
            if not ok:
                self.__exit__()
                raise NurbskitError(f"OpenCASCADE refused its setting {name} = {value!r}")
            self.saved[name] = saved
        return self

    def __exit__(self, *exc):
        from OCP.Interface import Interface_Static

        for name, value in reversed(self.saved.items()):
            if isinstance(value, str):
                Interface_Static.SetCVal_s(name, value)
            else:
                Interface_Static.SetIVal_s(name, value)
        self.saved = {}
        return False


def read_cad(path: str | os.PathLike, *, format: str | None = None, dtype=torch.float64,
             units: str = "mm") -> CadModel:
    """The faces (as TrimmedSurface: every face, analytic ones converted to B-splines by
    OCC, trimming as UV polylines) and free curves of a STEP, IGES or BREP file.

    ``units``: STEP and IGES coordinates are converted from the unit the file declares into
    this one (a key of :data:`UNITS`; default millimetres); BREP holds no unit."""
    path = Path(path)
    check_units(units)
    try:
        return shape_to_model(read_shape(path, format=format, units=units), dtype=dtype)
    except NurbskitError as exc:
        if str(exc).startswith(str(path)):
            raise
        raise InputError(f"{path}: {exc}") from None


def cad_info(path: str | os.PathLike) -> dict:
    """What ``nurbskit info`` says about a STEP / IGES / BREP file.

    Keys: ``file``, ``format``, ``kind`` ('cad'), ``num_faces``, counts of ``solids``,
    ``shells``, ``edges``, ``valid`` (BRepCheck_Analyzer on the shape read with OCC's
    default healing, as from any other program; ``write_shape`` checks its own files
    without it), ``surface_types`` (count per
    type), ``bbox`` and ``faces``: one entry per face with ``type`` (as stored),
    ``degrees``, ``sizes`` (control grid of its B-spline form), ``rational``, ``domain``,
    ``loops`` (outer + holes) and ``reversed``; ``units``: the length unit the file
    declares, as it names it (None for BREP, which has none; the numbers here are in
    millimetres, into which OCC's reader converts STEP and IGES).
    """
    path = Path(path)
    shape, declared = _read_shape(path, None, True, "mm")
    model = shape_to_model(shape)
    counts = check_shape(shape)
    faces, types = [], {}
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for trimmed, name, rev in zip(model.faces, model.face_types, model.reversed):
        s = trimmed.surface
        cp = s.control_points.detach().cpu().double().numpy().reshape(-1, 3)
        lo, hi = np.minimum(lo, cp.min(axis=0)), np.maximum(hi, cp.max(axis=0))
        types[name] = types.get(name, 0) + 1
        faces.append({"type": name, "degrees": list(s.degrees), "sizes": list(s.sizes),
                      "rational": bool(s.is_rational), "domain": [list(d) for d in s.domain],
                      "loops": len(trimmed.loops), "holes": len(trimmed.holes), "reversed": rev})
    return {
        "file": str(path), "format": cad_format(path), "kind": "cad", "num_faces": len(faces),
        "solids": counts["solids"], "shells": counts["shells"], "edges": counts["edges"],
        "num_curves": len(model.curves), "valid": counts["valid"], "surface_types": types, "units": declared,
        "bbox": [lo.tolist(), hi.tolist()] if faces else None,
        "note": "bbox of the control points of the faces' B-spline forms",
        "faces": faces,
    }


def format_cad_info(info: dict, max_faces: int = 50) -> str:
    """The text form of :func:`cad_info` (``nurbskit info`` without ``--json``)."""
    lines = [info["file"], f"  format      {info['format']}",
             f"  faces       {info['num_faces']} ({', '.join(f'{n} {k}' for k, n in info['surface_types'].items())})",
             f"  topology    {info['solids']} solids, {info['shells']} shells, {info['edges']} edges"
             + (f", {info['num_curves']} free curves" if info["num_curves"] else ""),
             f"  check       {'valid' if info['valid'] else 'INVALID'} (OpenCASCADE BRepCheck_Analyzer, "
             "after the healing OCC's reader applies to any file)"]
    if info.get("units"):
        lines.append(f"  units       the file declares {info['units']}; the numbers below are in millimetres")
    if info.get("bbox"):
        lo, hi = info["bbox"]
        lines.append("  bbox min    " + " ".join(f"{x:.6g}" for x in lo))
        lines.append("  bbox max    " + " ".join(f"{x:.6g}" for x in hi)
                     + "  (of the faces' control points: it holds the surfaces, loosely)")
    lines.append("  face  type                         degrees  control grid  rational  holes")
    for i, f in enumerate(info["faces"][:max_faces]):
        lines.append(f"  {i:4d}  {f['type']:<28} {f['degrees'][0]} x {f['degrees'][1]}    "
                     f"{f['sizes'][0]:>4} x {f['sizes'][1]:<5}  {'yes' if f['rational'] else 'no':<8}  {f['holes']}")
    if len(info["faces"]) > max_faces:
        lines.append(f"  ... {len(info['faces']) - max_faces} more faces (--json lists all)")
    return "\n".join(lines) + "\n"


# ---- any nurbskit result to any file --------------------------------------------------------

def read_objects(path: str | os.PathLike, *, units: str = "mm") -> list:
    """The geometry of a nurbskit JSON (one object, ``{"patches": [...]}`` or
    ``{"surfaces": [...]}``, trimmed or not), ``.3dm``, STEP, IGES or BREP file, as a list
    of NURBSCurve / NURBSSurface / TrimmedSurface / NURBSVolume; other NURBS files go
    through :func:`nurbskit.io.read_nurbs`. The ``report.json`` of ``nurbskit shape`` gives
    its :class:`~nurbskit.io.cad.analytic.RevolvedSurface` / ``ExtrudedSurface``.
    ``units``: STEP, IGES and ``.3dm`` coordinates are converted into it from the unit the
    file declares (see :func:`read_cad`, :func:`~nurbskit.io.cad.rhino.read_3dm_all`); the
    other files are read as they are."""
    from .._base import check_readable
    from ..nurbs import check_coordinates, read_nurbs

    path = check_readable(path)
    ext = path.suffix.lower()
    if ext in CAD_FORMATS:
        model = read_cad(path, units=units)
        found = [f if f.loops else f.surface for f in model.faces] + list(model.curves)
    elif ext == ".3dm":
        from .rhino import read_3dm_all

        found = read_3dm_all(path, units=units)
    elif ext == ".json":
        found = _read_json_objects(path)
    else:
        return [read_nurbs(path)]
    for obj in found:
        check_coordinates(obj, path)
    return found


def _indexed_files(index: Path, files: list, where: str) -> list:
    """The faces that an entry of ``nurbskit patches``' ``patches.json`` lists under
    ``files`` (paths relative to its folder, e.g. ``patches/001_1.json``); a name that
    leaves the folder is refused."""
    root = index.parent.resolve()
    out = []
    for j, name in enumerate(files):
        if not isinstance(name, str) or not name:
            raise InputError(f"{where}[files][{j}]: expected a file name, found {name!r}")
        target = (index.parent / name).resolve()
        if Path(name).is_absolute() or root not in target.parents:
            raise InputError(f"{where}[files][{j}]: {name!r} lies outside {index.parent}")
        if not target.is_file():
            raise InputError(f"{where}[files][{j}]: {index.parent / name} does not exist")
        out.extend(_read_json_objects(target, follow_index=False))  # an index of indexes is not followed
    return out


def _read_json_objects(path: Path, follow_index: bool = True) -> list:
    from ...core.serialize import from_dict
    from .._json import load_json

    data = load_json(path)  # nesting bounded, one-line errors
    if isinstance(data, dict) and "format" not in data and data.get("kind") in ("revolution", "extrusion", "freeform") \
            and "profile" in data:  # the report.json of `nurbskit shape`
        from .analytic import swept_from_report

        swept = swept_from_report(data, source=str(path))
        if swept is None:
            raise InputError(f"{path}: `nurbskit shape` chose a free-form surface; export surface.json beside it")
        return [swept]
    if isinstance(data, dict) and data.get("format") == "nurbskit" and "kind" in data:
        if data.get("trim"):
            return [TrimmedSurface.from_dict(data, source=str(path))]
        return [from_dict(data, source=str(path))]
    for key in ("patches", "surfaces"):
        if isinstance(data, dict) and isinstance(data.get(key), list):
            out = []
            for i, item in enumerate(data[key]):
                where = f"{path}[{key}][{i}]"
                if (follow_index and isinstance(item, dict) and "format" not in item
                        and isinstance(item.get("files"), list)):
                    out.extend(_indexed_files(path, item["files"], where))  # `nurbskit patches`' index
                    continue
                if isinstance(item, dict) and isinstance(item.get("surface"), dict):  # {"surface": {...}, "trim": [...]}
                    item = {**item["surface"], **({"trim": item["trim"]} if "trim" in item else {})}
                if not isinstance(item, dict):
                    raise InputError(f"{where}: expected a nurbskit surface object")
                out.append(TrimmedSurface.from_dict(item, source=where) if item.get("trim")
                           else from_dict(item, source=where))
            for i, item in enumerate(data.get("curves", []) if isinstance(data.get("curves"), list) else []):
                out.append(from_dict(item, source=f"{path}[curves][{i}]"))
            if not out:
                raise InputError(f"{path}: '{key}' is empty")
            return out
    from ..nurbs import read_nurbs

    return [read_nurbs(path)]


def objects_to_json(objects: list) -> dict:
    """nurbskit JSON for a list of objects: the object itself when there is one untrimmed
    spline, else ``{"format": "nurbskit", "surfaces": [...]}`` (trimmed ones with ``trim``)."""
    from ...core.serialize import to_dict

    if len(objects) == 1 and not isinstance(objects[0], TrimmedSurface) and not _is_mesh(objects[0]):
        return to_dict(objects[0])
    surfaces, curves = [], []
    for obj in objects:
        if isinstance(obj, TrimmedSurface):
            surfaces.append(obj.to_dict())
        elif getattr(obj, "kind", None) == "surface":
            surfaces.append(to_dict(obj))
        elif getattr(obj, "kind", None) == "curve":
            curves.append(to_dict(obj))
        else:
            raise OptionError(f"nurbskit JSON holds splines; cannot store a {type(obj).__name__}")
    data = {"format": "nurbskit", "version": 1, "surfaces": surfaces}
    if curves:
        data["curves"] = curves
    return data


def _is_mesh(obj) -> bool:
    return hasattr(obj, "vertices") and hasattr(obj, "faces")


def _as_list(obj) -> list:
    if isinstance(obj, (list, tuple)) and not (isinstance(obj, tuple) and len(obj) == 2
                                              and all(isinstance(a, np.ndarray) for a in obj)):
        return list(obj)
    return [obj]


#: OpenCASCADE's mesher refuses a chordal tolerance below Precision::Confusion(), 1e-7
#: model units ("Standard_NumericError ... invalid parameter value").
MIN_TOLERANCE = 1e-7
#: Peak memory per output triangle of a tessellated export: OpenCASCADE's mesh, the
#: arrays read from it and the writer's buffer (measured about 1.5 KB; planned as 2 KB).
BYTES_PER_TRIANGLE = 2048
#: Triangles per unit of (integrated maximum curvature / tolerance): fitted to OCC's
#: counts on the duck (1.8), a bump (0.8) and a cylinder (0.7), rounded up.
_TRIANGLES_PER_CURVATURE = 2.0


def check_tolerance(tolerance, option: str = "tolerance") -> float | None:
    """``tolerance`` as a float (None passes), or an OptionError naming ``option``:
    not a number, not finite, not positive, or below :data:`MIN_TOLERANCE`."""
    if tolerance is None:
        return None
    try:
        value = float(tolerance)
    except (TypeError, ValueError):
        raise OptionError(f"{option}: expected a number, got {tolerance!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise OptionError(f"{option} must be positive and finite (model units), got {value:g}")
    if value < MIN_TOLERANCE:
        raise OptionError(f"{option} {value:g}: OpenCASCADE's mesher works to {MIN_TOLERANCE:g} model units "
                          f"at best; give {MIN_TOLERANCE:g} or more")
    return value


def _surfaces_of(splines) -> list:
    return [s.surface if isinstance(s, TrimmedSurface) else s for s in splines]


def _integrated_curvature(surface, resolution: int = 64) -> float:
    """Integral of the larger absolute principal curvature over the surface (untrimmed),
    from the fundamental forms on a grid of ``resolution`` samples per knot span
    direction (at least 32, at most 256), midpoint rule (do Carmo 3.3)."""
    res = [int(min(max(32, 4 * (n - p)), 256)) for n, p in zip(surface.sizes, surface.degrees)]
    u, v = surface.grid_axes(res)
    with torch.no_grad():
        d = surface.detach().evaluate_grid(u, v, order=2).to(torch.float64).cpu().numpy()  # (R, S, 3, 3, dim)
    if d.shape[-1] != 3:
        return 0.0
    su, sv = d[..., 1, 0, :], d[..., 0, 1, :]
    normal = np.cross(su, sv)
    area = np.linalg.norm(normal, axis=-1)
    normal = normal / np.maximum(area, 1e-300)[..., None]
    E, F, G = (su * su).sum(-1), (su * sv).sum(-1), (sv * sv).sum(-1)
    L, M, N = ((d[..., i, j, :] * normal).sum(-1) for i, j in ((2, 0), (1, 1), (0, 2)))
    det = E * G - F * F
    with np.errstate(divide="ignore", invalid="ignore"):
        K = (L * N - M * M) / det
        H = (E * N - 2 * F * M + G * L) / (2 * det)
        kmax = np.abs(H) + np.sqrt(np.maximum(H * H - K, 0.0))
    kmax = np.where((det > 0) & np.isfinite(kmax), kmax, 0.0)  # degenerate points (poles) carry no area
    span = (float(u[-1] - u[0])) * (float(v[-1] - v[0]))
    return float(np.mean(kmax * area) * span)


def estimate_triangles(splines, tolerance: float) -> int:
    """About how many triangles OCC's mesher makes for ``splines`` at chordal ``tolerance``.

    A triangle of edge ``h`` on a surface of curvature ``k`` departs from it by about
    ``k h^2 / 8``, so the count grows as (integrated curvature) / tolerance; the constant
    is fitted to OCC's counts (within a factor of 3 on the shapes tried, above rather than
    below). Trimmed surfaces are counted untrimmed.
    """
    total = sum(_integrated_curvature(s) for s in _surfaces_of(splines))
    return int(_TRIANGLES_PER_CURVATURE * total / tolerance) + 2 * len(splines)


def check_tessellation_fits(splines, tolerance: float, option: str = "tolerance") -> int:
    """Refuse (OptionError naming ``option``) a tolerance whose mesh would not fit in memory,
    before OCC starts; returns the estimated triangle count."""
    from ..._budget import available_bytes, require_memory

    triangles = estimate_triangles(splines, tolerance)
    need = triangles * BYTES_PER_TRIANGLE
    budget = available_bytes()
    fits = tolerance * need / max(budget, 1)
    require_memory(need, f"{option} {tolerance:g} (about {triangles:,} triangles)",
                   f"a tolerance of {fits:.2g} or more fits", budget=budget)
    return triangles


#: A mesh with fewer than 1 / MESH_SHORTFALL of the triangles expected is OCC's mesher
#: failing quietly (see :func:`_meshed`); the estimate is above OCC's count by at most 3x.
MESH_SHORTFALL = 30
MESH_RETRIES = 4


def _meshed(splines, tolerance: float, expected: int) -> tuple[np.ndarray, np.ndarray]:
    """OCC's mesh of ``splines`` at ``tolerance``, made again at 0.9x the tolerance (finer
    than asked, up to :data:`MESH_RETRIES` times) when it holds under 1 / :data:`MESH_SHORTFALL`
    of the ``expected`` triangles.

    Why: OCC's mesher (Watson and Delabella alike) sometimes returns a mesh of a hundred
    triangles across a whole surface with no error status, at a tolerance where one a few
    percent finer gives thousands: on the thesis duck, at 5 of 60 tolerances between
    0.001 and 0.1 (0.0057, the default 1e-3 of its diagonal, among them: 118 triangles
    against 18,588 at 0.0055).
    """
    for attempt in range(MESH_RETRIES + 1):
        v, f = tessellate_shape(to_shape(splines, sew_tolerance=None), tolerance * 0.9 ** attempt)
        if len(f) * MESH_SHORTFALL >= expected:
            break
    return v, f


def tessellate_objects(objects: list, tolerance: float | None = None, *,
                       tolerance_option: str = "tolerance") -> tuple[np.ndarray, np.ndarray]:
    """One triangle mesh for curves-free geometry: meshes as they are; surfaces (trimmed or
    not) through OCC's mesher (``tolerance``: chordal, model units; default 1e-3 of the
    bounding-box diagonal of the control points). A tolerance that is not a positive finite
    number, or whose mesh would not fit in memory, is refused before any meshing (messages
    name ``tolerance_option``)."""
    tolerance = check_tolerance(tolerance, tolerance_option)
    meshes = [o for o in objects if _is_mesh(o) or (isinstance(o, tuple) and len(o) == 2)]
    splines = [o for o in objects if o not in meshes and (isinstance(o, TrimmedSurface)
                                                         or getattr(o, "kind", None) == "surface")]
    verts, faces, offset = [], [], 0
    for m in meshes:
        v, f = (m.vertices, m.faces) if _is_mesh(m) else m
        verts.append(np.asarray(v, dtype=np.float64))
        faces.append(np.asarray(f, dtype=np.int64) + offset)
        offset += len(v)
    if splines:
        if tolerance is None:
            tolerance = max(1e-3 * _diagonal(splines), MIN_TOLERANCE)
            tolerance_option = "the default tolerance"
        expected = check_tessellation_fits(splines, tolerance, tolerance_option)
        v, f = _meshed(splines, tolerance, expected)
        verts.append(v)
        faces.append(f + offset)
    if not verts:
        raise OptionError("nothing to tessellate: no surfaces or meshes (curves have no triangles)")
    return np.vstack(verts), np.vstack(faces)


def _diagonal(splines) -> float:
    pts = np.vstack([(s.surface if isinstance(s, TrimmedSurface) else s).control_points.detach().cpu().double()
                     .numpy().reshape(-1, 3) for s in splines])
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))) or 1.0


RESULT_FORMATS = ("step", "iges", "brep", "3dm", "json", "obj", "ply", "stl", "gltf", "glb", "off")


def result_format(path: str | os.PathLike, format: str | None = None) -> str:
    """The output format for ``path``: ``format`` if given, else by extension."""
    if format is not None:
        name = format.lower().lstrip(".")
        name = {"stp": "step", "igs": "iges", "brp": "brep"}.get(name, name)
        if name not in RESULT_FORMATS:
            raise OptionError(f"--format must be one of {', '.join(RESULT_FORMATS)}, got {format!r}")
        return name
    ext = Path(path).suffix.lower()
    name = CAD_FORMATS.get(ext) or MESH_FORMATS.get(ext) or {".3dm": "3dm", ".json": "json"}.get(ext)
    if name is None:
        raise OptionError(f"{path}: unknown output type {ext or '(no extension)'!r}; expected one of "
                          ".step .stp .iges .igs .brep .3dm .json .obj .ply .stl .gltf .glb .off")
    return name


def write_result(obj, path: str | os.PathLike, format: str | None = None, tolerance: float | None = None,
                 *, check: bool = True, analytic: bool = True, tolerance_option: str = "tolerance",
                 units: str = "mm", units_option: str = "units") -> dict:
    """Write a result (surface, trimmed surface, curve, patch list or mesh) in any format.

    CAD formats (step, iges, brep) go through :func:`write_cad` (read back and checked;
    ``analytic``: swept surfaces as analytic entities, see there); the other formats get a
    swept surface's exact NURBS;
    ``3dm`` through rhino3dm (trimming loops are not stored there: reported in
    ``left_out``); ``json`` as nurbskit JSON; mesh formats (obj, ply, stl, gltf/glb,
    off) tessellate surfaces with OCC's mesher to ``tolerance`` (chordal, model units;
    default 1e-3 of the bounding-box diagonal) and are written by trimesh; a tolerance
    whose mesh would not fit in memory is refused first (messages name ``tolerance_option``).
    ``units``: the unit of the coordinates, declared by STEP, IGES and ``.3dm`` files (the
    numbers written unchanged; see :data:`UNITS`; messages name ``units_option``); BREP,
    JSON and the mesh formats hold no unit.

    Returns:
        A report: ``format``, ``path``, and per format the check report (CAD), the
        triangle counts (meshes) or ``left_out``.
    """
    from .analytic import is_swept

    path = Path(path)
    fmt = result_format(path, format)
    check_tolerance(tolerance, tolerance_option)
    check_units(units, units_option)
    objects = _as_list(obj)
    if fmt not in ("step", "iges", "brep"):  # only OCC's formats have swept surfaces: the rest get the NURBS
        objects = [o.to_nurbs() if is_swept(o) else o for o in objects]
    if fmt in ("step", "iges", "brep"):
        report = write_cad(objects if len(objects) > 1 else objects[0], path, format=fmt, check=check,
                           analytic=analytic, units=units)
    elif fmt == "3dm":
        from .rhino import write_3dm_objects

        report = {"format": "3dm", "left_out": write_3dm_objects(path, objects, units=units)}
    elif fmt == "json":
        from ..._fs import atomic_open

        with atomic_open(path, "w") as handle:
            json.dump(objects_to_json(objects), handle)
        report = {"format": "json"}
    else:
        vertices, faces = tessellate_objects(objects, tolerance, tolerance_option=tolerance_option)
        report = {"format": fmt, **write_triangles(vertices, faces, path, fmt)}
    report["path"] = str(path)
    return report


def write_triangles(vertices: np.ndarray, faces: np.ndarray, path: Path, fmt: str) -> dict:
    """Write a triangle mesh with trimesh (OBJ, PLY, STL, glTF/GLB, OFF), atomically."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    file_type = {"gltf": "glb" if path.suffix.lower() == ".glb" else "gltf"}.get(fmt, fmt)
    if file_type == "gltf":
        # a .gltf file is JSON with its buffers embedded (one file, no side .bin)
        data = trimesh.Scene(mesh).export(file_type="gltf", embed_buffers=True)
        payload = data["model.gltf"] if isinstance(data, dict) else data
    else:
        payload = mesh.export(file_type=file_type)
    if isinstance(payload, str):
        payload = payload.encode()
    with atomic_path(path) as tmp:
        tmp.write_bytes(payload)
    return {"vertices": int(len(vertices)), "triangles": int(len(faces))}


__all__ = ["write_cad", "write_shape", "read_cad", "read_shape", "cad_info", "format_cad_info", "cad_format", "read_objects",
           "objects_to_json", "write_result", "result_format", "tessellate_objects", "write_triangles",
           "check_tolerance", "estimate_triangles", "check_tessellation_fits", "MIN_TOLERANCE",
           "CAD_FORMATS", "RESULT_FORMATS", "UNITS", "check_units"]
