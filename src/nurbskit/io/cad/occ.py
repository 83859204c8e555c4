"""nurbskit splines to and from OpenCASCADE geometry (``Geom_BSplineCurve``,
``Geom_BSplineSurface``), exactly.

Convention:
    nurbskit holds every B-spline in its *unwrapped* form: ``n`` control points, a flat
    knot vector of ``n + p + 1`` knots, the domain ``[t_p, t_n]``. OpenCASCADE stores
    distinct knots with multiplicities, and a periodic B-spline with only its ``n - p``
    distinct poles. The conversion is exact both ways: distinct knots and multiplicities
    are read off the flat vector (no arithmetic on knot values), and a periodic OCC
    spline is unwrapped with OCC's own ``SetNotPeriodic`` (which appends the first ``p``
    poles again and keeps the flat knots, checked in tests/test_io_cad.py). A nurbskit
    spline whose knots are periodic (the ``p`` knots at each end are the knots one period
    ``T = t_n - t_p`` away, ``t[i] = t[i + n - p] - T``, as OCC computes them, to a few
    units in the last place of the spline's dtype) and
    whose last ``p`` control points and weights repeat the first ``p`` is written as a
    periodic OCC spline with ``periodic="auto"`` (the default); otherwise as the plain
    (unclamped) spline, which is the same geometry.

    Coordinates are written as they are (the unit a file declares is the writer's
    ``units``, :data:`nurbskit.io.cad.exchange.UNITS`); 2-D control points get ``z = 0``. Parameter domains are never rescaled,
    so a surface read back evaluates at the same (u, v) to the same point.

OCP (``cadquery-ocp-novtk``, the ``[cad]`` extra) is imported on first use.
"""

from __future__ import annotations

import numpy as np
import torch

from ..._optional import require
from ...core.curve import NURBSCurve
from ...core.surface import NURBSSurface
from ...errors import NurbskitError, OptionError


def ocp():
    """The OCP package, or a NurbskitError naming the ``[cad]`` extra."""
    return require("OCP", "cad", "STEP, IGES and BREP files (OpenCASCADE)")


# ---- small array helpers -------------------------------------------------------------

def _array1(values, kind: str):
    ocp()
    from OCP.collections import Array1_double, Array1_int

    cls = Array1_int if kind == "int" else Array1_double
    values = np.asarray(values, dtype=np.int64 if kind == "int" else np.float64).tolist()  # Python ints / floats
    arr = cls(1, len(values))
    set_value = arr.SetValue  # one attribute lookup, not one per element (this loop is hot)
    for i, v in enumerate(values, 1):
        set_value(i, v)
    return arr


def knots_and_multiplicities(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct knots ``(K,)`` and multiplicities ``(K,)`` of a flat knot vector (exact)."""
    flat = np.asarray(flat, dtype=np.float64)
    starts = np.concatenate([[True], flat[1:] != flat[:-1]])
    values = flat[starts]
    counts = np.diff(np.concatenate([np.flatnonzero(starts), [flat.size]]))
    return values, counts


def _periodic_form(flat: np.ndarray, degree: int, points: np.ndarray, weights: np.ndarray, axis: int,
                   eps: float = 0.0):
    """For an unwrapped periodic spline along ``axis``: (distinct knots, multiplicities) of
    OCC's periodic form, or None when the spline is not periodic.

    ``eps``: the machine epsilon of the spline's own dtype. The knots beyond the domain
    may differ from the ones OCC derives by ``4 eps`` of the largest knot (the rounding of
    ``(i - p) / s`` against ``(i - p + s) / s - 1``, or of a float32 spline's knots
    wrapped in float64): OCC's replace them, a change below the spline's own precision."""
    n = points.shape[axis]
    p = degree
    m = n - p  # distinct poles
    if p < 1 or m < 2:
        return None
    t = np.asarray(flat, dtype=np.float64)
    period = t[n] - t[p]
    if not period > 0:
        return None
    # the knots OCC derives for a periodic spline (each wrapped knot one period away, in
    # floating point); bit-equal for the core's periodic_knots in float64, so that the
    # spline read back has the same flat knots
    tol = 4.0 * eps * float(np.abs(t).max())
    if not (np.allclose(t[:p], t[m:m + p] - period, rtol=0, atol=tol)
            and np.allclose(t[n + 1:], t[p + 1:2 * p + 1] + period, rtol=0, atol=tol)):
        return None
    take = lambda a, idx: np.take(a, idx, axis=axis)  # noqa: E731
    if not (np.array_equal(take(points, np.arange(m, n)), take(points, np.arange(p)))
            and np.array_equal(take(weights, np.arange(m, n)), take(weights, np.arange(p)))):
        return None
    inside = t[p:n + 1]
    values, counts = knots_and_multiplicities(inside)
    # multiplicities count every copy in the flat vector, also those outside [t_p, t_n]
    mult = np.array([int(np.sum(t == v)) for v in values])
    if mult[0] != mult[-1] or mult[0] > p or int(mult[:-1].sum()) != m:
        return None
    return values, mult


def is_periodic(spline, axis: int = 0) -> bool:
    """Whether ``spline`` (a curve or surface) is written as periodic along ``axis``."""
    cp = spline.control_points.detach().cpu().double().numpy()
    w = spline.weights.detach().cpu().double().numpy()
    flat = spline.knot_vectors[axis].detach().cpu().double().numpy()
    return _periodic_form(flat, spline.degrees[axis], cp, w, axis, _eps(spline)) is not None


def _eps(spline) -> float:
    """The machine epsilon of a spline's dtype (how far its periodic knots may be from OCC's)."""
    return float(torch.finfo(spline.control_points.dtype).eps)


def _xyz(cp: np.ndarray) -> np.ndarray:
    if cp.shape[-1] == 3:
        return cp
    if cp.shape[-1] == 2:
        return np.concatenate([cp, np.zeros(cp.shape[:-1] + (1,))], axis=-1)
    raise OptionError(f"CAD files hold 2-D or 3-D geometry; got {cp.shape[-1]}-D control points")


def _axis_form(flat, degree, cp, w, axis, periodic, eps: float = 0.0):
    form = _periodic_form(flat, degree, cp, w, axis, eps) if periodic in ("auto", True) else None
    if periodic is True and form is None:
        raise OptionError(f"periodic=True, but the knots or control points along axis {axis} are not periodic")
    if form is None:
        values, mult = knots_and_multiplicities(flat)
        return values, mult, False, cp.shape[axis]
    return form[0], form[1], True, cp.shape[axis] - degree


# ---- curves ----------------------------------------------------------------------------

def curve_to_occ(curve: NURBSCurve, periodic: bool | str = "auto"):
    """A ``Geom_BSplineCurve`` equal to ``curve`` (3-D; 2-D curves at z = 0)."""
    ocp()
    curve.require_single("an OpenCASCADE curve")
    from OCP.collections import Array1_gp_Pnt
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt

    cp = _xyz(curve.control_points.detach().cpu().double().numpy())
    w = curve.weights.detach().cpu().double().numpy()
    flat = curve.knot_vectors[0].detach().cpu().double().numpy()
    p = curve.degrees[0]
    values, mult, closed, count = _axis_form(flat, p, cp, w, 0, periodic, _eps(curve))
    poles = Array1_gp_Pnt(1, count)
    set_pole = poles.SetValue
    for i, xyz in enumerate(cp[:count].tolist(), 1):
        set_pole(i, gp_Pnt(*xyz))
    try:
        if curve.is_rational:
            return Geom_BSplineCurve(poles, _array1(w[:count], "float"), _array1(values, "float"),
                                     _array1(mult, "int"), p, closed)
        return Geom_BSplineCurve(poles, _array1(values, "float"), _array1(mult, "int"), p, closed)
    except Exception as exc:  # Standard_ConstructionError: OCC's own words
        raise NurbskitError(f"OpenCASCADE rejects this curve ({type(exc).__name__}: {exc})") from None


def _unwrapped(geom):
    """A non-periodic copy of a periodic B-spline (OCC's SetNotPeriodic: exact)."""
    if hasattr(geom, "IsUPeriodic"):
        if geom.IsUPeriodic() or geom.IsVPeriodic():
            geom = geom.Copy()
            if geom.IsUPeriodic():
                geom.SetUNotPeriodic()
            if geom.IsVPeriodic():
                geom.SetVNotPeriodic()
        return geom
    if geom.IsPeriodic():
        geom = geom.Copy()
        geom.SetNotPeriodic()
    return geom


def _flat(seq) -> np.ndarray:
    return np.array([seq.Value(i) for i in range(seq.Lower(), seq.Upper() + 1)], dtype=np.float64)


def curve_from_occ(geom, dtype=torch.float64) -> NURBSCurve:
    """A NURBSCurve equal to a ``Geom_BSplineCurve`` (periodic curves unwrapped)."""
    geom = _unwrapped(geom)
    n = geom.NbPoles()
    cp = np.empty((n, 3))
    for i in range(n):
        pt = geom.Pole(i + 1)
        cp[i] = (pt.X(), pt.Y(), pt.Z())
    w = np.array([geom.Weight(i + 1) for i in range(n)]) if geom.IsRational() else np.ones(n)
    t = lambda a: torch.as_tensor(a, dtype=dtype)  # noqa: E731
    return NURBSCurve(t(cp), geom.Degree(), t(_flat(geom.KnotSequence())), t(w))


# ---- surfaces --------------------------------------------------------------------------

def surface_to_occ(surface: NURBSSurface, periodic: bool | str = "auto"):
    """A ``Geom_BSplineSurface`` equal to ``surface`` (u is OCC's U, v its V)."""
    surface.require_single("an OpenCASCADE face")
    ocp()
    from OCP.collections import Array2_double, Array2_gp_Pnt
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt

    if surface.kind != "surface":
        raise OptionError(f"expected a surface, got a {surface.kind}")
    cp = _xyz(surface.control_points.detach().cpu().double().numpy())
    w = surface.weights.detach().cpu().double().numpy()
    (p, q) = surface.degrees
    fu, fv = (kv.detach().cpu().double().numpy() for kv in surface.knot_vectors)
    eps = _eps(surface)
    uk, um, uper, nu = _axis_form(fu, p, cp, w, 0, periodic, eps)
    vk, vm, vper, nv = _axis_form(fv, q, cp, w, 1, periodic, eps)
    poles = Array2_gp_Pnt(1, nu, 1, nv)
    set_pole = poles.SetValue
    for i, row in enumerate(cp[:nu, :nv].tolist(), 1):
        for j, xyz in enumerate(row, 1):
            set_pole(i, j, gp_Pnt(*xyz))
    args = [_array1(uk, "float"), _array1(vk, "float"), _array1(um, "int"), _array1(vm, "int"), p, q, uper, vper]
    try:
        if surface.is_rational:
            weights = Array2_double(1, nu, 1, nv)
            set_weight = weights.SetValue
            for i, row in enumerate(w[:nu, :nv].tolist(), 1):
                for j, wij in enumerate(row, 1):
                    set_weight(i, j, wij)
            return Geom_BSplineSurface(poles, weights, *args)
        return Geom_BSplineSurface(poles, *args)
    except Exception as exc:
        raise NurbskitError(f"OpenCASCADE rejects this surface ({type(exc).__name__}: {exc})") from None


def surface_from_occ(geom, dtype=torch.float64) -> NURBSSurface:
    """A NURBSSurface equal to a ``Geom_BSplineSurface`` (periodic directions unwrapped)."""
    geom = _unwrapped(geom)
    nu, nv = geom.NbUPoles(), geom.NbVPoles()
    cp = np.empty((nu, nv, 3))
    w = np.ones((nu, nv))
    rational = geom.IsURational() or geom.IsVRational()
    for i in range(nu):
        for j in range(nv):
            pt = geom.Pole(i + 1, j + 1)
            cp[i, j] = (pt.X(), pt.Y(), pt.Z())
            if rational:
                w[i, j] = geom.Weight(i + 1, j + 1)
    t = lambda a: torch.as_tensor(a, dtype=dtype)  # noqa: E731
    return NURBSSurface(t(cp), (geom.UDegree(), geom.VDegree()),
                        [t(_flat(geom.UKnotSequence())), t(_flat(geom.VKnotSequence()))], t(w))


def as_bspline_surface(geom):
    """``geom`` as a ``Geom_BSplineSurface`` when it is one (possibly inside a rectangular
    trim or an offset of zero), else None."""
    ocp()
    from OCP.Geom import Geom_BSplineSurface, Geom_RectangularTrimmedSurface

    if isinstance(geom, Geom_RectangularTrimmedSurface):
        geom = geom.BasisSurface()
    return geom if isinstance(geom, Geom_BSplineSurface) else None


__all__ = ["ocp", "curve_to_occ", "curve_from_occ", "surface_to_occ", "surface_from_occ", "is_periodic",
           "knots_and_multiplicities", "as_bspline_surface"]
