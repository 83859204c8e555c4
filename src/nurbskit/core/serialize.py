"""The nurbskit JSON format and adapters to geomdl objects.

nurbskit JSON (version 1)::

    {"format": "nurbskit", "version": 1, "kind": "curve" | "surface" | "volume",
     "degrees": [p, ...], "knot_vectors": [[...], ...],
     "control_points": nested lists shaped (n_1, ..., n_k, dim),
     "weights": nested lists shaped (n_1, ..., n_k)}

Convention: geomdl flattens control points in its own order, and this module is the one
place that knows it (:func:`to_geomdl_order`, :func:`from_geomdl_order`, used by the
geomdl adapters here and by every geomdl-ordered file in :mod:`nurbskit.io.nurbs`):
curves in order; surfaces with v fastest (index ``iu * n_v + iv``); volumes with w
outermost, then u, then v (index ``iw * n_u * n_v + iu * n_v + iv``). geomdl speaks of
order (degree + 1) in places; these adapters speak degrees.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import torch

from .._fs import atomic_open
from ..errors import InputError, NurbskitError, OptionError
from .curve import NURBSCurve
from .spline import TensorSpline
from .surface import NURBSSurface
from .volume import NURBSVolume

FORMAT = "nurbskit"
VERSION = 1
KINDS = {"curve": NURBSCurve, "surface": NURBSSurface, "volume": NURBSVolume}


def to_dict(obj: TensorSpline) -> dict:
    """The nurbskit JSON structure of a curve, surface or volume (float64 values)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "kind": obj.kind,
        "degrees": list(obj.degrees),
        "knot_vectors": [kv.detach().cpu().double().tolist() for kv in obj.knot_vectors],
        "control_points": obj.control_points.detach().cpu().double().tolist(),
        "weights": obj.weights.detach().cpu().double().tolist(),
    }


def whole_numbers(where, values, what: str) -> list[int]:
    """``values`` (a number or a list of them, as read from a file) as ints; an InputError
    naming ``where`` when one is not a whole number (``3.5``, ``"3"``, ``true``).

    Example:
        >>> whole_numbers("a.json", [3, 3.0], "degrees")
        [3, 3]
    """
    items = [values] if isinstance(values, (int, float, np.integer, np.floating)) else values
    if not isinstance(items, (list, tuple, np.ndarray)):
        raise InputError(f"{where}: {what} must be a list of integers, found {type(values).__name__}")
    out = []
    for value in items:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not isinstance(value, int) and (not np.isfinite(value) or float(value) != int(value)):
            shown = value.item() if isinstance(value, np.generic) else value
            raise InputError(f"{where}: {what} must be integers, found {shown!r}")
        out.append(int(value))
    return out


def from_dict(data: dict, *, dtype: torch.dtype = torch.float64, device=None, source: str = "data") -> TensorSpline:
    """Build a spline from the nurbskit JSON structure (validated)."""
    if not dtype.is_floating_point:
        raise OptionError(f"dtype: expected a floating-point dtype, got {dtype}")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError(f"{source}: expected a nurbskit JSON object with \"format\": \"nurbskit\"")
    if data.get("version") != VERSION:
        raise InputError(f"{source}: nurbskit format version {data.get('version')!r} is not supported (expected {VERSION})")
    kind = data.get("kind")
    if kind not in KINDS:
        raise InputError(f"{source}: kind must be one of {sorted(KINDS)}, got {kind!r}")
    def numbers(name: str, value):
        try:
            return torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=dtype, device=device)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{source}: field {name!r} must be a rectangular array of numbers") from None

    for name in ("control_points", "knot_vectors", "degrees"):
        if name not in data:
            raise InputError(f"{source}: missing field {name!r}")
    cp = numbers("control_points", data["control_points"])
    w = None if data.get("weights") is None else numbers("weights", data["weights"])
    if not isinstance(data["knot_vectors"], list):
        raise InputError(f"{source}: field 'knot_vectors' must be a list of knot vectors, "
                         f"found {type(data['knot_vectors']).__name__}")
    kvs = [numbers(f"knot_vectors[{i}]", k) for i, k in enumerate(data["knot_vectors"])]
    degrees = whole_numbers(source, data["degrees"], "degrees")
    cls = KINDS[kind]
    try:
        if kind == "curve":
            if len(degrees) != 1 or len(kvs) != 1:
                raise NurbskitError("a curve has one degree and one knot vector")
            return cls(cp, degrees[0], kvs[0], w)
        return cls(cp, degrees, kvs, w)
    except NurbskitError as exc:
        raise InputError(f"{source}: {exc}") from None


def save(obj: TensorSpline, path: str | os.PathLike) -> None:
    """Write ``obj`` as nurbskit JSON, atomically."""
    if not isinstance(obj, TensorSpline):
        raise NurbskitError(f"save needs a NURBSCurve, NURBSSurface or NURBSVolume, got {type(obj).__name__}")
    if Path(path).is_dir():
        raise InputError(f"{path}: is a directory, expected a file name")
    with atomic_open(path, "w") as handle:
        json.dump(to_dict(obj), handle)


def load(path: str | os.PathLike, *, dtype: torch.dtype = torch.float64, device=None) -> TensorSpline:
    """Read a nurbskit JSON file (``nurbskit.io`` reads the other NURBS formats)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected a nurbskit JSON file") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return from_dict(data, dtype=dtype, device=device, source=str(path))


# ---- geomdl -------------------------------------------------------------------------

def to_geomdl_order(control_points, weights) -> tuple[np.ndarray, np.ndarray]:
    """Control points ``(*sizes, dim)`` and weights ``(*sizes)`` flattened in geomdl's order.

    Returns float64 arrays ``(N, dim)`` and ``(N,)``; ``sizes`` has 1, 2 or 3 entries
    (curve, surface, volume).

    Example:
        >>> cp = np.arange(2 * 3 * 4 * 1, dtype=float).reshape(2, 3, 4, 1)  # (n_u, n_v, n_w, 1)
        >>> to_geomdl_order(cp, np.ones((2, 3, 4)))[0][:3, 0].tolist()  # w outermost: (0,0,0), (0,1,0), (0,2,0)
        [0.0, 4.0, 8.0]
    """
    cp = _numpy(control_points)
    w = _numpy(weights)
    if cp.ndim == 4:  # volume: w outermost, then u, then v
        cp = cp.transpose(2, 0, 1, 3)
        w = w.transpose(2, 0, 1)
    return np.ascontiguousarray(cp.reshape(-1, cp.shape[-1])), np.ascontiguousarray(w.reshape(-1))


def from_geomdl_order(points, weights, sizes) -> tuple[np.ndarray, np.ndarray | None]:
    """Inverse of :func:`to_geomdl_order`: ``(N, dim)`` and ``(N,)`` (or None) -> ``(*sizes, dim)``, ``(*sizes)``."""
    sizes = [int(n) for n in sizes]
    points = np.asarray(points, dtype=np.float64)
    dim = points.shape[-1]
    w = None if weights is None else np.asarray(weights, dtype=np.float64)
    if len(sizes) == 3:
        nu, nv, nw = sizes
        cp = points.reshape(nw, nu, nv, dim).transpose(1, 2, 0, 3)
        w = None if w is None else w.reshape(nw, nu, nv).transpose(1, 2, 0)
    else:
        cp = points.reshape(*sizes, dim)
        w = None if w is None else w.reshape(*sizes)
    return np.ascontiguousarray(cp), None if w is None else np.ascontiguousarray(w)


def _numpy(t) -> np.ndarray:
    if isinstance(t, torch.Tensor):
        return t.detach().cpu().double().numpy()
    return np.asarray(t, dtype=np.float64)


def _geomdl():
    try:
        from geomdl import NURBS
    except ImportError:  # pragma: no cover
        raise NurbskitError("geomdl is needed for this conversion: pip install geomdl") from None
    return NURBS


def to_geomdl(obj: TensorSpline):
    """A geomdl ``NURBS.Curve`` / ``NURBS.Surface`` / ``NURBS.Volume`` equal to ``obj``."""
    if not isinstance(obj, TensorSpline):
        raise NurbskitError(f"to_geomdl needs a NURBSCurve, NURBSSurface or NURBSVolume, got {type(obj).__name__}")
    obj.require_single("to_geomdl")
    if obj.kind == "volume" and obj.dim < 3:
        raise NurbskitError(f"to_geomdl: geomdl holds volumes with 3-D control points, this one's are {obj.dim}-D")
    NURBS = _geomdl()
    cp, w = to_geomdl_order(obj.control_points, obj.weights)
    kvs = [kv.detach().cpu().double().tolist() for kv in obj.knot_vectors]
    cpw = np.concatenate([cp * w[:, None], w[:, None]], axis=-1).tolist()
    if obj.kind == "curve":
        g = NURBS.Curve()
        g.degree = obj.degrees[0]
        g.ctrlptsw = cpw
        g.knotvector = kvs[0]
    elif obj.kind == "surface":
        g = NURBS.Surface()
        g.degree_u, g.degree_v = obj.degrees
        g.set_ctrlpts(cpw, *obj.sizes)
        g.knotvector_u, g.knotvector_v = kvs
    else:
        g = NURBS.Volume()
        g.degree_u, g.degree_v, g.degree_w = obj.degrees
        g.set_ctrlpts(cpw, *obj.sizes)
        g.knotvector_u, g.knotvector_v, g.knotvector_w = kvs
    return g


def from_geomdl(g, *, dtype: torch.dtype = torch.float64, device=None) -> TensorSpline:
    """A nurbskit object equal to a geomdl curve, surface or volume (B-spline or NURBS)."""
    if getattr(g, "pdimension", None) not in (1, 2, 3) or not hasattr(g, "ctrlpts"):
        raise NurbskitError(f"from_geomdl needs a geomdl curve, surface or volume, got {type(g).__name__}")
    cpw = np.asarray(g.ctrlptsw if hasattr(g, "ctrlptsw") else [list(p) + [1.0] for p in g.ctrlpts], dtype=np.float64)
    w = cpw[:, -1]
    cp = cpw[:, :-1] / w[:, None]
    as_t = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
    if g.pdimension == 1:
        return NURBSCurve(as_t(cp), g.degree, as_t(g.knotvector), as_t(w))
    if g.pdimension == 2:
        cp, w = from_geomdl_order(cp, w, (g.ctrlpts_size_u, g.ctrlpts_size_v))
        return NURBSSurface(
            as_t(cp), (g.degree_u, g.degree_v), [as_t(g.knotvector_u), as_t(g.knotvector_v)], as_t(w),
        )
    cp, w = from_geomdl_order(cp, w, (g.ctrlpts_size_u, g.ctrlpts_size_v, g.ctrlpts_size_w))
    return NURBSVolume(
        as_t(cp), (g.degree_u, g.degree_v, g.degree_w),
        [as_t(g.knotvector_u), as_t(g.knotvector_v), as_t(g.knotvector_w)], as_t(w),
    )
