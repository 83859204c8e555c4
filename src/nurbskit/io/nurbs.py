"""NURBS parameter files: nurbskit JSON, geomdl JSON, the thesis's ``.ctrlpts`` /
``.weights`` / ``.cptw`` text files, ``smesh`` text, and Rhino ``.3dm``.

Conventions, settled here once:

* ``.ctrlpts``: one Cartesian control point ``x y z`` per line, in geomdl order (defined
  in :mod:`nurbskit.core.serialize`, the one place that knows it).
* ``.weights``: the weights in the same order, separated by commas (and/or whitespace,
  line breaks; a trailing comma is allowed).
* ``.cptw``: one line per u index, control points separated by ``;``, each
  ``x*w,y*w,z*w,w`` (weighted, geomdl's ``ctrlptsw``); a file with one point per line
  is a curve.
* ``smesh``: line 1 the dimension (3), line 2 the degrees ``p q``, line 3 the sizes
  ``n_u n_v``, lines 4 and 5 the knot vectors, then ``x y z w`` lines (Cartesian, with
  the weight) with u varying fastest (geomdl's ``import_smesh``).

Control-point files carry no sizes, degrees or knots: they come from keyword options
(``sizes``, ``degrees``, ``knot_vectors``, ``weights``, ``kind``) or from a side JSON
(``meta=`` a path, or found beside the file as ``<file>.json``, e.g. ``duck1.ctrlpts.json``)
holding the same keys; options win over the side JSON. Without knot vectors the knots
are clamped uniform; with knot vectors and no degrees, the degree is read from the
multiplicity of the first knot (clamped vectors). A ``.weights`` file beside a
``.ctrlpts`` file (``duck1.weights`` for ``duck1.ctrlpts``) is used unless ``weights``
is given (``weights=None`` ignores it).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import torch

from .._fs import atomic_open, atomic_paths
from ..core.curve import NURBSCurve
from ..core.serialize import from_dict, from_geomdl_order, save, to_geomdl_order, whole_numbers
from ..core.spline import TensorSpline
from ..core.surface import NURBSSurface
from ..core.volume import NURBSVolume
from ..errors import NurbskitError, OptionError
from ._base import InputError, check_readable, is_number, read_bytes

NURBS_FORMATS = ("nurbskit", "geomdl", "ctrlpts", "cptw", "smesh", "3dm", "cad")
_CAD_EXTENSIONS = (".step", ".stp", ".iges", ".igs", ".brep")  # through OpenCASCADE: io/cad
_KIND_BY_DIM = {1: "curve", 2: "surface", 3: "volume"}
_CLASSES = {"curve": NURBSCurve, "surface": NURBSSurface, "volume": NURBSVolume}
_AUTO = "auto"


def nurbs_format(path: str | os.PathLike, format: str | None = None) -> str:
    """The NURBS format of ``path``: by ``format``, then by content (JSON kind, smesh layout), then extension."""
    path = Path(path)
    if format is not None:
        if format not in NURBS_FORMATS:
            raise OptionError(f"format must be one of {NURBS_FORMATS}, got {format!r}")
        return format
    ext = path.suffix.lower()
    if ext == ".3dm":
        return "3dm"
    if ext in _CAD_EXTENSIONS:
        return "cad"
    if ext == ".json":
        return "json"
    if ext == ".ctrlpts":
        return "ctrlpts"
    if ext == ".cptw":
        return "cptw"
    if ext == ".weights":
        raise InputError(f"{path}: a .weights file holds only weights; read the .ctrlpts file it belongs to")
    if ext in (".smesh", ".dat") or "smesh" in path.name.lower():
        return "smesh"
    raise InputError(
        f"{path}: unknown NURBS file type {ext or '(no extension)'!r}; expected .json, .ctrlpts, .cptw, "
        ".smesh/.dat or .3dm"
    )


def is_nurbs_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` looks like a NURBS parameter file (by extension and, for JSON, content)."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext in (".ctrlpts", ".cptw", ".smesh", ".3dm", ".weights") + _CAD_EXTENSIONS:
        return True
    if ext == ".json":
        return True
    if ext == ".dat" or "smesh" in path.name.lower():
        try:
            with open(path, "rb") as handle:
                first = handle.read(64).split(b"\n", 1)[0].strip()
            return first in (b"3", b"2")
        except OSError:
            return False
    return False


# ---- reading ------------------------------------------------------------------------

#: The largest control-point coordinate read: beyond it, squared distances and cross
#: products leave float64 (1e150 squared is 1e300).
MAX_COORDINATE = 1e150


def read_nurbs(path: str | os.PathLike, *, format: str | None = None, index: int = 0,
               dtype: torch.dtype = torch.float64, within: str | os.PathLike | None = None,
               **options) -> TensorSpline:
    """Read a NURBS curve, surface or volume.

    Args:
        path: the file (see the module docstring for the formats).
        format: force one of 'nurbskit', 'geomdl', 'ctrlpts', 'cptw', 'smesh', '3dm'.
        index: which object, for files holding several (geomdl JSON, .3dm).
        dtype: dtype of the returned tensors.
        within: a folder that every file read must lie in, after following symbolic
            links: the file itself and the companions a control-point file brings (its
            side JSON, a sibling ``.weights``, a weights file the side JSON names). For
            a server (the studio) that takes file names from a client; None: no limit.
        options: for control-point files: ``sizes``, ``degrees``, ``knot_vectors``,
            ``weights`` (array, a path, or None), ``kind``, ``meta`` (side JSON path).

    Example:
        >>> duck = read_nurbs("duck1.ctrlpts", sizes=(14, 13), degrees=(3, 3))  # doctest: +SKIP
        >>> duck.sizes  # doctest: +SKIP
        (14, 13)
    """
    path = _inside(check_readable(path), within, "file")
    fmt = nurbs_format(path, format)
    if not dtype.is_floating_point:
        raise OptionError(f"dtype: expected a floating-point dtype, got {dtype}")
    if fmt in ("ctrlpts", "cptw", "smesh"):
        _one_object(path, index)
    try:
        if fmt in ("json", "nurbskit", "geomdl"):
            _no_options(path, options)
            obj = _read_json(path, fmt, index)
        elif fmt == "ctrlpts":
            obj = _read_ctrlpts(path, options, within)
        elif fmt == "cptw":
            obj = _read_cptw(path, options, within)
        elif fmt == "smesh":
            _no_options(path, options)
            obj = _read_smesh(path)
        elif fmt == "cad":  # the index-th curve or surface (face surfaces untrimmed) of a STEP/IGES/BREP file
            _no_options(path, options)
            from .cad import read_objects

            found = [o.surface if hasattr(o, "loops") else o for o in read_objects(path)]
            if not -len(found) <= index < len(found):
                raise OptionError(f"{path}: index {index} is out of range; the file holds {len(found)} curves/surfaces")
            obj = found[index]
        else:
            _no_options(path, options)
            from .cad import read_3dm

            obj = read_3dm(path, index=index)
    except (InputError, OptionError):
        raise
    except NurbskitError as exc:  # construction found the parameters inconsistent
        raise InputError(f"{path}: {exc}") from None
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError) as exc:
        # a field of the wrong kind (a list where a name belongs, text where a size belongs)
        raise InputError(f"{path}: malformed {fmt} data ({type(exc).__name__}: {exc})") from None
    check_coordinates(obj, path)
    return obj.to(dtype)


def check_coordinates(obj, path) -> None:
    """An InputError naming ``path`` when the control points of ``obj`` (a spline, or what
    holds one as ``.surface``) exceed :data:`MAX_COORDINATE`."""
    spline = getattr(obj, "surface", obj)
    cp = getattr(spline, "control_points", None)
    largest = float(cp.detach().abs().max()) if cp is not None and cp.numel() else 0.0
    if largest > MAX_COORDINATE:
        raise InputError(f"{path}: control points up to {largest:.3g}: their squares (normals, tessellation, "
                         f"distances) overflow float64; rescale the geometry")


def _no_options(path, options):
    if options:
        raise OptionError(f"{path}: options {sorted(options)} apply only to .ctrlpts and .cptw files")


def _load_json(path: Path):
    from ._json import load_json

    return load_json(path)


def _plain(value):
    """A numpy scalar as the Python number it holds (so that messages show ``-1.0``, not ``np.float64(-1.0)``)."""
    return value.item() if isinstance(value, np.generic) else value


def _read_json(path: Path, fmt: str, index: int) -> TensorSpline:
    data = _load_json(path)
    if isinstance(data, dict) and data.get("format") == "nurbskit" and fmt != "geomdl":
        _one_object(path, index)
        return from_dict(data, source=str(path))
    if isinstance(data, dict) and "shape" in data and fmt != "nurbskit":
        return _from_geomdl_json(path, data, index)
    raise InputError(
        f"{path}: JSON is neither nurbskit ('\"format\": \"nurbskit\"') nor geomdl ('\"shape\": {{...}}') NURBS data"
    )


def _one_object(path: Path, index: int) -> None:
    """A file of one object answers index 0 (or -1) only."""
    if index not in (0, -1):
        raise OptionError(f"{path}: index {index} is out of range; the file holds one object")


def _from_geomdl_json(path: Path, data: dict, index: int) -> TensorSpline:
    shape = data["shape"]
    if not isinstance(shape, dict):
        raise InputError(f"{path}: geomdl JSON 'shape' must be an object")
    kind = shape.get("type")
    items = shape.get("data")
    if isinstance(items, dict):  # a single object, as in NURBS-Diff's AMSurface.json
        items = [items]
    if not isinstance(kind, str) or kind not in _CLASSES or not isinstance(items, list) or not items:
        raise InputError(f"{path}: geomdl JSON needs shape.type curve/surface/volume and shape.data, got type {kind!r}")
    if not -len(items) <= index < len(items):
        raise OptionError(f"{path}: index {index} is out of range; the file holds {len(items)} {kind}(s)")
    item = items[index]
    axes = {"curve": [""], "surface": ["_u", "_v"], "volume": ["_u", "_v", "_w"]}[kind]
    try:
        degrees = whole_numbers(path, [item["degree" + a] for a in axes], "geomdl JSON degrees")
        knots = [np.asarray(item["knotvector" + a], dtype=np.float64) for a in axes]
        cp = item["control_points"]
        points = np.asarray(cp["points"], dtype=np.float64)
        weights = np.asarray(cp["weights"], dtype=np.float64) if cp.get("weights") is not None else None
        if kind == "curve":
            sizes = [points.shape[0]]
        else:
            sizes = whole_numbers(path, [item["size" + a] for a in axes], "geomdl JSON sizes")
    except KeyError as exc:
        raise InputError(f"{path}: geomdl JSON {kind} lacks the field {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{path}: geomdl JSON has a malformed field ({exc})") from None
    if points.ndim < 2 or points.shape[-1] < 1 or min(sizes) < 1 or min(degrees) < 1:
        raise InputError(f"{path}: geomdl JSON needs points (N, dim), sizes and degrees >= 1; found points "
                         f"of shape {points.shape}, sizes {sizes}, degrees {degrees}")
    dim = points.shape[-1]
    count = int(np.prod(sizes))
    if points.size != count * dim:
        raise InputError(f"{path}: geomdl JSON sizes {sizes} need {count} control points, found {points.size // dim}")
    if weights is not None and weights.size != count:
        raise InputError(f"{path}: geomdl JSON has {weights.size} weights for {count} control points")
    return _assemble(kind, points.reshape(count, dim), None if weights is None else weights.reshape(count),
                     sizes, degrees, knots)


def _assemble(kind, points, weights, sizes, degrees, knots) -> TensorSpline:
    """A spline from control points (and weights) flattened in geomdl order (:func:`from_geomdl_order`)."""
    sizes = [int(s) for s in sizes]
    cp, w = from_geomdl_order(points, weights, sizes)
    t = lambda a: None if a is None else torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float64)  # noqa: E731
    kvs = None if knots is None else [None if k is None else t(k) for k in knots]
    if kvs is not None and all(k is None for k in kvs):
        kvs = None
    elif kvs is not None and any(k is None for k in kvs):
        from ..core.knots import clamped_uniform

        kvs = [clamped_uniform(n, p, dtype=torch.float64) if k is None else k for k, n, p in zip(kvs, sizes, degrees)]
    if kind == "curve":
        return NURBSCurve(t(cp), degrees[0], None if kvs is None else kvs[0], t(w))
    return _CLASSES[kind](t(cp), tuple(degrees), kvs, t(w))


def _flatten(obj: TensorSpline) -> tuple[np.ndarray, np.ndarray]:
    """Control points ``(N, dim)`` and weights ``(N,)`` in geomdl order (:func:`to_geomdl_order`)."""
    return to_geomdl_order(obj.control_points, obj.weights)


# ---- control-point text files -------------------------------------------------------

def read_weights(path: str | os.PathLike) -> np.ndarray:
    """The weights of a ``.weights`` file: ``(N,)`` float64 (comma and/or whitespace separated)."""
    path = check_readable(path)
    text = read_bytes(path)
    tokens = re.split(rb"[,\s]+", text.strip())
    tokens = [t for t in tokens if t]
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not is_number(t))
        raise InputError(f"{path}: weights must be numbers separated by commas; found {bad[:30]!r}") from None
    if values.size == 0:
        raise InputError(f"{path}: holds no weights")
    if not np.all(np.isfinite(values)) or np.any(values <= 0):
        bad = values[~(np.isfinite(values) & (values > 0))][0]
        raise InputError(f"{path}: weights must be positive and finite, found {_plain(bad)!r}")
    return values


def _inside(path: Path, within, what: str) -> Path:
    """``path``, or an InputError when ``within`` is a folder and ``path``'s real location
    (symbolic links followed) is not inside it (see :func:`read_nurbs`)."""
    if within is not None:
        root, real = Path(within).resolve(), Path(path).resolve()
        if real != root and root not in real.parents:
            raise InputError(f"{Path(path).name}: the {what} lies outside {root.name}/, the only folder read here")
    return path


def _side_json(path: Path, meta, within=None) -> tuple[dict, Path | None]:
    if meta is None:
        for candidate in (path.with_name(path.name + ".json"),):
            if candidate.is_file():
                meta = candidate
                break
    if meta is None:
        return {}, None
    if isinstance(meta, dict):
        return dict(meta), path.parent
    meta = _inside(Path(meta), within, "side JSON")
    check_readable(meta)
    data = _load_json(meta)
    if not isinstance(data, dict):
        raise InputError(f"{meta}: side JSON must be an object with sizes, degrees, knot_vectors")
    return data, meta.parent


_CTRL_OPTIONS = {"sizes", "degrees", "knot_vectors", "weights", "kind", "meta"}


def _resolve(path: Path, options: dict, count: int, default_kind: str | None = None, within=None):
    unknown = set(options) - _CTRL_OPTIONS
    if unknown:
        raise OptionError(f"{path}: unknown options {sorted(unknown)}; allowed: {sorted(_CTRL_OPTIONS)}")
    side, base = _side_json(path, options.get("meta"), within)
    merged = {k: side[k] for k in ("sizes", "degrees", "knot_vectors", "weights", "kind") if k in side}
    merged.update({k: v for k, v in options.items() if k != "meta"})
    if "weights" in merged and isinstance(merged["weights"], str) and base is not None and "weights" not in options:
        merged["weights"] = str(_inside(base / merged["weights"], within, "weights file its side JSON names"))
    kv = merged.get("knot_vectors")
    if kv is not None:
        kv = [None if k is None else np.asarray(k, dtype=np.float64).ravel() for k in kv]
    degrees = merged.get("degrees")
    if degrees is not None:
        degrees = whole_numbers(path, degrees, "degrees")
    sizes = merged.get("sizes")
    if sizes is not None:
        sizes = whole_numbers(path, sizes, "sizes")
    if degrees is None and kv is not None and all(k is not None for k in kv):
        degrees = [int(np.sum(k == k[0])) - 1 for k in kv]
    if sizes is None and kv is not None and degrees is not None and all(k is not None for k in kv):
        sizes = [k.size - p - 1 for k, p in zip(kv, degrees)]
    if sizes is None and default_kind == "curve":
        sizes = [count]
    if sizes is None:
        raise OptionError(
            f"{path}: the control-point file holds {count} points but not how they form a grid; "
            "give sizes (e.g. --sizes 14 13), or knot vectors, as options or in a side JSON "
            f"({path.name}.json)"
        )
    sizes = [int(s) for s in sizes]
    if min(sizes, default=0) < 1:
        raise OptionError(f"{path}: sizes must be positive, got {sizes}")
    kind = merged.get("kind") or _KIND_BY_DIM.get(len(sizes))
    if kind not in _CLASSES or {"curve": 1, "surface": 2, "volume": 3}[kind] != len(sizes):
        raise OptionError(f"{path}: sizes {sizes} do not describe a {kind}")
    if int(np.prod(sizes)) != count:
        raise InputError(f"{path}: holds {count} control points but sizes {sizes} need {int(np.prod(sizes))}")
    if degrees is None:
        raise OptionError(f"{path}: degrees are needed (e.g. --degrees 3 3), as an option or in a side JSON")
    degrees = [int(d) for d in degrees]
    if len(degrees) != len(sizes):
        raise OptionError(f"{path}: {len(sizes)} sizes but {len(degrees)} degrees")
    return kind, sizes, degrees, kv, merged.get("weights", _AUTO)


def _weights_for(path: Path, spec, count: int, within=None) -> np.ndarray | None:
    if spec is _AUTO or (isinstance(spec, str) and spec == _AUTO):
        sibling = path.with_suffix(".weights")
        spec = _inside(sibling, within, "weights file beside it") if sibling.is_file() else None
    if spec is None:
        return None
    if isinstance(spec, (str, os.PathLike)):
        w = read_weights(spec)
        where = str(spec)
    else:
        w = np.asarray(spec.detach().cpu() if isinstance(spec, torch.Tensor) else spec, dtype=np.float64).ravel()
        where = "weights option"
    if w.size != count:
        raise InputError(f"{path}: {where} has {w.size} weights for {count} control points")
    return w


def _read_ctrlpts(path: Path, options: dict, within=None) -> TensorSpline:
    from .text import read_table

    table = read_table(path)
    if table.shape[1] not in (2, 3):
        raise InputError(f"{path}: .ctrlpts lines need 2 or 3 numbers (x y [z]), found {table.shape[1]}")
    kind, sizes, degrees, kv, wspec = _resolve(path, options, table.shape[0], within=within)
    weights = _weights_for(path, wspec, table.shape[0], within)
    return _assemble(kind, table, weights, sizes, degrees, kv)


def _read_cptw(path: Path, options: dict, within=None) -> TensorSpline:
    text = read_bytes(path).decode("ascii", errors="replace")
    rows = [r.strip().rstrip(";") for r in text.splitlines() if r.strip() and not r.lstrip().startswith(("#", "%"))]
    if not rows:
        raise InputError(f"{path}: holds no control points")
    grid = []
    for i, row in enumerate(rows, start=1):
        try:
            grid.append([[float(c) for c in p.split(",") if c.strip()] for p in row.split(";")])
        except ValueError:
            raise InputError(f"{path}: line {i} is not 'x,y,z,w;x,y,z,w;...': {row[:60]!r}") from None
    per_row = {len(r) for r in grid}
    width = {len(p) for r in grid for p in r}
    if len(per_row) != 1 or len(width) != 1:
        raise InputError(f"{path}: every line needs the same number of points and every point the same number of values")
    width = width.pop()
    if width not in (3, 4):
        raise InputError(f"{path}: cptw points are x*w,y*w,w or x*w,y*w,z*w,w (3 or 4 values), found {width}")
    cpw = np.asarray(grid, dtype=np.float64).reshape(-1, width)
    n_rows, n_cols = len(grid), per_row.pop()
    opts = dict(options)
    if "sizes" not in opts and not (opts.get("meta") or path.with_name(path.name + ".json").is_file()):
        opts["sizes"] = [n_rows] if n_cols == 1 else [n_rows, n_cols]
    kind, sizes, degrees, kv, wspec = _resolve(path, opts, cpw.shape[0], within=within)
    w = cpw[:, -1]
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise InputError(f"{path}: weights (the last value of each point) must be positive")
    return _assemble(kind, cpw[:, :-1] / w[:, None], w, sizes, degrees, kv)


def _read_smesh(path: Path) -> TensorSpline:
    lines = [ln.split() for ln in read_bytes(path).decode("ascii", errors="replace").splitlines() if ln.strip()]
    try:
        dim = int(lines[0][0])
        p, q = int(lines[1][0]), int(lines[1][1])
        nu, nv = int(lines[2][0]), int(lines[2][1])
        ku = np.array(lines[3], dtype=np.float64)
        kv = np.array(lines[4], dtype=np.float64)
    except (IndexError, ValueError):
        raise InputError(f"{path}: not an smesh file (expected dimension, degrees, sizes, two knot vectors)") from None
    if dim != 3:
        raise InputError(f"{path}: smesh dimension must be 3, got {dim}")
    # geomdl reads the first n_u * n_v lines and ignores what follows (NURBS-Diff's roof has two more)
    body = lines[5: 5 + nu * nv]
    if len(body) != nu * nv:
        raise InputError(f"{path}: smesh sizes {nu} x {nv} need {nu * nv} control point lines, found {len(body)}")
    try:
        table = np.array(body, dtype=np.float64)
    except ValueError:
        raise InputError(f"{path}: smesh control point lines must each be 'x y z w'") from None
    if table.ndim != 2 or table.shape[1] != 4:
        raise InputError(f"{path}: smesh control point lines must each be 'x y z w'")
    # file order: u fastest, i.e. the lines are the (n_v, n_u) table of the (u, v) net transposed
    table = table.reshape(nv, nu, 4).transpose(1, 0, 2)
    return _assemble("surface", *to_geomdl_order(table[..., :3], table[..., 3]), [nu, nv], [p, q], [ku, kv])


# ---- writing ------------------------------------------------------------------------

def write_nurbs(path: str | os.PathLike, obj: TensorSpline, *, format: str | None = None) -> list[Path]:
    """Write a curve, surface or volume; the format follows the extension (or ``format``).

    '.json' writes nurbskit JSON (``format='geomdl'`` writes geomdl's JSON); '.ctrlpts'
    writes the points, a ``.weights`` file when rational, and the side JSON
    ``<file>.json`` with sizes, degrees and knots, so that :func:`read_nurbs` reads it
    back; '.cptw' the same with weighted points; '.smesh'/'.dat' smesh (surfaces in 3-D);
    '.3dm' Rhino (curves and surfaces). Every file is written atomically.

    Returns:
        The paths written.
    """
    path = Path(path)
    if not isinstance(obj, TensorSpline):
        raise OptionError(f"write_nurbs needs a NURBSCurve, NURBSSurface or NURBSVolume, got {type(obj).__name__}")
    if path.is_dir():
        raise OptionError(f"{path}: is a directory, expected a file name")
    ext = path.suffix.lower()
    fmt = format or {".json": "nurbskit", ".ctrlpts": "ctrlpts", ".cptw": "cptw", ".smesh": "smesh",
                     ".dat": "smesh", ".3dm": "3dm", **dict.fromkeys(_CAD_EXTENSIONS, "cad")}.get(ext)
    if fmt not in NURBS_FORMATS:
        raise OptionError(
            f"{path}: cannot write NURBS as {ext or '(no extension)'!r}; use .json, .ctrlpts, .cptw, .smesh/.dat or .3dm"
        )
    if fmt == "nurbskit":  # the one format that holds a batch
        save(obj, path)
        return [path]
    obj.require_single(f"writing {path.name} ({fmt})")
    if fmt == "geomdl":
        with atomic_open(path, "w") as handle:
            json.dump(to_geomdl_json(obj), handle, indent=1)
        return [path]
    if fmt == "3dm":
        from .cad import write_3dm

        write_3dm(path, obj)
        return [path]
    if fmt == "cad":
        from .cad import write_cad

        write_cad(obj, path)
        return [path]
    if fmt == "smesh":
        return [_write_smesh(path, obj)]
    return _write_ctrl(path, obj, fmt)


def to_geomdl_json(obj: TensorSpline) -> dict:
    """geomdl's JSON structure (``exchange.export_json``) for one object."""
    obj.require_single("to_geomdl_json")
    points, weights = _flatten(obj)
    axes = {"curve": [""], "surface": ["_u", "_v"], "volume": ["_u", "_v", "_w"]}[obj.kind]
    item = {"type": "spline", "rational": bool(obj.is_rational), "dimension": obj.dim}
    for a, p, kv, n in zip(axes, obj.degrees, obj.knot_vectors, obj.sizes):
        item["degree" + a] = int(p)
        item["knotvector" + a] = kv.detach().cpu().double().tolist()
        if obj.kind != "curve":
            item["size" + a] = int(n)
    item["control_points"] = {"points": points.tolist(), "weights": weights.tolist()}
    return {"shape": {"type": obj.kind, "count": 1, "data": [item]}}


def _side(obj: TensorSpline, weights_file: str | None) -> dict:
    return {
        "format": "nurbskit-ctrlpts", "kind": obj.kind, "sizes": list(obj.sizes),
        "degrees": list(obj.degrees),
        "knot_vectors": [kv.detach().cpu().double().tolist() for kv in obj.knot_vectors],
        "weights": weights_file,
        "order": "geomdl: surfaces v fastest (line iu*n_v + iv); volumes w outermost, then u, then v",
    }


def _write_ctrl(path: Path, obj: TensorSpline, fmt: str) -> list[Path]:
    """The control points (``.ctrlpts``, with a ``.weights`` file when rational, or weighted
    ``.cptw``) and the side JSON, written as one set: all or none."""
    from .text import format_rows

    if obj.dim not in (2, 3):
        raise OptionError(f"{path}: .{fmt} lines hold 2-D or 3-D points; this {obj.kind}'s are {obj.dim}-D")
    points, weights = _flatten(obj)
    files: dict[Path, bytes] = {}
    weights_name = None
    if fmt == "ctrlpts":
        data = format_rows([points[:, i] for i in range(points.shape[1])], "f" * points.shape[1])
        if obj.is_rational:
            wpath = path.with_suffix(".weights")
            files[wpath] = (",".join(repr(float(w)) for w in weights) + "\n").encode()
            weights_name = wpath.name
    else:
        cpw = np.concatenate([points * weights[:, None], weights[:, None]], axis=1)
        if obj.kind == "surface":
            nu, nv = obj.sizes
            rows = [";".join(",".join(repr(float(c)) for c in cpw[iu * nv + iv]) for iv in range(nv)) for iu in range(nu)]
        else:
            rows = [",".join(repr(float(c)) for c in pt) for pt in cpw]
        data = ("\n".join(rows) + "\n").encode()
    side = _side(obj, weights_name if fmt == "ctrlpts" else None)
    if fmt == "cptw":
        side.pop("weights")
    spath = path.with_name(path.name + ".json")
    files = {path: data, **files, spath: json.dumps(side, indent=1).encode()}
    with atomic_paths(list(files)) as temps:
        for tmp, content in zip(temps, files.values()):
            tmp.write_bytes(content)
    return list(files)


def _write_smesh(path: Path, obj: TensorSpline) -> Path:
    if obj.kind != "surface" or obj.dim != 3:
        raise OptionError(f"{path}: smesh holds surfaces in 3-D; got a {obj.kind} in {obj.dim}-D")
    cp = obj.control_points.detach().cpu().double().numpy()
    w = obj.weights.detach().cpu().double().numpy()
    nu, nv = obj.sizes
    rows = np.concatenate([cp, w[..., None]], axis=-1).transpose(1, 0, 2).reshape(-1, 4)  # u fastest
    lines = ["3", f"{obj.degrees[0]} {obj.degrees[1]}", f"{nu} {nv}"]
    lines += [" ".join(repr(float(k)) for k in kv.detach().cpu().double().tolist()) for kv in obj.knot_vectors]
    lines += [" ".join(repr(float(c)) for c in row) for row in rows]
    with atomic_open(path, "w") as handle:
        handle.write("\n".join(lines) + "\n")
    return path
