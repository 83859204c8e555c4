"""The files of a volume fit, as ``nurbskit volume`` writes them.

:func:`write_outputs` writes ``mesh.obj`` and ``mesh.ply`` (unit-cube coordinates),
``volume.json`` (nurbskit format), ``views.png`` (each drawing beside the projection of
the result) and ``report.json`` into a folder; the command and ``examples/volume_fit.py``
both call it (the command inside :func:`nurbskit._fs.output_directory`, so that the
folder appears only when complete).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .._fs import atomic_open
from ..core.serialize import save
from .figure import write_comparison_png

#: What :func:`write_outputs` writes, in order.
FILES = ("mesh.obj", "mesh.ply", "volume.json", "views.png", "report.json")


def write_outputs(result, directory: str | os.PathLike, report: dict | None = None) -> list[str]:
    """Write a :class:`~nurbskit.volume.fit.SilhouetteFit`'s files into ``directory`` (which
    must exist) -> the names written (:data:`FILES`). ``report``: the report to write
    (default ``result.report()``; the command adds its preset and inputs)."""
    from ..io import write_mesh

    d = Path(directory)
    write_mesh(d / "mesh.obj", result.mesh.vertices, result.mesh.faces)
    write_mesh(d / "mesh.ply", result.mesh.vertices, result.mesh.faces)
    save(result.volume, d / "volume.json")
    write_comparison_png(d / "views.png", result.drawings, result.projections, result.iou)
    with atomic_open(d / "report.json", "w", encoding="utf-8") as fh:
        json.dump(result.report() if report is None else report, fh, indent=2)
        fh.write("\n")
    return list(FILES)


__all__ = ["write_outputs", "FILES"]
