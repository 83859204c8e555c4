"""Which format a file is in: by content first (magic bytes), then by extension.

Content wins because extensions lie (an OFF file saved as ``.ply``, a binary STL
called ``.dat``); text formats without a signature (OBJ, XYZ) fall back to the
extension. Mesh formats nurbskit has no reader for go through trimesh when trimesh
knows them.
"""

from __future__ import annotations

import importlib
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from ._base import InputError, Payload, check_readable, sniff

EXTENSIONS = {
    ".ply": "ply", ".off": "off", ".noff": "off", ".coff": "off", ".obj": "obj", ".stl": "stl",
    ".pcd": "pcd", ".npy": "npy", ".npz": "npz",
    ".xyz": "text", ".txt": "text", ".csv": "text", ".xyzc": "text", ".pts": "text", ".xyzn": "text",
    ".asc": "text", ".zip": "zip",
}
NURBS_EXTENSIONS = (".json", ".ctrlpts", ".cptw", ".smesh", ".dat", ".3dm", ".weights",
                    ".step", ".stp", ".iges", ".igs", ".brep")  # CAD files: nurbskit.io.cad
MESH_FORMATS = ("ply", "off", "obj", "stl", "npz", "trimesh")


@dataclass(frozen=True)
class Writer:
    """One row of the writer table: where the writer lives and what it accepts.

    Every writer is called as ``function(path, points, faces, normals, colors, labels,
    **options)`` with validated arrays (or None) and returns the names of the given
    attributes its format cannot store.
    """

    module: str                      # under nurbskit.io
    function: str
    options: frozenset = frozenset()  # keyword options it accepts
    points: bool = True              # writes point clouds
    mesh: bool = False               # writes triangle meshes

    def load(self):
        return getattr(importlib.import_module(f"nurbskit.io.{self.module}"), self.function)


_TEXT = Writer("text", "write_text_points", frozenset({"precision"}))

# The one table of writers, by extension: write_points and write_mesh look here only.
WRITERS = {
    ".ply": Writer("ply", "write_ply", frozenset({"binary"}), mesh=True),
    ".pcd": Writer("pcd", "write_pcd", frozenset({"data", "coordinate_dtype"})),
    ".off": Writer("off", "write_off", frozenset({"precision"}), mesh=True),
    ".obj": Writer("obj", "write_obj", frozenset({"precision"}), mesh=True),
    ".stl": Writer("stl", "write_stl", frozenset({"binary"}), points=False, mesh=True),
    ".npy": Writer("npy", "write_npy"),
    ".npz": Writer("npy", "write_npz", mesh=True),
    **{ext: _TEXT for ext in (".xyz", ".txt", ".csv", ".xyzc", ".pts")},
}
POINT_WRITE = tuple(ext for ext, w in WRITERS.items() if w.points)
MESH_WRITE = tuple(ext for ext, w in WRITERS.items() if w.mesh)


def writer_for(path: Path, format: str | None, kind: str) -> tuple[str, Writer]:
    """The extension and table row to write ``kind`` ('points' or 'mesh') to ``path``.

    Raises OptionError for an extension without a writer of that kind, or a directory.
    """
    from ..errors import OptionError

    ext = (format if format is None or format.startswith(".") else "." + format) or path.suffix
    ext = ext.lower()
    row = WRITERS.get(ext)
    if row is None or not getattr(row, kind):
        writable = ", ".join(POINT_WRITE if kind == "points" else MESH_WRITE)
        what = "points" if kind == "points" else "a mesh"
        cad = "; nurbskit export writes CAD files" if ext in (".step", ".stp", ".iges", ".igs", ".brep", ".brp") else ""
        raise OptionError(f"{path}: cannot write {what} as {ext or '(no extension)'!r}; writable: {writable}{cad}")
    if path.is_dir():
        raise OptionError(f"{path}: is a directory, expected a file name")
    return ext, row


def check_options(ext: str, row: Writer, options: dict) -> None:
    """OptionError for keyword options the format's writer does not take."""
    from ..errors import OptionError

    unknown = set(options) - row.options
    if unknown:
        raise OptionError(f"options {sorted(unknown)} do not apply to {ext} files (allowed: {sorted(row.options) or 'none'})")


def _trimesh_extensions() -> set[str]:
    try:
        import trimesh

        return {"." + e.lower() for e in trimesh.available_formats()}
    except Exception:  # pragma: no cover - trimesh is a dependency, this is belt and braces
        return set()


def detect_format(path: str | os.PathLike, format: str | None = None) -> str:
    """The reader to use for ``path``: 'ply', 'off', 'obj', 'stl', 'pcd', 'npy', 'npz', 'text',
    'zip' or 'trimesh'. ``format`` (one of those, or an extension like '.xyz') overrides.

    Raises InputError for a missing, empty or unrecognised file.
    """
    path = check_readable(path)
    if format is not None:
        name = format.lower()
        name = EXTENSIONS.get(name if name.startswith(".") else "." + name, name)
        if name not in set(EXTENSIONS.values()) | {"trimesh"}:
            raise InputError(f"{path}: unknown format {format!r}; expected one of {sorted(set(EXTENSIONS.values()))}")
        return name
    ext = path.suffix.lower()
    found = sniff(path)
    if found == "npz" and ext == ".zip":
        return "zip"
    if found == "json":
        raise InputError(f"{path}: is a JSON file; NURBS files are read with read_nurbs (nurbskit info/convert handle them)")
    if found is not None:
        return found
    if ext in EXTENSIONS:
        return EXTENSIONS[ext]
    if ext in NURBS_EXTENSIONS:
        raise InputError(f"{path}: {ext} is a NURBS parameter file, not points or a mesh; read it with read_nurbs")
    if ext in _trimesh_extensions():
        return "trimesh"
    known = ", ".join(sorted(EXTENSIONS))
    raise InputError(f"{path}: unknown file type {ext or '(no extension)'!r}; readable point and mesh files are {known}")


def read_payload(path: str | os.PathLike, format: str | None = None) -> Payload:
    """Read any point or mesh file into the common payload (internal)."""
    path = Path(path)
    name = detect_format(path, format)
    try:
        if name == "zip":
            return _read_zip(path)
        if name == "trimesh":
            return _read_trimesh(path)
        reader = _reader(name)
        return reader(path)
    except MemoryError:
        raise InputError(f"{path}: the data do not fit in memory") from None


def _reader(name: str):
    if name == "ply":
        from .ply import read_ply as reader
    elif name == "off":
        from .off import read_off as reader
    elif name == "obj":
        from .obj import read_obj as reader
    elif name == "stl":
        from .stl import read_stl as reader
    elif name == "pcd":
        from .pcd import read_pcd as reader
    elif name == "npy":
        from .npy import read_npy as reader
    elif name == "npz":
        from .npy import read_npz as reader
    else:
        from .text import read_text_points as reader
    return reader


def _read_zip(path: Path) -> Payload:
    """A zip archive holding exactly one readable point or mesh file (e.g. ``horse.zip``)."""
    try:
        with zipfile.ZipFile(path) as archive:
            members = [m for m in archive.infolist()
                       if not m.is_dir() and Path(m.filename).suffix.lower() in EXTENSIONS
                       and Path(m.filename).suffix.lower() != ".zip" and not Path(m.filename).name.startswith(".")]
            if len(members) != 1:
                names = [m.filename for m in members]
                raise InputError(f"{path}: expected one point or mesh file in the zip archive, found {names}")
            member = members[0]
            from ._base import check_fits

            check_fits(path, member.file_size * 2, f"the archive member {member.filename}")
            with tempfile.TemporaryDirectory(prefix="nurbskit-zip-") as tmp:
                target = Path(tmp) / Path(member.filename).name
                with archive.open(member) as src, open(target, "wb") as dst:
                    while chunk := src.read(1 << 20):
                        dst.write(chunk)
                try:
                    payload = read_payload(target)
                except InputError as exc:  # name the member inside the archive, not the temporary copy
                    raise InputError(str(exc).replace(str(target), f"{path}[{member.filename}]")) from None
    except zipfile.BadZipFile as exc:
        raise InputError(f"{path}: not a valid zip archive ({exc})") from None
    payload.info["format"] = f"zip ({payload.info.get('format', '?')})"
    return payload


def _read_trimesh(path: Path) -> Payload:
    import numpy as np
    import trimesh

    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds; the message is what matters
        raise InputError(f"{path}: trimesh could not read it ({type(exc).__name__}: {exc})") from None
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    return Payload(vertices, faces if faces.size else None, info={"format": f"trimesh ({path.suffix.lower()})"})
