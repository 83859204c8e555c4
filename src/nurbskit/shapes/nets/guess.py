"""The network's guess in world coordinates: the initialiser of the geometric refinement.

Canonicalisation (how a world cloud is put in the frame the networks were trained in):

1. centre on the centroid and divide by the largest distance from it (:func:`.data.normalise`);
2. the direction (axis, or extrusion direction), ``direction="normals"`` (the default):
   the shape package's own estimators on an even subsample of :data:`AXIS_POINTS` points
   (:func:`nurbskit.shapes.normals.estimate_normals`, then
   :func:`nurbskit.shapes.axis.revolution_axis` (line geometry) or
   :func:`~nurbskit.shapes.axis.extrusion_direction`, :data:`AXIS_ITERATIONS` robust
   rounds): a few milliseconds of one CPU thread, a median error of 0.4-0.7 degree on
   the benchmark's clouds. When that estimate is ambiguous (its ``spread`` above
   :data:`SPREAD_LIMIT`: a sphere's axis, a plane's direction) the network's own search
   below runs instead;
3. ``direction="search"``: analysis by synthesis, the network alone: for each candidate
   direction ``d`` the cloud is turned so that ``d`` is z (frame rows ``(e1, e2, d)``,
   ``e1`` by the contract's ``plane_basis`` rule), the network predicts a profile, and
   the candidate whose generated surface is nearest the cloud (Chamfer) wins. Principal
   directions alone do not do: a vase about as wide as it is tall has a nearly isotropic
   covariance (eigenvalues within 5 %, measured), so PCA's eigenvectors point anywhere
   (measured on the benchmark's vases: the nearest eigenvector is 13 degrees off the axis
   at the median). Candidates: the three principal directions and 30 directions over the
   hemisphere (about 25 degrees apart), then rings of 6 at 8, 3 and 1 degrees around the
   best so far (54 network evaluations on a subsample, in batches): about ten times the
   time of step 2, for a 1-2 degree axis;
4. the profile is predicted at the chosen direction from up to :data:`MAX_POINTS` points;
5. the winner is mapped back: axis point = the centroid, lengths times the scale.

Convention: the returned dict follows the network initialiser contract of
``docs/shapes.md`` (``fit_shape(init="network")``): ``axis_point (3,)``, ``axis_direction
(3,)`` unit, ``profile`` a 2-D cubic :class:`NURBSCurve` ``(N_CTRL, 2)`` in ``(r, z)`` about
the axis (revolution) or in ``(x, y)`` along ``plane_basis(axis_direction)`` from
``axis_point`` (extrusion), ``extent (t0, t1)`` for an extrusion, plus ``frame``
(``origin``, ``e1``, ``e2``: the profile plane's 3-D unit vectors), ``chamfer`` (the
Chamfer distance of the generated surface in the normalised frame, with ``score=True``;
None otherwise), ``weights`` (the model's name) and
``direction_from`` (``"normals"`` or ``"search"``: which step found the direction).
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch
from torch import Tensor

from ...core.curve import NURBSCurve
from ...errors import InputError, OptionError
from ...core.neighbors import nearest_neighbors
from ..axis import extrusion_direction, revolution_axis
from ..normals import estimate_normals
from .data import DEGREE, KINDS, N_CTRL, normalise, profile_knots
from .models import build_model
from .training import model_name

__all__ = ["DIRECTIONS", "initial_guess", "guess_surface", "load_model", "plane_basis", "predict_canonical"]

MAX_POINTS = 512  # points of the final prediction (an even stride through the cloud; the networks were trained on 512)
SEARCH_POINTS = 160  # points per candidate direction in the search
AXIS_POINTS = 400  # points of the normals-based direction (an even subsample)
AXIS_NEIGHBOURS = {"revolution": 16, "extrusion": 24}  # k of the normals on that subsample
AXIS_ITERATIONS = {"revolution": 1, "extrusion": 2}
"""Rounds of the line-geometry / direction fit (the first unweighted, then Tukey-reweighted).
Measured on the benchmark's first 100 world clouds per kind: a revolution's axis is as good
after one round (median 0.64 against 0.65 degree for two, mean distance 0.754 / 0.755 % of
the diagonal) for 50 fewer operations; an extrusion's direction is not (0.46 against 0.39
degree), so it keeps two. The full geometric fit uses 10."""
SPREAD_LIMIT = 0.25  # a normals estimate with a larger spread is ambiguous: search instead
DIRECTIONS = ("normals", "search")


def plane_basis(direction: Tensor) -> tuple[Tensor, Tensor]:
    """The contract's in-plane unit vectors ``(e1, e2)`` for ``direction (3,)``.

    ``nurbskit.shapes.init.plane_basis`` when the shape fitter has it (the contract's owner),
    else the same rule here: ``e1`` the x axis projected onto the plane (the y axis when
    ``|d_x| > 0.9``), normalised; ``e2 = d x e1``.
    """
    try:
        from ..init import plane_basis as owner  # the shape fitter's (the contract's owner), once merged
    except ImportError:
        owner = None
    if owner is not None:
        return owner(direction)
    d = direction / direction.norm()
    ref = torch.tensor([0.0, 1.0, 0.0] if abs(float(d[0])) > 0.9 else [1.0, 0.0, 0.0], dtype=d.dtype)
    e1 = ref - (ref @ d) * d
    e1 = e1 / e1.norm()
    return e1, torch.linalg.cross(d, e1, dim=-1)


@lru_cache(maxsize=8)
def load_model(kind: str, input: str = "points", path: str | None = None):
    """The trained network (eval mode) from the shipped weights or a weights file ``path``."""
    from ...learn import load_weights

    name = model_name(kind, input)
    try:
        state, meta = load_weights(path or name)
    except InputError as exc:
        raise OptionError(f"{exc}; train it with: nurbskit train revolve --input {input} --kind {kind} "
                          f"--out DIR, then copy DIR/weights.pt to src/nurbskit/learn/weights/{name}.pt") from None
    model = build_model(meta.get("kind", kind), meta.get("input", input))
    model.load_state_dict(state)
    model.eval()
    return model


def predict_canonical(model, clouds: Tensor) -> tuple[Tensor, Tensor]:
    """``clouds (B, N, 3)`` normalised and canonical -> ``(coords (B, n_outputs), chamfer (B,))``.

    ``chamfer`` is :func:`nurbskit.losses.chamfer_distance`'s (the training loss) between each
    cloud and its generated surface, from the core's neighbour search run on one thread:
    the search calls it for dozens of small clouds, where a thread pool per query costs
    more than the query (about 5x slower with all cores on this loaded machine, measured).
    """
    with torch.no_grad():
        x = clouds.to(torch.float32)
        coords = model(x)
        chamfer = _chamfer(x, model.surface_points(coords))
    return coords.to(torch.float64), chamfer.to(torch.float64)


def _chamfer(x: Tensor, surf: Tensor) -> Tensor:
    """``chamfer_distance(x, surf)`` (reduction "mean") per batch element, ``(B,)``, by the
    core's neighbour search on one thread (see :func:`predict_canonical`)."""
    to_surface, _ = nearest_neighbors(x, surf, workers=1)
    coverage, _ = nearest_neighbors(surf, x, workers=1)
    return to_surface.mean(-1) + coverage.mean(-1)


@lru_cache(maxsize=1)
def _profile_knots() -> Tensor:
    return profile_knots()


def _knots() -> Tensor:
    """The profile's knot vector (:func:`.data.profile_knots`), built once: a copy per curve."""
    return _profile_knots().clone()


def _check_points(points) -> Tensor:
    if not isinstance(points, Tensor):
        points = torch.as_tensor(points)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 16:
        raise InputError(f"initial_guess: points must have shape (N >= 16, 3), got {tuple(points.shape)}")
    p = points.detach().to(torch.float64)
    if not torch.isfinite(p).all():
        raise InputError("initial_guess: points contain NaN or infinite values")
    return p


def _frames(dirs: Tensor) -> Tensor:
    """Right-handed frames ``(K, 3, 3)`` with rows ``(e1, e2, d)`` for unit ``dirs (K, 3)`` (the contract's e1 rule)."""
    x_ref = torch.tensor([1.0, 0.0, 0.0], dtype=dirs.dtype).expand_as(dirs)
    y_ref = torch.tensor([0.0, 1.0, 0.0], dtype=dirs.dtype).expand_as(dirs)
    ref = torch.where(dirs[:, :1].abs() > 0.9, y_ref, x_ref)
    e1 = ref - (ref * dirs).sum(-1, keepdim=True) * dirs
    e1 = e1 / e1.norm(dim=-1, keepdim=True)
    return torch.stack([e1, torch.linalg.cross(dirs, e1, dim=-1), dirs], 1)


def _hemisphere(count: int) -> Tensor:
    """``(count, 3)`` unit directions spread evenly over the upper hemisphere (a Fibonacci lattice)."""
    i = torch.arange(count, dtype=torch.float64)
    z = (i + 0.5) / count
    phi = i * math.pi * (3 - math.sqrt(5))
    ring = (1 - z**2).sqrt()
    return torch.stack([ring * torch.cos(phi), ring * torch.sin(phi), z], -1)


def _ring(d: Tensor, degrees: float, count: int = 8) -> Tensor:
    """``d`` and ``count`` directions at ``degrees`` around it: ``(count + 1, 3)``."""
    e1, e2, _ = _frames(d[None])[0]
    beta = torch.arange(count, dtype=d.dtype) * (2 * math.pi / count)
    a = math.radians(degrees)
    around = math.cos(a) * d + math.sin(a) * (torch.cos(beta)[:, None] * e1 + torch.sin(beta)[:, None] * e2)
    return torch.cat([d[None], around])


def _score(model, cloud: Tensor, dirs: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """The network's profile for ``cloud (n, 3)`` turned so each of ``dirs (K, 3)`` is z: (frames, coords, chamfer)."""
    frames = _frames(dirs)
    coords, chamfer = predict_canonical(model, torch.einsum("nj,kij->kni", cloud, frames))
    return frames, coords, chamfer


def _normals_direction(rel: Tensor, kind: str) -> tuple[Tensor, float]:
    """Direction ``(3,)`` and spread of the normalised cloud ``rel (N, 3)`` from normals.

    The public estimators of :mod:`nurbskit.shapes.axis` on an even subsample of at most
    :data:`AXIS_POINTS` points (normals by :func:`~nurbskit.shapes.normals.estimate_normals`
    with :data:`AXIS_NEIGHBOURS` neighbours): the subsample and the few robust rounds keep
    it to a few milliseconds; the full geometric fit uses every point.
    """
    n = rel.shape[0]
    sub = rel[torch.linspace(0, n - 1, min(n, AXIS_POINTS), dtype=torch.float64).round().long()]
    normals = estimate_normals(sub, AXIS_NEIGHBOURS[kind])
    if kind == "revolution":
        axis = revolution_axis(sub, normals, iterations=AXIS_ITERATIONS["revolution"])
        return axis.direction, axis.spread
    return extrusion_direction(normals, iterations=AXIS_ITERATIONS["extrusion"])


def _search_direction(model, rel: Tensor) -> Tensor:
    """The network's direction for the normalised cloud ``rel (N, 3)`` (module docstring, step 3)."""
    _, evecs = torch.linalg.eigh(rel.T @ rel / rel.shape[0])
    search = rel[:: max(1, -(-rel.shape[0] // SEARCH_POINTS))]
    dirs = torch.cat([evecs.T, _hemisphere(30)])
    _, _, chamfer = _score(model, search, dirs)
    d = dirs[int(torch.argmin(chamfer))]
    for degrees in (8.0, 3.0, 1.0):
        dirs = _ring(d, degrees, 6)
        _, _, chamfer = _score(model, search, dirs)
        d = dirs[int(torch.argmin(chamfer))]
    return d


def initial_guess(points, kind: str, *, weights: str | None = None, direction: str = "normals",
                  score: bool = False) -> dict:
    """The trained network's surface of ``kind`` for a world cloud ``points (N, 3)``.

    The direction (axis or extrusion direction) comes from normals
    (``direction="normals"``: the public estimators of :mod:`nurbskit.shapes.axis` on
    :data:`AXIS_POINTS` points; the search below when that is ambiguous) or from the
    network alone (``direction="search"``: analysis by synthesis, the direction whose
    generated surface is nearest the cloud by Chamfer among 54 candidates; see the module
    docstring). The network then predicts the profile from up to :data:`MAX_POINTS`
    points turned to that direction. The axis passes through the centroid.

    Args:
        points: ``(N, 3)`` float64, any pose and size (not centred or scaled).
        kind: 'revolution' or 'extrusion'.
        weights: a weights file instead of the shipped ``shapes_<kind>_points``.
        direction: 'normals' (default) or 'search'.
        score: also compute ``chamfer`` (the training loss between :data:`SEARCH_POINTS` of
            the points and the generated surface, in the normalised frame; about 1 ms, so
            off by default: ``chamfer`` is then None).

    Returns:
        the contract's dict (module docstring). Raises InputError for bad points,
        OptionError when the weights are missing or an option is unknown.

    Example:
        >>> from nurbskit.shapes.synthetic import vase_cloud
        >>> guess = initial_guess(vase_cloud(1000, seed=2).points, "revolution")
        >>> {"axis_point", "axis_direction", "profile"} <= set(guess), guess["profile"].control_points.shape
        (True, torch.Size([8, 2]))
    """
    if kind not in KINDS:
        raise OptionError(f"initial_guess: kind must be one of {', '.join(KINDS)}, got {kind!r}")
    if direction not in DIRECTIONS:
        raise OptionError(f"initial_guess: direction must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
    p = _check_points(points)
    model = load_model(kind, "points", weights)
    rel, centre, scale = normalise(p)
    found = "search"
    if direction == "normals":
        d, spread = _normals_direction(rel, kind)
        if spread <= SPREAD_LIMIT:
            found = "normals"
    if found == "search":
        d = _search_direction(model, rel)
    frame = _frames(d[None])[0]
    with torch.no_grad():
        x = (rel[:: max(1, -(-rel.shape[0] // MAX_POINTS))] @ frame.T).to(torch.float32)
        coords = model(x[None])
        chamfer = None
        if score:  # on SEARCH_POINTS of them: the neighbour search costs more than the network
            check = (rel[:: max(1, -(-rel.shape[0] // SEARCH_POINTS))] @ frame.T).to(torch.float32)
            chamfer = float(_chamfer(check[None], model.surface_points(coords))[0])
    c = coords[0].to(torch.float64)
    prof = c[: 2 * N_CTRL].reshape(N_CTRL, 2) * scale
    out = {"axis_point": centre.clone(), "axis_direction": frame[2].clone(), "chamfer": chamfer,
           "weights": model_name(kind, "points"), "direction_from": found}
    # the frame's e1 is the contract's plane_basis(d) rule (see _frames), so the profile needs no turn;
    # a revolution's profile is (r, z) whatever e1 is: the network knows full turns only, the fitter
    # finds a partial angle from the points
    e1, e2 = frame[0], frame[1]
    if kind == "extrusion":
        t0, t1 = (c[2 * N_CTRL:] * scale).tolist()
        out["extent"] = (min(t0, t1), max(t0, t1))
    # unchecked, as the world curve of guess_surface: the knots are the fixed clamped uniform vector and
    # the points finite network outputs of a finite cloud (the check cost more than the network's head)
    out["profile"] = NURBSCurve(prof.contiguous(), degree=DEGREE, knot_vector=_knots(), validate=False)
    out["frame"] = {"origin": centre.clone(), "e1": e1.clone(), "e2": e2.clone()}
    return out


def guess_surface(guess: dict, kind: str):
    """The exact world-coordinate NURBS surface of an :func:`initial_guess` result (full turn)."""
    from ...core.construct import extrude, revolve

    o, d = guess["axis_point"], guess["axis_direction"] / guess["axis_direction"].norm()
    e1, e2 = guess["frame"]["e1"], guess["frame"]["e2"]
    c = guess["profile"].control_points
    if kind == "revolution":
        curve = NURBSCurve(o + c[:, :1] * e1 + c[:, 1:] * d, degree=DEGREE, knot_vector=_knots(), validate=False)
        return revolve(curve, o, d, validate=False)
    t0, t1 = guess["extent"]
    curve = NURBSCurve(o + c[:, :1] * e1 + c[:, 1:] * e2 + t0 * d, degree=DEGREE, knot_vector=_knots(), validate=False)
    return extrude(curve, d, t1 - t0, validate=False)
