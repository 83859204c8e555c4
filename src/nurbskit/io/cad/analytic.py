"""Surfaces of revolution and extrusion as OpenCASCADE's swept surfaces, so that STEP
files carry ``SURFACE_OF_REVOLUTION`` / ``SURFACE_OF_LINEAR_EXTRUSION`` (IGES: entities
120 and 122) with the exact B-spline profile as their swept curve.

A nurbskit surface is always a NURBS; what makes it "a revolution of profile P about axis
A by angle t" is how it was made, so that is carried explicitly: a
:class:`RevolvedSurface` or :class:`ExtrudedSurface` holds the profile and the sweep,
``to_nurbs()`` gives the exact NURBS (:func:`nurbskit.core.construct.revolve` /
``extrude``), and :func:`~nurbskit.io.cad.write_cad` writes the analytic entity (or, with
``analytic=False``, the NURBS). :func:`swept_from_report` builds one from the
``report.json`` of ``nurbskit shape`` (``kind``, ``axis``, ``profile`` with its plane's
frame, ``angle`` / ``extent``), which is what ``nurbskit export SHAPE_DIR/report.json
out.step`` uses.

Convention:
    Parameters differ from nurbskit's and are not carried over (a swept surface is
    written as the analytic surface, not as the NURBS): OCC's surface of revolution has
    ``U`` the angle in radians, ``[0, angle]``, counter-clockwise about the axis
    direction starting at the profile, and ``V`` the profile's parameter; the extrusion
    has ``U`` the profile's parameter and ``V`` the distance along the unit direction,
    ``[0, length]`` (``[length, 0]`` for a negative length). nurbskit's ``revolve`` has
    ``u`` in ``[0, 1]`` along rational quadratic arcs (not proportional to the angle) and
    ``v`` the profile's parameter; ``extrude`` has ``u`` in ``[0, 1]`` along the sweep.
    The point sets are the same (tested to 1e-9 of the diagonal through STEP).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ...core.curve import NURBSCurve
from ...errors import InputError, NurbskitError, OptionError
from .occ import curve_to_occ, ocp


def _vec3(value, what: str) -> tuple[float, float, float]:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise OptionError(f"{what} must be 3 finite numbers, got {value!r}")
    return tuple(float(x) for x in v)


def _profile_3d(profile: NURBSCurve, what: str) -> NURBSCurve:
    if getattr(profile, "kind", None) != "curve" or profile.dim != 3:
        raise OptionError(f"{what}: the profile must be a 3-D NURBSCurve")
    return profile


@dataclass
class RevolvedSurface:
    """``profile`` (a 3-D NURBSCurve) turned about the axis through ``axis_point`` along
    ``axis_direction`` by ``angle`` radians (``0 < angle <= 2 pi``, counter-clockwise
    about the direction)."""

    profile: NURBSCurve
    axis_point: tuple
    axis_direction: tuple
    angle: float = 2 * math.pi

    kind = "revolution"

    def __post_init__(self):
        _profile_3d(self.profile, "RevolvedSurface")
        self.axis_point = _vec3(self.axis_point, "axis_point")
        self.axis_direction = _vec3(self.axis_direction, "axis_direction")
        if not np.linalg.norm(self.axis_direction) > 0:
            raise OptionError("axis_direction must not be zero")
        self.angle = float(self.angle)
        if not 0 < self.angle <= 2 * math.pi + 1e-12:
            raise OptionError(f"the angle of a revolution must be in (0, 2 pi], got {self.angle}")
        self.angle = min(self.angle, 2 * math.pi)

    def to_nurbs(self):
        """The exact NURBS (:func:`nurbskit.core.construct.revolve`)."""
        from ...core.construct import revolve

        return revolve(self.profile, list(self.axis_point), list(self.axis_direction), self.angle)

    def to_occ(self):
        """``Geom_SurfaceOfRevolution`` with the profile's ``Geom_BSplineCurve`` as basis curve."""
        ocp()
        from OCP.Geom import Geom_SurfaceOfRevolution
        from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt

        return Geom_SurfaceOfRevolution(curve_to_occ(self.profile, periodic=False),
                                        gp_Ax1(gp_Pnt(*self.axis_point), gp_Dir(*self.axis_direction)))

    def bounds(self) -> tuple[float, float, float, float]:
        """``(u0, u1, v0, v1)`` of the face on :meth:`to_occ` (see Convention)."""
        (v0, v1), = self.profile.domain
        return 0.0, self.angle, float(v0), float(v1)


@dataclass
class ExtrudedSurface:
    """``profile`` (a 3-D NURBSCurve) swept along ``direction`` (normalised) over the signed
    distance ``length``."""

    profile: NURBSCurve
    direction: tuple
    length: float

    kind = "extrusion"

    def __post_init__(self):
        _profile_3d(self.profile, "ExtrudedSurface")
        self.direction = _vec3(self.direction, "direction")
        if not np.linalg.norm(self.direction) > 0:
            raise OptionError("the extrusion direction must not be zero")
        self.length = float(self.length)
        if not (math.isfinite(self.length) and self.length != 0):
            raise OptionError(f"the extrusion length must be finite and non-zero, got {self.length}")

    def to_nurbs(self):
        """The exact NURBS (:func:`nurbskit.core.construct.extrude`)."""
        from ...core.construct import extrude

        return extrude(self.profile, list(self.direction), self.length)

    def to_occ(self):
        """``Geom_SurfaceOfLinearExtrusion`` of the profile's ``Geom_BSplineCurve``."""
        ocp()
        from OCP.Geom import Geom_SurfaceOfLinearExtrusion
        from OCP.gp import gp_Dir

        return Geom_SurfaceOfLinearExtrusion(curve_to_occ(self.profile, periodic=False), gp_Dir(*self.direction))

    def bounds(self) -> tuple[float, float, float, float]:
        (u0, u1), = self.profile.domain
        return float(u0), float(u1), min(0.0, self.length), max(0.0, self.length)


SWEPT_TYPES = (RevolvedSurface, ExtrudedSurface)


def is_swept(obj) -> bool:
    return isinstance(obj, SWEPT_TYPES)


def swept_face(obj, tolerance: float):
    """A ``TopoDS_Face`` on the analytic surface of ``obj`` over :meth:`bounds` (OCC adds
    the seam of a full turn and degenerate edges where the profile touches the axis)."""
    ocp()
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    maker = BRepBuilderAPI_MakeFace(obj.to_occ(), *obj.bounds(), tolerance)
    if not maker.IsDone():
        raise NurbskitError(f"OpenCASCADE could not make a face on this surface of {obj.kind} (error {maker.Error()})")
    return maker.Face()


def swept_from_report(report, source: str = "report.json"):
    """The :class:`RevolvedSurface` / :class:`ExtrudedSurface` that ``nurbskit shape`` fitted,
    from its ``report.json`` (a path or the loaded dict); None for a free-form result.

    The report's profile lives in a plane: ``(r, z)`` control points about the axis with
    ``frame`` {origin, radial, axial} for a revolution (3-D point ``origin + r radial + z
    axial``), ``(x, y)`` with {origin, x, y} for an extrusion (``origin + x X + y Y``,
    swept over ``extent`` [t0, t1] along the direction), exactly as
    :mod:`nurbskit.shapes.fit` builds its surface.
    """
    if isinstance(report, (str, Path)):
        path = Path(report)
        source = str(path)
        try:
            report = json.loads(path.read_bytes())
        except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: cannot read it as JSON ({getattr(exc, 'msg', exc)})") from None
    if not isinstance(report, dict):
        raise InputError(f"{source}: expected the JSON object of `nurbskit shape`'s report")
    kind = report.get("kind")
    if kind not in ("revolution", "extrusion"):
        if kind == "freeform":
            return None
        raise InputError(f"{source}: 'kind' must be revolution, extrusion or freeform, got {kind!r}")
    try:
        prof, frame, axis = report["profile"], report["profile"]["frame"], report["axis"]
        cp2 = torch.tensor(prof["control_points"], dtype=torch.float64)
        weights = torch.tensor(prof["weights"], dtype=torch.float64)
        knots = torch.tensor(prof["knot_vector"], dtype=torch.float64)
        degree = int(prof["degree"])
        origin = torch.tensor(frame["origin"], dtype=torch.float64)
        if kind == "revolution":
            e1, e2 = (torch.tensor(frame[k], dtype=torch.float64) for k in ("radial", "axial"))
        else:
            e1, e2 = (torch.tensor(frame[k], dtype=torch.float64) for k in ("x", "y"))
        direction = axis["direction"]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{source}: not a complete `nurbskit shape` report (missing or bad {exc})") from None
    if cp2.ndim != 2 or cp2.shape[1] != 2:
        raise InputError(f"{source}: profile control points must be (n, 2), got {tuple(cp2.shape)}")
    if kind == "revolution":
        cp = origin + cp2[:, :1] * e1 + cp2[:, 1:2] * e2
        profile = NURBSCurve(cp, degree=degree, knot_vector=knots, weights=weights)
        return RevolvedSurface(profile, axis["point"], direction, report.get("angle", 2 * math.pi))
    d = torch.tensor(direction, dtype=torch.float64)
    d = d / d.norm()
    try:
        t0, t1 = (float(x) for x in report["extent"])
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{source}: an extrusion report needs 'extent' [t0, t1]") from None
    cp = origin + cp2[:, :1] * e1 + cp2[:, 1:2] * e2 + t0 * d
    profile = NURBSCurve(cp, degree=degree, knot_vector=knots, weights=weights)
    return ExtrudedSurface(profile, d.tolist(), t1 - t0)


__all__ = ["RevolvedSurface", "ExtrudedSurface", "swept_from_report", "swept_face", "is_swept", "SWEPT_TYPES"]
