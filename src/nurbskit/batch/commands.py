"""The registry of batchable commands: what each input is, how one runs, what to report.

A :class:`BatchCommand` is everything ``nurbskit batch`` needs to know about a single
command:

* ``extensions``: which files a folder given as INPUT contributes;
* ``expand``: how one input file becomes work items (one item per file for ``fit``;
  one per CSV row for ``volume``);
* ``argv``: how an item becomes the single command's own arguments (the options after
  ``--`` are appended and parsed by that command's own ``argparse`` parser, so they mean
  exactly what they mean in the single command);
* ``metrics``: the headline numbers taken from the ``report.json`` the command wrote.

One item runs *in process* on a worker by calling the single command's ``run``
function (what ``nurbskit fit`` itself calls) with ``--out DIR/<item name>``: the
outputs are those of the single command, written the same way (built under a temporary
name by :func:`nurbskit._fs.output_directory`, renamed into place when complete).

Adding a command is a few lines: a metrics function and one ``register(BatchCommand(...))``
call (see ``patches`` at the end of this module).

Entries hold only module-level functions, so that they pickle by reference and every
worker resolves them from its own installed ``nurbskit``.
"""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path
from typing import Callable

from ..errors import InputError, OptionError


@dataclasses.dataclass(frozen=True)
class Item:
    """One unit of work: one task, one output folder ``DIR/<name>/``.

    ``inputs`` maps a role to a file (``{"input": "a.ply"}`` for fit; ``front``, ``left``
    and ``top`` for volume); ``source`` is what the user named (a file, or ``table.csv:3``).
    """

    name: str
    inputs: tuple[tuple[str, str], ...]
    source: str

    @property
    def paths(self) -> list[str]:
        return [p for _, p in self.inputs]


def one_item_per_file(path: Path) -> list[Item]:
    """The default ``expand``: the file itself is the input (name: its stem)."""
    return [Item(name=path.stem, inputs=(("input", str(path)),), source=str(path))]


def positional_argv(item: Item) -> list[str]:
    """The default ``argv``: the input file as the command's one positional argument."""
    return [item.paths[0]]


@dataclasses.dataclass(frozen=True)
class BatchCommand:
    """How ``nurbskit batch`` runs one command (see the module docstring).

    ``module`` is the CLI module whose ``register(subparsers)`` adds the parser named
    ``name``; its ``run`` default is called once per item. ``metrics(report)`` returns
    the headline numbers (floats) from the ``report.json`` the command writes.
    ``skip_names``: file names a folder search passes over although their extension is
    one of ``extensions`` (``export``: the ``report.json`` of earlier results).
    """

    name: str
    module: str
    extensions: tuple[str, ...]
    metrics: Callable[[dict], dict]
    expand: Callable[[Path], list[Item]] = one_item_per_file
    argv: Callable[[Item], list[str]] = positional_argv
    report: str = "report.json"
    description: str = ""
    skip_names: tuple[str, ...] = ()


def _number(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def fit_metrics(report: dict) -> dict:
    """``nurbskit fit``'s headline: input-to-surface distance, mean and 95th percentile,
    as fractions of the input's bounding-box diagonal (what the command prints)."""
    m = report.get("metrics", {})
    return {"to_surface_mean": _number(m.get("to_surface_mean")), "to_surface_p95": _number(m.get("to_surface_p95"))}


def volume_metrics(report: dict) -> dict:
    """``nurbskit volume``'s headline: intersection over union per view and their mean."""
    iou = report.get("iou", {})
    out = {f"iou_{view}": _number(iou.get(view)) for view in ("front", "left", "top")}
    out["mean_iou"] = _number(report.get("mean_iou"))
    return out


def patches_metrics(report: dict) -> dict:
    """``nurbskit patches``'s headline: |N|, completeness, P_cov^i and P_cov^o (percent)."""
    m = report.get("metrics", {})
    return {"patches": _number(m.get("N")), "completeness": _number(m.get("completeness")),
            "p_cov_in": _number(m.get("P_cov_i")), "p_cov_out": _number(m.get("P_cov_o"))}


def shape_metrics(report: dict) -> dict:
    """``nurbskit shape``'s headline: the kind fitted (``revolution``, ``extrusion`` or the
    free-form fallback of ``--kind auto``: a label, counted per kind in the aggregate) and
    the input-to-surface distance, mean and p95, as fractions of the diagonal."""
    m = report.get("metrics", {})
    return {"kind": str(report.get("kind", "")), "to_surface_mean": _number(m.get("to_surface_mean")),
            "to_surface_p95": _number(m.get("to_surface_p95"))}


def curves_metrics(report: dict) -> dict:
    """``nurbskit curves``'s headline: curves found and the symmetric Chamfer to the ink (pixels)."""
    return {"curves": _number(report.get("curves")),
            "chamfer_px": _number((report.get("chamfer_px") or {}).get("symmetric"))}


VIEWS = ("front", "left", "top")


def volume_rows(path: Path) -> list[Item]:
    """Items of a volume CSV: one row per drawing triple.

    Columns ``front,left,top`` and an optional ``name`` (default: the front drawing's
    stem); a header row naming them is optional (without one the order is front, left,
    top[, name]). Relative paths are taken from the CSV's folder.
    """
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = [r for r in csv.reader(handle) if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable CSV of front,left,top drawings ({exc})") from None
    if not rows:
        raise InputError(f"{path}: expected rows of front,left,top drawings, found none")
    header = [c.strip().lower() for c in rows[0]]
    if set(VIEWS) <= set(header):
        columns, rows = header, rows[1:]
    else:
        columns = [*VIEWS, "name"]
    items = []
    for number, row in enumerate(rows, start=2 if columns is header else 1):
        cells = dict(zip(columns, (c.strip() for c in row)))
        missing = [v for v in VIEWS if not cells.get(v)]
        if missing:
            raise InputError(f"{path}, row {number}: expected front, left and top drawings, missing {', '.join(missing)}")
        files = tuple((v, str((path.parent / cells[v]) if not Path(cells[v]).is_absolute() else Path(cells[v]))) for v in VIEWS)
        name = cells.get("name") or Path(cells["front"]).stem
        items.append(Item(name=name, inputs=files, source=f"{path}:{number}"))
    return items


def volume_argv(item: Item) -> list[str]:
    return [arg for role, path in item.inputs for arg in (f"--{role}", path)]


# Files a folder contributes to `fit`: the point, mesh and NURBS formats nurbskit reads,
# except names too generic to be inputs in a folder of outputs (.json, .csv, .dat, .zip)
# and side files (.weights); name such files explicitly or by a glob.
FIT_EXTENSIONS = (
    ".ply", ".off", ".noff", ".coff", ".obj", ".stl", ".pcd", ".npy", ".npz",
    ".xyz", ".xyzc", ".xyzn", ".pts", ".asc", ".txt", ".ctrlpts", ".cptw", ".smesh", ".3dm",
)

COMMANDS: dict[str, BatchCommand] = {}


def register(command: BatchCommand) -> BatchCommand:
    """Add (or replace) a batchable command; returns it."""
    COMMANDS[command.name] = command
    return command


def get_command(command: str | BatchCommand) -> BatchCommand:
    """The registered command called ``command`` (a BatchCommand passes through)."""
    if isinstance(command, BatchCommand):
        return command
    try:
        return COMMANDS[command]
    except KeyError:
        raise OptionError(f"COMMAND: expected one of {', '.join(sorted(COMMANDS))}, got {command!r}") from None


register(BatchCommand(
    name="fit", module="nurbskit.cli.fit_command", extensions=FIT_EXTENSIONS, metrics=fit_metrics,
    description="fit a NURBS surface to each point cloud, mesh or NURBS file",
))
register(BatchCommand(
    name="volume", module="nurbskit.cli.volume_command", extensions=(".csv",), metrics=volume_metrics,
    expand=volume_rows, argv=volume_argv,
    description="fit a NURBS volume to each front/left/top row of CSV files",
))
register(BatchCommand(
    name="patches", module="nurbskit.cli.patches_command", extensions=FIT_EXTENSIONS, metrics=patches_metrics,
    description="fit a few trimmed NURBS patches to each scan",
))
register(BatchCommand(
    name="shape", module="nurbskit.cli.shape_command", extensions=FIT_EXTENSIONS, metrics=shape_metrics,
    description="fit an exact surface of revolution or extrusion (or free-form) to each cloud",
))
register(BatchCommand(
    name="curves", module="nurbskit.cli.curves_command", extensions=(".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"),
    metrics=curves_metrics, description="fit B-spline curves to each drawing",
))


def _register_export() -> None:
    from . import export

    register(BatchCommand(
        name="export", module="nurbskit.batch.export", extensions=export.EXTENSIONS, metrics=export.export_metrics,
        skip_names=export.NOT_GEOMETRY,
        description="write each NURBS or CAD file as STEP, IGES, BREP, .3dm or a mesh into its own folder",
    ))


_register_export()
