"""Exact constructors: surfaces of revolution and extrusions from a profile curve.

Both are exact in NURBS form (no approximation), and differentiable: every output tensor
is built from the profile's control points, weights and the axis by torch operations,
so gradients reach all of them (the shape fitter refines profile and axis this way).

* :func:`revolve`: The NURBS Book (Piegl & Tiller, 2nd ed.), algorithm A7.1. Each
  profile control point sweeps a circular arc about the axis, written as ``narcs``
  rational quadratic Bezier arcs of angle ``dtheta <= 90`` degrees; the middle control
  point of each arc is the intersection of the end tangents, at distance
  ``r / cos(dtheta / 2)`` from the axis, with weight ``cos(dtheta / 2)`` times the
  profile's weight. A full turn is the nine-point circle (weights 1 and sqrt(2)/2).
* :func:`extrude`: the profile and its translate, degree 1 in the sweep direction.

Convention: the sweep is the **first** parametric direction ``u`` (degree 2 for a
revolution, 1 for an extrusion, domain [0, 1]); the profile's parameter is ``v`` with
its own degree and knot vector. For a revolution, ``u`` maps to the angle
monotonically, ``u = 0`` is the profile itself and ``u = 1`` the profile rotated by
``angle`` (right-hand rule about ``axis_direction``).
"""

from __future__ import annotations

import math

import torch

from ..errors import NurbskitError
from .curve import NURBSCurve
from .surface import NURBSSurface

Tensor = torch.Tensor

__all__ = ["revolve", "extrude", "arc_count"]


def _vector(x, like: Tensor, name: str) -> Tensor:
    t = torch.as_tensor(x, dtype=like.dtype, device=like.device) if not isinstance(x, Tensor) else x.to(like)
    if t.shape != (3,):
        raise NurbskitError(f"{name} must be a 3-vector, got shape {tuple(t.shape)}")
    if not torch.isfinite(t.detach()).all():
        raise NurbskitError(f"{name} contains NaN or infinite values")
    return t


def _check_profile(profile) -> None:
    if not isinstance(profile, NURBSCurve):
        raise NurbskitError(f"profile must be a NURBSCurve, got {type(profile).__name__}")
    if profile.dim != 3:
        raise NurbskitError(f"profile must be a curve in 3D, got dimension {profile.dim}")
    if profile.control_points.ndim != 2:
        raise NurbskitError("profile must not be batched")


def arc_count(angle: float) -> int:
    """Number of rational quadratic arcs A7.1 uses for ``angle``: each spans at most 90 degrees."""
    return max(1, math.ceil(angle / (math.pi / 2) - 1e-12))


def revolve(profile: NURBSCurve, axis_point, axis_direction, angle: float = 2 * math.pi, *,
            validate: bool = True) -> NURBSSurface:
    """The exact surface swept by ``profile`` turning about an axis (The NURBS Book A7.1).

    Args:
        profile: a 3D :class:`NURBSCurve` of any degree, rational or not, ``m`` control points.
        axis_point: ``(3,)`` a point on the axis.
        axis_direction: ``(3,)`` the axis direction (any length but zero).
        angle: sweep angle in radians, ``0 < angle <= 2 pi``.
        validate: check the surface built (knot vectors, weights, finiteness) as
            :class:`NURBSSurface` does by default. ``False`` for a caller that builds many
            surfaces from one valid profile (a fitting loop, the network's guess): its
            knots and positive weights carry over, and the checks cost more than the
            construction (measured: about half of ``revolve``'s time on an 8-point profile).

    Returns:
        a :class:`NURBSSurface` with control points ``(2 * narcs + 1, m, 3)``, degrees
        ``(2, profile.degree)``, ``narcs = arc_count(angle)`` (4 for a full turn), knots in
        u ``[0, 0, 0, 1/narcs, 1/narcs, ..., 1, 1, 1]`` and the profile's knots in v.

    Example:
        >>> import torch
        >>> line = NURBSCurve(torch.tensor([[1., 0., 0.], [1., 0., 2.]], dtype=torch.float64), degree=1)
        >>> cylinder = revolve(line, [0., 0., 0.], [0., 0., 1.])
        >>> cylinder.sizes, cylinder.degrees
        ((9, 2), (2, 1))
        >>> p = cylinder.evaluate(torch.rand(5, 2, dtype=torch.float64))
        >>> bool(((p[:, :2].norm(dim=-1) - 1).abs() < 1e-12).all())
        True
    """
    _check_profile(profile)
    angle = float(angle)
    if not (0 < angle <= 2 * math.pi + 1e-12) or not math.isfinite(angle):
        raise NurbskitError(f"revolve: angle must be in (0, 2 pi], got {angle}")
    angle = min(angle, 2 * math.pi)
    P = profile.control_points  # (m, 3)
    o = _vector(axis_point, P, "axis_point")
    a = _vector(axis_direction, P, "axis_direction")
    a_norm = a.norm()
    if not float(a_norm.detach()) > 0:
        raise NurbskitError("revolve: axis_direction must not be zero")
    a = a / a_norm
    narcs = arc_count(angle)
    dtheta = angle / narcs
    wm = math.cos(dtheta / 2)

    # Frame per profile point: O the foot on the axis, X the radial unit vector, Y = a x X.
    rel = P - o
    h = rel @ a  # (m,)
    foot = o + h[:, None] * a  # (m, 3)
    radial = rel - h[:, None] * a
    r = radial.norm(dim=-1)  # (m,)
    on_axis = r.detach() <= 1e-300
    # Points on the axis stay put; their X only has to be finite (any perpendicular).
    helper = torch.tensor([1.0, 0.0, 0.0], dtype=P.dtype, device=P.device)
    if abs(float(a.detach()[0])) > 0.9:
        helper = torch.tensor([0.0, 1.0, 0.0], dtype=P.dtype, device=P.device)
    fallback = helper - (helper @ a) * a
    fallback = fallback / fallback.norm()
    X = torch.where(on_axis[:, None], fallback.expand_as(radial), radial / torch.where(on_axis, torch.ones_like(r), r)[:, None])
    Y = torch.linalg.cross(a.expand_as(X), X, dim=-1)

    # Angles of the 2 * narcs + 1 control points (ends and tangent intersections) and radii scales.
    k = torch.arange(2 * narcs + 1, dtype=P.dtype, device=P.device)
    theta = k * (dtheta / 2)  # (n_u,)
    is_mid = (torch.arange(2 * narcs + 1, device=P.device) % 2) == 1
    scale = torch.where(is_mid, torch.full_like(theta, 1.0 / wm), torch.ones_like(theta))
    cos_t, sin_t = (torch.cos(theta) * scale), (torch.sin(theta) * scale)
    # (n_u, m, 3) = foot + r * (cos X + sin Y), middle points pushed out by 1 / wm.
    ctrl = foot[None] + r[None, :, None] * (cos_t[:, None, None] * X[None] + sin_t[:, None, None] * Y[None])
    w_u = torch.where(is_mid, torch.full_like(theta, wm), torch.ones_like(theta))
    weights = w_u[:, None] * profile.weights[None, :]

    inner = [i / narcs for i in range(1, narcs) for _ in range(2)]
    knots_u = torch.tensor([0.0, 0.0, 0.0, *inner, 1.0, 1.0, 1.0], dtype=P.dtype, device=P.device)
    return NURBSSurface(ctrl, degrees=(2, profile.degree), knot_vectors=[knots_u, profile.knot_vector], weights=weights,
                        validate=validate)


def extrude(profile: NURBSCurve, direction, length: float | Tensor = 1.0, *, validate: bool = True) -> NURBSSurface:
    """The exact extrusion of ``profile`` along ``direction`` over ``length``.

    Args:
        profile: a 3D :class:`NURBSCurve`, ``m`` control points.
        direction: ``(3,)`` the sweep direction (normalised here; any length but zero).
        length: signed distance swept (a float or a 0-d tensor, differentiable).
        validate: check the surface built, as :func:`revolve`'s ``validate``.

    Returns:
        a :class:`NURBSSurface` with control points ``(2, m, 3)``: row 0 the profile,
        row 1 the profile translated by ``length * direction / |direction|``; degrees
        ``(1, profile.degree)``, knots ``[0, 0, 1, 1]`` in u, the profile's in v.

    Example:
        >>> import torch
        >>> c = NURBSCurve(torch.tensor([[0., 0., 0.], [1., 0., 0.]]), degree=1)
        >>> extrude(c, [0., 0., 1.], 2.0).evaluate(torch.tensor([[1.0, 0.5]])).tolist()
        [[0.5, 0.0, 2.0]]
    """
    _check_profile(profile)
    P = profile.control_points
    d = _vector(direction, P, "direction")
    d_norm = d.norm()
    if not float(d_norm.detach()) > 0:
        raise NurbskitError("extrude: direction must not be zero")
    length = torch.as_tensor(length, dtype=P.dtype, device=P.device)
    if not float(length.detach().abs()) > 0 or not torch.isfinite(length.detach()):
        raise NurbskitError(f"extrude: length must be finite and non-zero, got {float(length.detach())}")
    shift = length * d / d_norm
    ctrl = torch.stack([P, P + shift], 0)
    weights = torch.stack([profile.weights, profile.weights], 0)
    knots_u = torch.tensor([0.0, 0.0, 1.0, 1.0], dtype=P.dtype, device=P.device)
    return NURBSSurface(ctrl, degrees=(1, profile.degree), knot_vectors=[knots_u, profile.knot_vector], weights=weights,
                        validate=validate)
