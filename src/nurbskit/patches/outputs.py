"""The files of one multi-patch fit.

:func:`patch_report` gathers the numbers; :func:`write_patch_outputs` writes everything
``nurbskit patches`` promises into a directory:

=========================  ==========================================================
``patches/NNN.json``       patch NNN: a nurbskit surface with its trimming loops under
                           ``trim`` (:mod:`nurbskit.core.trim`); a patch whose inliers
                           form several separate regions adds ``NNN_1.json``, ...
``patches.json``           ``{"patches": [...], "history": [...], "energy": [...]}``
``patches.ply``            the trimmed meshes of all patches, one colour per patch
``meshes/NNN.ply``         the trimmed mesh of patch NNN
``labels.txt``             the patch of every input point, -1 for outliers
``report.json``            :func:`patch_report`: metrics, planar start, timings per stage
``config.json``            the resolved :class:`~nurbskit.patches.config.PatchConfig`
``planar.png``             the planar start, points coloured by region
``patches.png``            the final patches, points coloured by patch
``energy.png``             the energy U after each accepted merge
=========================  ==========================================================
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._fs import atomic_open
from .config import config_to_dict
from .driver import PatchSet


def palette(count: int) -> np.ndarray:
    """``(count, 3)`` uint8 colours, distinct for neighbours in index order (golden-ratio hues)."""
    import colorsys

    return np.array(
        [[int(255 * c) for c in colorsys.hsv_to_rgb((0.61803398875 * i) % 1.0, 0.65, 0.95)] for i in range(count)],
        dtype=np.uint8,
    ).reshape(-1, 3)


def patch_report(result: PatchSet) -> dict:
    """The numbers of a multi-patch fit, JSON-ready."""
    return {
        "points": int(len(result.points)),
        "eps": float(result.config.eps),
        "eps_units": float(result.eps),
        "metrics": result.metrics,
        "planar_start": result.planar,
        "timings": {k: float(v) for k, v in result.timings.items()},
        "seconds": float(sum(result.timings.values())),
        "counts": result.counts,
        "patches": [p.summary() for p in result.patches],
    }


def _dump(path: Path, data) -> None:
    with atomic_open(path, "w") as fh:
        json.dump(data, fh, indent=1)
        fh.write("\n")


def write_patch_outputs(result: PatchSet, directory, *, figures: bool = True, extra: dict | None = None) -> dict:
    """Write the files of the module docstring to ``directory``; return the report (with ``files``)."""
    from ..io import write_mesh

    out = Path(directory)
    (out / "patches").mkdir(parents=True, exist_ok=True)
    (out / "meshes").mkdir(exist_ok=True)
    colours = palette(len(result.patches))
    entries = []
    all_v, all_f, all_c, offset = [], [], [], 0
    for i, patch in enumerate(result.patches):
        names = []
        for k, face in enumerate(patch.faces):
            name = f"patches/{i:03d}.json" if k == 0 else f"patches/{i:03d}_{k}.json"
            _dump(out / name, face.to_dict())
            names.append(name)
        v, f = patch.mesh
        mesh_name = f"meshes/{i:03d}.ply"
        if len(f):
            write_mesh(out / mesh_name, v, f, colors=np.repeat(colours[i : i + 1], len(v), 0))
            all_v.append(v)
            all_f.append(f + offset)
            all_c.append(np.repeat(colours[i : i + 1], len(v), 0))
            offset += len(v)
        entries.append({"index": i, "files": names, "mesh": mesh_name, "colour": colours[i].tolist(), **patch.summary()})
    if all_f:
        write_mesh(out / "patches.ply", np.concatenate(all_v), np.concatenate(all_f), colors=np.concatenate(all_c))
    _dump(out / "patches.json", {"patches": entries, "history": result.history, "energy": result.energy})
    with atomic_open(out / "labels.txt", "w") as fh:
        fh.write("\n".join(str(int(x)) for x in result.labels) + "\n")
    report = patch_report(result)
    if extra:
        report.update(extra)
    _dump(out / "config.json", config_to_dict(result.config))
    files = ["patches/", "meshes/", "patches.json", "labels.txt", "report.json", "config.json"]
    if all_f:
        files.insert(2, "patches.ply")
    if figures:
        from .figures import plot_energy, plot_labels

        plot_labels(result.points, result.planar_labels, out / "planar.png",
                    f"planar start: {result.planar['planes']} planes, {result.planar['coverage']:.1f} % of the points")
        plot_labels(result.points, result.labels, out / "patches.png",
                    f"{len(result.patches)} patches, completeness {result.metrics['completeness']:.1f} %")
        plot_energy(result.energy, out / "energy.png")
        files += ["planar.png", "patches.png", "energy.png"]
    report["files"] = files
    _dump(out / "report.json", report)
    return report
