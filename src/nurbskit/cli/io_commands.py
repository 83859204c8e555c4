"""``nurbskit info``, ``nurbskit convert`` and ``nurbskit sample``: files in and out.

Examples::

    nurbskit info scan.pcd --json
    nurbskit convert bunny.obj bunny.ply
    nurbskit convert duck1.ctrlpts duck1.json --sizes 14 13 --degrees 3 3
    nurbskit sample bunny.obj -n 100000 --method poisson --seed 0 -o bunny_100k.ply

Every output is written atomically (temporary file, then rename), so pressing Ctrl-C
never leaves a damaged or half-written file; an output that is one of the inputs is
refused (``io._base.check_not_input``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError
from ._options import int_in


def register(subparsers) -> None:
    p = subparsers.add_parser("info", help="describe a point, mesh or NURBS file",
                              description="Kind, counts, bounding box and attributes of a point, mesh or NURBS file.")
    p.add_argument("file", help="the file to describe")
    p.add_argument("--json", action="store_true", help="print JSON (kind, num_points, num_faces, bbox, attributes, ...)")
    _nurbs_options(p)
    p.set_defaults(run=run_info)

    p = subparsers.add_parser("convert", help="convert points, meshes or NURBS files by extension",
                              description="Read IN and write OUT in the format of OUT's extension. "
                                          "Points: .ply .pcd .xyz .txt .csv .xyzc .pts .npy .npz .off .obj; "
                                          "meshes: .ply .off .obj .stl .npz; NURBS: .json .ctrlpts .cptw .smesh .dat .3dm.")
    p.add_argument("input", metavar="IN", help="file to read")
    p.add_argument("output", metavar="OUT", help="file to write (its extension picks the format)")
    p.add_argument("--ascii", action="store_true", help="write text PLY / STL / PCD instead of binary")
    p.add_argument("--pcd-data", choices=("binary", "ascii", "binary_compressed"), default=None,
                   help="PCD data section (default binary)")
    p.add_argument("--geomdl", action="store_true", help="write geomdl's JSON instead of nurbskit JSON for .json")
    _nurbs_options(p)
    p.set_defaults(run=run_convert)

    p = subparsers.add_parser("sample", help="sample points on a mesh (Poisson-disk or uniform) or a NURBS surface",
                              description="Sample N points on a triangle mesh and write them as a point file. "
                                          "Given a NURBS file instead, sample it on a uniform parametric grid "
                                          "(the thesis's parametric sampling).")
    p.add_argument("mesh", metavar="MESH", help="triangle mesh to sample (or a NURBS file: .json, .ctrlpts, ...)")
    p.add_argument("-n", type=int, default=None, help="number of points (meshes: required; NURBS: about n, on a grid)")
    p.add_argument("--method", choices=("poisson", "uniform"), default=None,
                   help="poisson: blue noise, well spread (default); uniform: independent, area-weighted")
    p.add_argument("--seed", type=int_in(0), default=None, metavar="SEED",
                   help="random seed, a non-negative integer (default: fresh entropy)")
    p.add_argument("--grid", type=int, nargs="+", metavar="R", help="NURBS: samples per parametric direction")
    p.add_argument("-o", "--output", required=True, help="point file to write (.ply, .xyz, .pcd, .npy, ...)")
    p.add_argument("--no-normals", action="store_true", help="do not write the normal of each sample")
    _nurbs_options(p)
    p.set_defaults(run=run_sample)


def _nurbs_options(p) -> None:
    g = p.add_argument_group("control-point files (.ctrlpts, .cptw)")
    g.add_argument("--sizes", type=int, nargs="+", help="control points per direction, e.g. 14 13")
    g.add_argument("--degrees", type=int, nargs="+", help="degree per direction, e.g. 3 3")
    g.add_argument("--weights", help="a .weights file (default: the one beside the .ctrlpts file, if any)")
    g.add_argument("--meta", help="side JSON with sizes, degrees, knot_vectors (default: FILE.json if present)")


def _nurbs_kwargs(args) -> dict:
    out = {}
    for key in ("sizes", "degrees", "weights", "meta"):
        value = getattr(args, key, None)
        if value is not None:
            out[key] = value
    return out


def _progress(total: int, desc: str):
    from tqdm import tqdm

    # tqdm hides itself when stderr is not a terminal (disable=None)
    return tqdm(total=total, desc=desc, unit="step", disable=None, file=sys.stderr, leave=False)


# ---- info ---------------------------------------------------------------------------

def describe(path: str | Path, **nurbs_options) -> dict:
    """What ``nurbskit info`` reports about a file, as a dict.

    Keys: ``file``, ``format``, ``kind`` ('points', 'mesh', 'curve', 'surface', 'volume'),
    ``num_points``, ``num_faces`` (meshes), ``bbox`` ([[min x, y, z], [max x, y, z]]),
    ``attributes``; NURBS files add ``sizes``, ``degrees``, ``rational``, ``domain``.
    """
    from ..io import formats
    from ..io.nurbs import is_nurbs_file, nurbs_format, read_nurbs

    path = Path(path)
    formats.check_readable(path)
    if path.suffix.lower() in (".step", ".stp", ".iges", ".igs", ".brep", ".brp"):  # CAD files: io/cad
        from ..io.cad import cad_info

        return cad_info(path)
    if is_nurbs_file(path):
        fmt = nurbs_format(path)
        try:
            obj = read_nurbs(path, **nurbs_options)
        except OptionError:
            if nurbs_options or fmt != "ctrlpts":
                raise
            # a bare .ctrlpts file: describe the points; the grid needs --sizes/--degrees
            from ..io.text import read_table

            table = read_table(path)
            return {
                "file": str(path), "format": fmt, "kind": "control points", "num_points": int(table.shape[0]),
                "bbox": [table.min(axis=0).tolist(), table.max(axis=0).tolist()], "attributes": [],
                "note": "sizes and degrees unknown: pass --sizes and --degrees, or a side JSON, to read it as NURBS",
            }
        cp = obj.control_points.detach().cpu().double().numpy().reshape(-1, obj.dim)
        return {
            "file": str(path), "format": fmt if fmt != "json" else "json", "kind": obj.kind,
            "num_points": int(cp.shape[0]), "sizes": list(obj.sizes), "degrees": list(obj.degrees),
            "dim": obj.dim, "rational": bool(obj.is_rational),
            "domain": [list(d) for d in obj.domain],
            "bbox": [cp.min(axis=0).tolist(), cp.max(axis=0).tolist()],
            "attributes": ["weights"] if obj.is_rational else [],
        }
    payload = formats.read_payload(path)
    pts = payload.points
    finite = np.isfinite(pts).all(axis=1)
    good = pts[finite]
    pcd = payload.info.get("format", "").startswith("pcd")
    if not pcd:  # NaN marks holes only in PCD; elsewhere it is damage, refused as read_points does
        from ..io._base import check_finite

        check_finite(path, pts, "vertices" if payload.faces is not None else "points")
    info = {
        "file": str(path), "format": payload.info.get("format", "?"),
        "kind": "mesh" if payload.faces is not None and payload.faces.shape[0] else "points",
        # for PCD, the points read_points returns: NaN holes are not points
        "num_points": int(finite.sum() if pcd else pts.shape[0]),
        "num_faces": int(0 if payload.faces is None else payload.faces.shape[0]),
        "bbox": [good.min(axis=0).tolist(), good.max(axis=0).tolist()] if good.size else None,
        "attributes": [n for n in ("normals", "colors", "labels") if getattr(payload, n) is not None],
    }
    if not finite.all():
        info["dropped_nan_points"] = int((~finite).sum())
    if payload.labels is not None:  # of the points counted (a PCD's NaN holes carry a label too)
        labels = np.asarray(payload.labels).reshape(-1)
        info["num_labels"] = int(np.unique(labels[finite] if pcd and labels.shape[0] == pts.shape[0] else labels).size)
    for key in ("width", "height"):
        if key in payload.info:
            info[key] = payload.info[key]
    return info


def run_info(args) -> int:
    info = describe(args.file, **_nurbs_kwargs(args))
    if args.json:
        sys.stdout.write(json.dumps(info, indent=1) + "\n")
        return 0
    if info["kind"] == "cad":
        from ..io.cad.exchange import format_cad_info

        sys.stdout.write(format_cad_info(info))
        return 0
    lines = [f"{info['file']}", f"  format      {info['format']}", f"  kind        {info['kind']}"]
    if info["kind"] in ("points", "mesh"):
        lines.append(f"  points      {info['num_points']:,}")
        if info["kind"] == "mesh":
            lines.append(f"  faces       {info['num_faces']:,}")
        if "dropped_nan_points" in info:
            lines.append(f"  NaN holes   {info['dropped_nan_points']:,} (not counted as points; read_points drops them)")
    elif info["kind"] == "control points":
        lines.append(f"  points      {info['num_points']:,}")
        lines.append(f"  note        {info['note']}")
    else:
        lines.append(f"  control pts {info['num_points']:,} ({' x '.join(map(str, info['sizes']))}), "
                     f"degrees {tuple(info['degrees'])}, {'rational' if info['rational'] else 'non-rational'}")
        lines.append(f"  domain      {info['domain']}")
    if info.get("bbox"):
        lo, hi = info["bbox"]
        lines.append("  bbox min    " + " ".join(f"{x:.6g}" for x in lo))
        lines.append("  bbox max    " + " ".join(f"{x:.6g}" for x in hi))
    lines.append(f"  attributes  {', '.join(info['attributes']) or 'none'}")
    if "num_labels" in info:
        lines.append(f"  labels      {info['num_labels']} distinct")
    sys.stdout.write("\n".join(lines) + "\n")
    return 0


# ---- convert ------------------------------------------------------------------------

def _note(command: str, left_out: list[str], out: Path) -> None:
    if left_out:
        sys.stderr.write(f"nurbskit {command}: note: {out.suffix or out.name} cannot store "
                         f"{', '.join(left_out)}; left out of {out}\n")


def _inputs(args, src) -> list:
    """Every file a command reads: ``src``, and for control-point files the weights and side
    JSON given or found beside it (see :func:`nurbskit.io.read_nurbs`)."""
    src = Path(src)
    found = [src, getattr(args, "weights", None), getattr(args, "meta", None)]
    ext = src.suffix.lower()
    if ext in (".ctrlpts", ".cptw"):  # a .cptw holds its weights: only a .ctrlpts reads a .weights beside it
        beside = [src.with_name(src.name + ".json")] + ([src.with_suffix(".weights")] if ext == ".ctrlpts" else [])
        found += [p for p in beside if p.is_file()]
    return found


def _one_untrimmed_object(src: Path, out: Path):
    """The one NURBS object of a CAD file (STEP, IGES, BREP, .3dm), which ``convert``
    writes; a file of several faces or curves, or of a trimmed face, is refused (read as
    its first face, untrimmed, it would lose the rest)."""
    from ..io.cad import read_objects

    found = read_objects(src)
    if len(found) > 1 or getattr(found[0], "loops", None):
        what = f"{len(found)} faces and curves" if len(found) > 1 else "a trimmed face"
        raise OptionError(f"{src}: holds {what}; convert writes one untrimmed NURBS object: "
                          f"`nurbskit export {src} {out.with_suffix('.json')}` keeps every face with its trim")
    return found[0]  # float64, as read_nurbs returns it


def run_convert(args) -> int:
    from ..io import formats
    from ..io.mesh import write_mesh
    from ..io.nurbs import _no_options, is_nurbs_file, read_nurbs, write_nurbs
    from ..io.points import write_points

    from ..io._base import check_not_input

    src, out = Path(args.input), Path(args.output)
    formats.check_readable(src)
    out_ext = out.suffix.lower()
    if out.is_dir():
        raise OptionError(f"{out}: is a directory, expected an output file name")
    # write_nurbs puts a side JSON beside a .ctrlpts / .cptw output, and a .ctrlpts a .weights file
    outputs = [out] + ([out.with_name(out.name + ".json")] if out_ext in (".ctrlpts", ".cptw") else []) \
        + ([out.with_suffix(".weights")] if out_ext == ".ctrlpts" else [])
    for written in outputs:
        check_not_input(written, _inputs(args, src))
    if args.pcd_data is not None and out_ext != ".pcd":
        raise OptionError(f"--pcd-data applies to a .pcd output, not {out_ext or 'no extension'!r}")
    if args.geomdl and out_ext != ".json":
        raise OptionError(f"--geomdl applies to a .json output (geomdl's JSON), not {out_ext or 'no extension'!r}")
    if args.ascii and out_ext not in (".ply", ".stl", ".pcd"):
        raise OptionError(f"--ascii applies to .ply, .stl and .pcd outputs; {out_ext or 'no extension'!r} has one form")
    with _progress(2, "convert") as bar:
        if is_nurbs_file(src):
            if src.suffix.lower() in (".step", ".stp", ".iges", ".igs", ".brep", ".3dm"):
                _no_options(src, _nurbs_kwargs(args))
                obj = _one_untrimmed_object(src, out)  # the file read once
            else:
                obj = read_nurbs(src, **_nurbs_kwargs(args))
            bar.update(1)
            if out_ext not in (".json", ".ctrlpts", ".cptw", ".smesh", ".dat", ".3dm"):
                raise OptionError(
                    f"{out}: a NURBS file converts to .json, .ctrlpts, .cptw, .smesh/.dat or .3dm, not {out_ext or 'no extension'!r}"
                )
            write_nurbs(out, obj, format="geomdl" if args.geomdl and out_ext == ".json" else None)
            bar.update(1)
            return 0
        if _nurbs_kwargs(args):
            raise OptionError("--sizes, --degrees, --weights and --meta apply to control-point files only")
        payload = formats.read_payload(src)
        bar.update(1)
        faces = payload.faces if payload.faces is not None and payload.faces.shape[0] else None
        if faces is not None and out_ext in formats.MESH_WRITE:
            from ..io._base import check_finite

            check_finite(src, payload.points, "vertices")
            left = write_mesh(out, payload.points, faces, payload.normals, payload.colors,
                              **({"binary": not args.ascii} if out_ext in (".ply", ".stl") else {}))
            if payload.labels is not None:
                left = left + ["labels"]
        else:
            if out_ext == ".stl":
                raise InputError(f"{src}: has no faces; STL holds triangles only")
            from ..io.points import cloud_from_payload

            # the NaN policy of read_points: PCD holes dropped, other NaN refused
            cloud = cloud_from_payload(src, payload)
            options = {}
            if out_ext == ".ply":
                options["binary"] = not args.ascii
            if out_ext == ".pcd":
                options["data"] = args.pcd_data or ("ascii" if args.ascii else "binary")
            left = write_points(out, cloud.points, cloud.normals, cloud.colors, cloud.labels, **options)
            if faces is not None:
                left = ["faces"] + left
        bar.update(1)
    _note("convert", left, out)
    return 0


# ---- sample -------------------------------------------------------------------------

def run_sample(args) -> int:
    from ..geometry.sampling import sample_mesh
    from ..io.mesh import read_mesh
    from ..io.points import write_points

    from ..io._base import check_not_input
    from ..io.nurbs import is_nurbs_file

    if args.n is not None and args.n < 1:
        raise OptionError(f"-n must be a positive integer, got {args.n}")
    out = Path(args.output)
    check_not_input(out, _inputs(args, args.mesh), "-o")
    if is_nurbs_file(args.mesh):
        if args.method is not None:
            raise OptionError("--method applies to meshes; a NURBS file is sampled on a uniform parameter grid")
        if args.n is not None and args.grid:
            raise OptionError("give -n (about n points) or --grid R [S [T]], not both")
        return _sample_nurbs(args, out)
    if args.n is not None:
        _check_sample_memory(args.n, args.method or "poisson")
    if args.n is None:
        raise OptionError("-n is required to sample a mesh")
    if args.grid:
        raise OptionError("--grid applies to NURBS files; a mesh is sampled with -n and --method")
    with _progress(3, "sample") as bar:
        mesh = read_mesh(args.mesh)
        bar.update(1)
        try:
            points, face = sample_mesh(mesh.vertices, mesh.faces, args.n, method=args.method or "poisson",
                                       seed=args.seed, return_faces=True)
        except InputError as exc:  # the mesh cannot be sampled: name it
            raise InputError(f"{args.mesh}: {exc}") from None
        bar.update(1)
        normals = None
        if not args.no_normals:
            tri = mesh.vertices[mesh.faces[face]]
            normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            length = np.linalg.norm(normals, axis=1, keepdims=True)
            normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
        left = write_points(out, points, normals)
        bar.update(1)
    _note("sample", [x for x in left if x != "normals"] if args.no_normals else left, out)
    return 0


#: Peak bytes per sample of ``nurbskit sample`` (measured peak resident memory over the
#: sample count, 0.5 to 2 million samples of the bunny and 2,000^2 grids of the duck,
#: rounded up): the Poisson elimination keeps candidate sets and their neighbour lists
#: (about 2.2 KB), uniform sampling the points, faces and barycentric coordinates, a NURBS
#: grid the basis products, points, normals and the written copy (about 490 bytes).
SAMPLE_BYTES = {"poisson": 2400, "uniform": 400, "grid": 560}


def _check_sample_memory(n: int, method: str, option: str | None = None) -> None:
    """Refuse a sample count before sampling when it cannot fit in memory (one line saying what fits)."""
    from .._budget import available_bytes, require_memory

    per_point = SAMPLE_BYTES[method]
    require_memory(n * per_point, f"{option or f'-n {n:,}'} ({method}, {n:,} samples)",
                   f"at most about {available_bytes() // per_point:,} samples fit")


def _sample_nurbs(args, out: Path) -> int:
    """Parametric sampling of a NURBS curve, surface or volume on a uniform grid."""
    import math

    from ..geometry.sampling import sample_parametric
    from ..io.nurbs import read_nurbs
    from ..io.points import write_points

    obj = read_nurbs(args.mesh, **_nurbs_kwargs(args))
    k = len(obj.sizes)
    if args.grid:
        if len(args.grid) != k or min(args.grid) < 1:
            raise OptionError(f"--grid needs {k} positive integer(s) for a {obj.kind}, got {args.grid}")
        grid = list(args.grid)
    elif args.n is not None:
        grid = [max(2, round(args.n ** (1.0 / k)))] * k
    else:
        raise OptionError("give -n (about n points) or --grid R [S [T]] to sample a NURBS file")
    option = f"--grid {' '.join(map(str, grid))}" if args.grid else f"-n {args.n:,}"
    if math.prod(grid) > 50_000_000:
        raise OptionError(f"{option} asks for {math.prod(grid):,} points; at most 50,000,000")
    _check_sample_memory(math.prod(grid), "grid", option)
    if obj.dim != 3:
        raise OptionError(f"{args.mesh}: point files hold 3-D points; this {obj.kind} is {obj.dim}-D")
    points = sample_parametric(obj, grid).detach().cpu().double().numpy()
    normals = None
    if obj.kind == "surface" and not args.no_normals:
        u, v = obj.grid_axes(grid)
        normals = obj.normals_grid(u, v).reshape(-1, 3).detach().cpu().double().numpy()
    left = write_points(out, points, normals)
    _note("sample", left, out)
    return 0


__all__ = ["register", "describe", "run_info", "run_convert", "run_sample"]

