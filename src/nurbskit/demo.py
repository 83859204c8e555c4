"""``make demo``: the thesis duck, evaluated and exported, and a surface fitted to a point cloud.

Run as ``python -m nurbskit.demo --out out``. It writes

* ``out/duck/``: the duck body of the thesis (14 x 13 control points, degree 3, two
  weights of 0.5) as nurbskit JSON (``duck.json``), its evaluation on a 64 x 64 grid
  (``duck_points.off``) and a tessellated mesh (``duck.obj``);
* ``out/fit/``: our default pipeline fitted to a 900-point Poisson-disk sample of the
  duck (the thesis's unsupervised input), with everything ``nurbskit fit`` writes.

The duck comes from ``<data>/thesis_nurbsdiff/ducky``, where ``<data>`` is ``--data``,
else the environment variable ``NURBSKIT_DATA``, else ``../shared/data`` relative to
the working directory (``make demo`` runs in the repository's root); never a path
derived from where this file is installed. Without that folder a built-in closed shape
(a bumpy egg) stands in for the duck, written to ``out/egg/`` as ``egg.*``. Every run
replaces those folders and ``out/fit``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from .core import NURBSSurface

#: The data folder relative to the working directory when neither --data nor NURBSKIT_DATA says.
DEFAULT_DATA = Path("..") / "shared" / "data"
DUCK_SIZES = (14, 13)


def data_root(given: str | os.PathLike | None = None) -> Path:
    """The data folder: ``given``, else ``$NURBSKIT_DATA``, else ``../shared/data`` from the working directory."""
    if given:
        return Path(given)
    env = os.environ.get("NURBSKIT_DATA")
    return Path(env) if env else DEFAULT_DATA


def thesis_data_dir(root: Path) -> Path | None:
    """``<root>/thesis_nurbsdiff`` when present."""
    d = Path(root) / "thesis_nurbsdiff"
    return d if d.is_dir() else None


def load_duck(thesis_dir: Path, dtype: torch.dtype = torch.float64) -> NURBSSurface:
    """The duck body (duck1) with its knots rescaled to [0, 1] as in NURBS-Diff's example."""
    from .io import read_nurbs

    ducky = Path(thesis_dir) / "ducky"
    meta = json.loads((ducky / "duck_knots.json").read_text())["duck1_body"]
    kvs = [meta["knotvector_u_normalized"], meta["knotvector_v_normalized"]]
    return read_nurbs(
        ducky / "duck1.ctrlpts", sizes=list(DUCK_SIZES), degrees=[meta["degree_u"], meta["degree_v"]],
        knot_vectors=kvs, weights=str(ducky / "duck1.weights"), dtype=dtype,
    )


def builtin_shape(dtype: torch.dtype = torch.float64) -> NURBSSurface:
    """A closed stand-in for the duck: a bumpy egg, 12 x 11 control points, closed in v.

    Rows run from pole to pole along x; columns go around (the last equals the first),
    like the duck's control net.
    """
    n_u, n_v = 12, 11
    s = torch.linspace(0, 1, n_u, dtype=dtype)
    ang = torch.linspace(0, 2 * math.pi, n_v, dtype=dtype)
    radius = torch.sin(math.pi * s) * (1 + 0.25 * s)
    bump = 1 + 0.15 * torch.cos(3 * ang)[None, :] * torch.sin(math.pi * s)[:, None]
    x = (2.0 * s - 1.0)[:, None].expand(n_u, n_v)
    y = radius[:, None] * bump * torch.cos(ang)[None, :]
    z = 0.8 * radius[:, None] * bump * torch.sin(ang)[None, :]
    cp = torch.stack([x, y, z], dim=-1).clone()
    cp[:, -1] = cp[:, 0]
    return NURBSSurface(cp, (3, 3))


def grid_mesh(surface: NURBSSurface, resolution: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(R*S, 3)`` float64 and triangles ``(2*(R-1)*(S-1), 3)`` of :func:`~nurbskit.core.tessellate.tessellate`."""
    from .core.tessellate import tessellate

    with torch.no_grad():
        v, f, _ = tessellate(surface, resolution)
    return v.double().cpu().numpy(), f.cpu().numpy()


def poisson_sample(surface: NURBSSurface, n: int, seed: int = 0, resolution=(128, 128)) -> np.ndarray:
    """``n`` Poisson-disk points on the surface (through a fine tessellation), fixed seed."""
    from .geometry.sampling import sample_mesh

    v, f = grid_mesh(surface, resolution)
    # Drop triangles of zero area (collapsed poles), which sampling cannot use.
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    f = f[np.linalg.norm(np.cross(e1, e2), axis=1) > 1e-14]
    return np.asarray(sample_mesh(v, f, n, method="poisson", seed=seed), dtype=np.float64)


def export_surface(surface: NURBSSurface, directory: Path, name: str, resolution=(64, 64)) -> list[str]:
    """``name.json`` (nurbskit), ``name_points.off`` (grid evaluation) and ``name.obj`` (mesh)."""
    from .core.serialize import save
    from .io import write_mesh, write_points

    save(surface, directory / f"{name}.json")
    v, f = grid_mesh(surface, resolution)
    write_points(directory / f"{name}_points.off", v)
    write_mesh(directory / f"{name}.obj", v, f)
    return [f"{name}.json", f"{name}_points.off", f"{name}.obj"]


def main(argv: list[str] | None = None) -> int:
    from ._fs import output_directory
    from .fit import fit_surface
    from .fit.outputs import write_fit_outputs

    parser = argparse.ArgumentParser(prog="python -m nurbskit.demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="out", help="output folder (its duck/ or egg/, and fit/, are replaced)")
    parser.add_argument("--data", default=None,
                        help="folder holding thesis_nurbsdiff/ (default $NURBSKIT_DATA, else ../shared/data "
                             "from the working directory)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1: the demo's problems are small, and extra threads "
                             "only add synchronisation, badly so on a busy machine)")
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    out = Path(args.out)
    t0 = time.perf_counter()

    thesis = thesis_data_dir(data_root(args.data))
    if thesis is not None:
        shape, name, source = load_duck(thesis), "duck", f"the thesis duck from {thesis / 'ducky'}"
    else:
        shape, name, source = builtin_shape(), "egg", "a built-in closed shape, a bumpy egg (../shared/data not found)"
    with output_directory(out / name, overwrite=True) as tmp:
        files = export_surface(shape, tmp, name)
    print(f"[1/2] {source}: wrote {out / name}/ ({', '.join(files)})")

    points = poisson_sample(shape, 900, seed=0)
    result = fit_surface(points, "default")
    with output_directory(out / "fit", overwrite=True) as tmp:
        report = write_fit_outputs(result, tmp, figures=not args.no_figures)
    m = report["metrics"]
    print(
        f"[2/2] default pipeline on a 900-point Poisson sample of the {name}: "
        f"input-to-surface mean {m['to_surface_mean']:.2e}, p95 {m['to_surface_p95']:.2e} of the diagonal, "
        f"{report['seconds']:.1f} s; wrote {out / 'fit'}/ ({', '.join(report['files'])})"
    )
    print(f"done in {time.perf_counter() - t0:.1f} s; results under {out.resolve()}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
