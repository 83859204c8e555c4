"""Where the shape fitter starts: the geometric estimate, or a trained network's guess.

``init="network"`` asks :func:`nurbskit.shapes.nets.initial_guess` (the learned path of
issue 11, DeepSpline section 5: a PointNet-style encoder predicting the profile's control
points; a separate subpackage, loaded lazily here) for the axis and the profile, then runs
the same refinement as the geometric path. This module states and checks that contract;
``docs/shapes.md`` ("Network initialiser contract") says the same for the network's side.

Contract of ``nurbskit.shapes.nets.initial_guess(points, kind) -> dict``:

* ``points``: ``(N, 3)`` float64 CPU tensor, the cloud as given (not normalised);
  ``kind``: ``"revolution"`` or ``"extrusion"``.
* ``"axis_point"``: ``(3,)`` tensor, a point on the axis (revolution) or the origin of
  the profile's plane (extrusion), in the cloud's coordinates.
* ``"axis_direction"``: ``(3,)`` tensor, non-zero (normalised here): the axis of
  revolution, or the extrusion direction.
* ``"profile"``: a :class:`~nurbskit.core.curve.NURBSCurve` with **2-D** control points
  ``(n, 2)``, any degree and knot vector, rational or not, in the plane's coordinates:

  - revolution: ``(r, z)``: ``r >= 0`` the distance from the axis, ``z`` the signed height
    along ``axis_direction`` measured from ``axis_point``;
  - extrusion: ``(x, y) = ((q - axis_point) . e1, (q - axis_point) . e2)`` for a point
    ``q`` of the section, with ``(e1, e2) = plane_basis(axis_direction)`` (below).

* optional ``"angle"`` (revolution, radians in (0, 2 pi]) and ``"extent"`` (extrusion:
  ``(t0, t1)``, heights along the unit direction from ``axis_point``); when absent they
  come from the points (the angular gap; the range of the heights).

Convention: tensors are converted to float64 CPU here; the guess is not modified.
"""

from __future__ import annotations

import importlib
import math

import torch

from ..core.curve import NURBSCurve
from ..errors import NurbskitError, OptionError

Tensor = torch.Tensor
F64 = torch.float64

__all__ = ["INITS", "NetworkGuess", "plane_basis", "network_guess"]

INITS = ("geometric", "network")
NETS_MODULE = "nurbskit.shapes.nets"


def plane_basis(direction) -> tuple[Tensor, Tensor]:
    """The in-plane unit vectors ``(e1, e2)`` ``(3,)`` orthogonal to ``direction (3,)``.

    ``e1`` is the x axis projected onto the plane (the y axis when ``|d_x| > 0.9``),
    normalised; ``e2 = d x e1`` (``d`` normalised), so ``(e1, e2, d)`` is right-handed.

    Example:
        >>> e1, e2 = plane_basis(torch.tensor([0.0, 0.0, 2.0], dtype=torch.float64))
        >>> e1.tolist(), e2.tolist()
        ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    """
    d = torch.as_tensor(direction)
    d = d / d.norm()
    ref = torch.tensor([1.0, 0.0, 0.0], dtype=d.dtype)
    if abs(float(d.detach()[0])) > 0.9:
        ref = torch.tensor([0.0, 1.0, 0.0], dtype=d.dtype)
    e1 = ref - (ref @ d) * d
    e1 = e1 / e1.norm()
    return e1, torch.linalg.cross(d, e1, dim=-1)


class NetworkGuess(dict):
    """The checked guess: float64 ``axis_point``, unit ``axis_direction``, ``profile``
    (2-D NURBSCurve), and ``angle`` / ``extent`` or None."""


def _vector(guess: dict, key: str) -> Tensor:
    if key not in guess:
        raise NurbskitError(f"the network's initial guess has no {key!r} (expected keys axis_point, "
                            "axis_direction, profile)")
    v = torch.as_tensor(guess[key]).detach().to(F64).cpu().reshape(-1)
    if v.shape != (3,) or not torch.isfinite(v).all():
        raise NurbskitError(f"the network's {key!r} must be a finite (3,) tensor, got shape "
                            f"{tuple(torch.as_tensor(guess[key]).shape)}")
    return v


def check_guess(guess, kind: str) -> NetworkGuess:
    """Validate a guess against the contract (module docstring); one-line errors."""
    if not isinstance(guess, dict):
        raise NurbskitError(f"the network's initial guess must be a dict, got {type(guess).__name__}")
    o = _vector(guess, "axis_point")
    d = _vector(guess, "axis_direction")
    if not float(d.norm()) > 0:
        raise NurbskitError("the network's 'axis_direction' is zero")
    prof = guess.get("profile")
    if not isinstance(prof, NURBSCurve) or prof.control_points.ndim != 2 or prof.dim != 2:
        raise NurbskitError("the network's 'profile' must be a NURBSCurve with (n, 2) control points, got "
                            f"{type(prof).__name__}" + (f" of dimension {prof.dim}" if isinstance(prof, NURBSCurve) else ""))
    ctrl = prof.control_points.detach().to(F64).cpu()
    if not torch.isfinite(ctrl).all():
        raise NurbskitError("the network's profile has NaN or infinite control points")
    profile = NURBSCurve(ctrl, degree=prof.degree, knot_vector=prof.knot_vector.detach().to(F64).cpu(),
                         weights=prof.weights.detach().to(F64).cpu())
    angle = guess.get("angle")
    if angle is not None:
        angle = float(angle)
        if not 0 < angle <= 2 * math.pi + 1e-9:
            raise NurbskitError(f"the network's 'angle' must be in (0, 2 pi], got {angle}")
    extent = guess.get("extent")
    if extent is not None:
        extent = tuple(float(t) for t in extent)
        if len(extent) != 2 or not extent[1] > extent[0]:
            raise NurbskitError(f"the network's 'extent' must be (t0, t1) with t0 < t1, got {extent}")
    return NetworkGuess(axis_point=o, axis_direction=d / d.norm(), profile=profile, angle=angle, extent=extent)


def network_guess(points: Tensor, kind: str) -> NetworkGuess:
    """Call ``nurbskit.shapes.nets.initial_guess(points, kind)`` and check its answer.

    Raises :class:`OptionError` (one line) when the learned path is not installed.
    """
    try:
        nets = importlib.import_module(NETS_MODULE)
    except ModuleNotFoundError as exc:
        if exc.name not in (NETS_MODULE, None):
            raise
        raise OptionError(
            f"--init network needs the trained point-cloud model for {kind} (module {NETS_MODULE}, "
            "weights made by `nurbskit train revolve --input points`), which is not installed; "
            "use --init geometric"
        ) from None
    initial_guess = getattr(nets, "initial_guess", None)
    if initial_guess is None:
        raise OptionError(f"--init network: {NETS_MODULE} has no initial_guess(points, kind); the trained "
                          f"model for {kind} is missing; use --init geometric")
    return check_guess(initial_guess(points.detach().clone(), kind), kind)
