"""Rhino ``.3dm`` files through rhino3dm (optional extra ``nurbskit[cad]``): NURBS curves and
surfaces, read and written.

openNURBS differs from The NURBS Book in two ways, handled here: its knot vectors
omit the first and last knot (``n + p - 1`` knots, not ``n + p + 1``), and its
``Point4d`` control points are homogeneous (``x*w, y*w, z*w, w``).

Units: a file is written with the numbers as they are and declares ``units`` (the unit of
nurbskit's coordinates, default millimetres; see :data:`nurbskit.io.cad.exchange.UNITS`)
as its model unit system. Reading takes the numbers as they are, or, given ``units``
(:func:`read_3dm_all`, what ``nurbskit export`` reads), converts them from the unit the
file declares.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from ..._fs import atomic_path
from ..._optional import require
from ...core.curve import NURBSCurve
from ...core.spline import TensorSpline
from ...core.surface import NURBSSurface
from ...errors import OptionError
from .._base import InputError
from .exchange import UNITS, check_units


def _rhino():
    return require("rhino3dm", "cad", "reading and writing .3dm files")


def _full_knots(knots) -> np.ndarray:
    k = np.array([knots[i] for i in range(len(knots))], dtype=np.float64)
    return np.concatenate([[k[0]], k, [k[-1]]])


def _geometry_of(obj):
    geo = obj.Geometry
    rh = _rhino()
    if isinstance(geo, rh.NurbsCurve) or isinstance(geo, rh.NurbsSurface):
        return geo
    if isinstance(geo, rh.Curve):
        return geo.ToNurbsCurve()
    if isinstance(geo, rh.Surface):
        return geo.ToNurbsSurface()
    if isinstance(geo, rh.Brep) and geo.IsSurface:  # one face, untrimmed
        return geo.Faces[0].ToNurbsSurface()
    return None


def _read_model(path: Path):
    """The rhino3dm model of ``path`` and its NURBS curves and surfaces, in order. Breps that
    are not one untrimmed surface (trimmed faces, polysurfaces) are refused: read without
    their trims they would be other shapes (a trimmed disk read as its square)."""
    rh = _rhino()
    model = rh.File3dm.Read(str(path))
    if model is None:
        raise InputError(f"{path}: rhino3dm could not read it as a .3dm file")
    breps = sum(1 for o in model.Objects if isinstance(o.Geometry, rh.Brep) and not o.Geometry.IsSurface)
    if breps:
        raise InputError(f"{path}: holds {breps} trimmed or multi-face Brep(s) (polysurfaces), which nurbskit "
                         "does not read from .3dm; save them as STEP or IGES, read with their trims")
    found = [g for g in (_geometry_of(o) for o in model.Objects) if g is not None]
    if not found:
        raise InputError(f"{path}: holds no NURBS curve or surface")
    return found, RHINO_MM_PER_UNIT.get(str(model.Settings.ModelUnitSystem).split(".")[-1])


#: Millimetres per unit of the rhino3dm ``UnitSystem`` members a file may declare (the
#: others, ``None``, ``Unset``, custom units, astronomical ones: numbers read as they are).
RHINO_MM_PER_UNIT = {"Microns": 1e-3, "Millimeters": 1.0, "Centimeters": 10.0, "Decimeters": 100.0,
                     "Meters": 1000.0, "Kilometers": 1e6, "Inches": 25.4, "Feet": 304.8, "Yards": 914.4,
                     "Miles": 1_609_344.0, "Mils": 0.0254, "Microinches": 2.54e-5}


def read_3dm(path: str | os.PathLike, index: int = 0) -> TensorSpline:
    """The ``index``-th NURBS curve or surface of a ``.3dm`` file (meshes, points and other
    objects are skipped; a Brep counts when it is one untrimmed surface, and any other Brep
    is refused)."""
    path = Path(path)
    found, _ = _read_model(path)
    if not -len(found) <= index < len(found):
        raise OptionError(f"{path}: index {index} is out of range; the file holds {len(found)} curves/surfaces")
    return _spline_of(found[index])


def _spline_of(geo) -> TensorSpline:
    """The nurbskit curve or surface of an openNURBS ``NurbsCurve`` / ``NurbsSurface``."""
    rh = _rhino()
    t = lambda a: torch.as_tensor(np.asarray(a, dtype=np.float64))  # noqa: E731
    if isinstance(geo, rh.NurbsCurve):
        n = len(geo.Points)
        cpw = np.array([[geo.Points[i].X, geo.Points[i].Y, geo.Points[i].Z, geo.Points[i].W] for i in range(n)])
        w = cpw[:, 3] if geo.IsRational else np.ones(n)
        cp = cpw[:, :3] / w[:, None] if geo.IsRational else cpw[:, :3]
        return NURBSCurve(t(cp), geo.Degree, t(_full_knots(geo.Knots)), t(w))
    nu, nv = geo.Points.CountU, geo.Points.CountV
    cpw = np.zeros((nu, nv, 4))
    for i in range(nu):
        for j in range(nv):
            p = geo.Points.GetPoint(i, j) if not geo.IsRational else geo.Points.GetControlPoint(i, j)
            if geo.IsRational:
                cpw[i, j] = (p.X, p.Y, p.Z, p.W)
            else:
                cpw[i, j] = (p.X, p.Y, p.Z, 1.0)
    w = cpw[..., 3]
    cp = cpw[..., :3] / w[..., None] if geo.IsRational else cpw[..., :3]
    return NURBSSurface(t(cp), (geo.OrderU - 1, geo.OrderV - 1),
                        [t(_full_knots(geo.KnotsU)), t(_full_knots(geo.KnotsV))], t(w))


def _new_model(units: str):
    """An empty rhino3dm model whose model unit system is ``units``."""
    rh = _rhino()
    model = rh.File3dm()
    model.Settings.ModelUnitSystem = getattr(rh.UnitSystem, UNITS[units][3])
    return model


def write_3dm(path: str | os.PathLike, obj: TensorSpline, *, units: str = "mm") -> None:
    """Write one curve or surface (in 2-D or 3-D) to a ``.3dm`` file, atomically; the file
    declares ``units`` (the coordinates' unit, written unchanged)."""
    check_units(units)
    path = Path(path)
    model = _new_model(units)
    geo = _geometry(path, obj)
    if obj.kind == "curve":
        model.Objects.AddCurve(geo)
    else:
        model.Objects.AddSurface(geo)
    with atomic_path(path) as tmp:
        if not model.Write(str(tmp), 7):
            raise OSError(f"rhino3dm could not write {path}")


def _geometry(path: Path, obj: TensorSpline):
    """An openNURBS curve or surface equal to ``obj`` (checked valid by rhino3dm)."""
    rh = _rhino()
    if obj.kind not in ("curve", "surface"):
        raise OptionError(f"{path}: .3dm holds curves and surfaces; got a {obj.kind}")
    obj.require_single(f"writing {path.name} (3dm)")
    if obj.dim not in (2, 3):
        raise OptionError(f"{path}: .3dm control points are 2-D or 3-D; got {obj.dim}-D")
    cp = obj.control_points.detach().cpu().double().numpy()
    if obj.dim == 2:
        cp = np.concatenate([cp, np.zeros(cp.shape[:-1] + (1,))], axis=-1)
    w = obj.weights.detach().cpu().double().numpy()
    kvs = [kv.detach().cpu().double().numpy() for kv in obj.knot_vectors]
    rational = bool(obj.is_rational) or not np.allclose(w, 1.0, rtol=0, atol=0)
    if obj.kind == "curve":
        n, p = obj.sizes[0], obj.degrees[0]
        geo = rh.NurbsCurve(3, rational, p + 1, n)
        for i in range(n):
            x, y, z = cp[i] * w[i]
            geo.Points[i] = rh.Point4d(x, y, z, w[i]) if rational else rh.Point4d(*cp[i], 1.0)
        for i, k in enumerate(kvs[0][1:-1]):
            geo.Knots[i] = float(k)
    else:
        (nu, nv), (p, q) = obj.sizes, obj.degrees
        geo = rh.NurbsSurface.Create(3, rational, p + 1, q + 1, nu, nv)
        for i in range(nu):
            for j in range(nv):
                x, y, z = cp[i, j] * w[i, j] if rational else cp[i, j]
                geo.Points[(i, j)] = rh.Point4d(x, y, z, w[i, j] if rational else 1.0)
        for i, k in enumerate(kvs[0][1:-1]):
            geo.KnotsU[i] = float(k)
        for i, k in enumerate(kvs[1][1:-1]):
            geo.KnotsV[i] = float(k)
    if not geo.IsValid:
        raise OptionError(f"{path}: rhino3dm rejects this {obj.kind} as invalid (check knots and weights)")
    return geo


def read_3dm_all(path: str | os.PathLike, *, units: str | None = None) -> list[TensorSpline]:
    """Every NURBS curve and surface of a ``.3dm`` file, in the file's order.

    ``units`` (a key of :data:`~nurbskit.io.cad.exchange.UNITS`): control points converted
    from the unit the file declares into it, as STEP and IGES inputs are
    (:data:`RHINO_MM_PER_UNIT`; a file declaring no such unit is read as it is); None
    (the default): the numbers as they are."""
    found, file_mm = _read_model(Path(path))  # the file read once
    splines = [_spline_of(geo) for geo in found]
    if units is None or file_mm is None or file_mm == UNITS[check_units(units)][2]:
        return splines
    scale = file_mm / UNITS[units][2]
    return [s._replace(control_points=s.control_points * scale) for s in splines]


def write_3dm_objects(path: str | os.PathLike, objects, *, units: str = "mm") -> list[str]:
    """Write several curves and surfaces (trimmed surfaces: their surface) to one ``.3dm``
    file, atomically, declaring ``units`` (the coordinates' unit, written unchanged).
    Returns what the file cannot hold (``['trimming loops']`` when a trimmed surface was
    given: rhino3dm offers no way to build trimmed faces)."""
    from ...core.trim import TrimmedSurface

    check_units(units)
    path = Path(path)
    model = _new_model(units)
    left_out = []
    for obj in objects:
        if isinstance(obj, TrimmedSurface):
            if obj.loops and "trimming loops" not in left_out:
                left_out.append("trimming loops")
            obj = obj.surface
        if not isinstance(obj, TensorSpline):
            raise OptionError(f"{path}: .3dm holds curves and surfaces; got a {type(obj).__name__}")
        geo = _geometry(path, obj)
        (model.Objects.AddCurve if obj.kind == "curve" else model.Objects.AddSurface)(geo)
    with atomic_path(path) as tmp:
        if not model.Write(str(tmp), 7):
            raise OSError(f"rhino3dm could not write {path}")
    return left_out
