"""What every reader and writer shares: the result types, file checks, content sniffing,
size checks before allocating, and the fast text block parser.

Convention: readers return float64 coordinates, int64 faces, uint8 colours ``(N, 3|4)``
and int64 labels; every error is an :class:`~nurbskit.errors.InputError` whose message
starts with the file name and says what was expected and what arrived.
"""

from __future__ import annotations

import contextlib
import contextvars
import io
import os
import re
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._budget import human_bytes as _human
from ..errors import InputError, OptionError


@dataclass(eq=False)  # arrays have no single truth value: compare fields yourself
class PointCloud:
    """Points read from a file.

    Attributes:
        points: ``(N, 3)`` float64.
        normals: ``(N, 3)`` float64 or None.
        colors: ``(N, 3)`` or ``(N, 4)`` uint8 (RGB[A], 0..255) or None.
        labels: ``(N,)`` int64 or None (a segment / class id per point).
        dropped: number of points dropped because a coordinate was NaN (PCD holes).
        source: the path read, or None.

    Example:
        >>> import numpy as np
        >>> PointCloud(np.zeros((2, 3))).num_points
        2
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    labels: np.ndarray | None = None
    dropped: int = 0
    source: Path | None = None

    @property
    def num_points(self) -> int:
        return int(self.points.shape[0])

    def __len__(self) -> int:
        return self.num_points

    @property
    def attributes(self) -> list[str]:
        """Names of the optional attributes present: subset of normals, colors, labels."""
        return [n for n in ("normals", "colors", "labels") if getattr(self, n) is not None]


@dataclass(eq=False)
class Mesh:
    """A triangle mesh: the one mesh type of the package (readers return it, writers and
    the volume pipeline take it).

    Attributes:
        vertices: ``(V, 3)`` float64.
        faces: ``(F, 3)`` int64, indices into ``vertices`` (polygons fan-triangulated).
        normals: ``(V, 3)`` float64 per-vertex normals, or None.
        colors: ``(V, 3|4)`` uint8 per-vertex colours, or None.
        source: the path read, or None.

    Example:
        >>> import numpy as np
        >>> Mesh(np.eye(3), np.array([[0, 1, 2]])).num_faces
        1
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    source: Path | None = None

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def is_empty(self) -> bool:
        """True for a mesh without faces (e.g. an isosurface of a field below its isovalue)."""
        return self.num_faces == 0

    @classmethod
    def empty(cls) -> "Mesh":
        """A mesh with no vertices and no faces."""
        return cls(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))


@dataclass(eq=False)
class Payload:
    """What a format reader hands to the dispatchers (internal)."""

    points: np.ndarray
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    labels: np.ndarray | None = None
    dropped: int = 0
    info: dict = field(default_factory=dict)


# ---- file checks --------------------------------------------------------------------

def check_readable(path: str | os.PathLike) -> Path:
    """The path as a Path, or an InputError for a missing file, a directory, a pipe or
    device, an empty file."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a file")
    if not path.is_file():  # a FIFO, a device, a socket: no size, and perhaps no end
        raise InputError(f"{path}: is not a regular file (a pipe or a device), expected a file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    return path


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file: equal once resolved (symlinks, ``..``), or, when
    both exist, the same inode (hard links, bind mounts; ``os.path.samefile``)."""
    a, b = Path(a), Path(b)
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_not_input(output: str | os.PathLike, inputs, option: str | None = None) -> None:
    """Refuse (OptionError, one line naming ``option`` or the output) to write ``output``
    when it is one of ``inputs`` (None entries skipped): nurbskit never writes over its inputs.

    Example:
        >>> check_not_input("out.ply", ["scan.ply"])
    """
    where = f"{option} {output}" if option else f"{output}"
    for given in inputs:
        if given is not None and same_file(output, given):
            named = "" if Path(given) == Path(output) else f" {given}"
            raise OptionError(f"{where}: is the input file{named}; nurbskit never writes over its inputs")


def read_bytes(path: Path) -> bytes:
    """The whole file, after checking that it fits in memory."""
    check_fits(path, path.stat().st_size, "the file")
    try:
        return path.read_bytes()
    except MemoryError:
        raise InputError(f"{path}: the file ({_human(path.stat().st_size)}) does not fit in memory") from None


#: A ceiling on :func:`available_memory` for the current thread's work (:func:`memory_cap`).
_CAP: contextvars.ContextVar[int | None] = contextvars.ContextVar("nurbskit_memory_cap", default=None)


@contextlib.contextmanager
def memory_cap(nbytes: int):
    """Plan at most ``nbytes`` in this block, whatever the machine has: a server reading a
    client's file (a few MB of ``.npz`` can declare gigabytes) gives one client no more."""
    token = _CAP.set(int(nbytes))
    try:
        yield
    finally:
        _CAP.reset(token)


def available_memory() -> int:
    """Bytes of memory the OS says can still be allocated (MemAvailable; a large number if
    unknown), at most the cap of :func:`memory_cap` when one is set."""
    cap = _CAP.get()
    return _available_memory() if cap is None else min(cap, _available_memory())


def _available_memory() -> int:
    try:
        with open("/proc/meminfo", "rb") as handle:
            for line in handle:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # not Linux
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 1 << 62


def check_fits(path: Path, nbytes: int, what: str) -> None:
    """Refuse to allocate ``nbytes`` when the machine does not have them (checked before allocating)."""
    avail = available_memory()
    if nbytes > avail:
        raise InputError(
            f"{path}: reading {what} needs about {_human(nbytes)} of memory but only {_human(avail)} is available"
        )


def check_declared(path: Path, count: int, item_bytes: float, available_bytes: int, what: str) -> None:
    """Compare a count from a header with the data that follows it.

    ``item_bytes`` is the least number of bytes one item can take (exact for binary data,
    a lower bound for text); a header claiming more than the file can hold is refused
    before anything is allocated.
    """
    if count < 0:
        raise InputError(f"{path}: header declares a negative number of {what} ({count})")
    need = count * item_bytes
    if need > available_bytes:
        raise InputError(
            f"{path}: header declares {count:,} {what} ({_human(need)}) but only "
            f"{_human(available_bytes)} of data follow; the file is truncated or the header is wrong"
        )


# ---- sniffing -----------------------------------------------------------------------

_OFF_KEYWORD = re.compile(rb"^\s*(ST)?(C)?(N)?(4)?(n)?OFF\b")


def sniff(path: Path) -> str | None:
    """Format name from the first bytes of the file, or None when the content says nothing.

    Recognises ply, off, pcd, npy, npz, json, stl (ascii by ``solid`` + ``facet``, binary by
    its exact size), so a file whose extension lies is still read as what it is.
    """
    with open(path, "rb") as handle:
        head = handle.read(4096)
    size = path.stat().st_size
    if head.startswith(b"ply") and head[3:4] in (b"\n", b"\r"):
        return "ply"
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith(b"PK\x03\x04"):
        return "npz"
    stripped = head.lstrip()
    if _OFF_KEYWORD.match(head):
        return "off"
    if re.match(rb"^(#[^\n]*\n\s*)*(VERSION|FIELDS)\s", stripped) and b"FIELDS" in head and b"DATA" in head:
        return "pcd"
    if stripped.startswith(b"{"):
        return "json"
    if stripped[:5].lower() == b"solid" and b"facet" in head:
        return "stl"
    if size >= 84:
        n = int(np.frombuffer(head[80:84], "<u4")[0]) if len(head) >= 84 else -1
        if n >= 0 and size == 84 + 50 * n:
            return "stl"
    return None


# ---- text --------------------------------------------------------------------------

_COMMENT = re.compile(rb"(#|//)[^\n]*")
_BLANK = re.compile(rb"\n[ \t\r]*(?=\n)")


def clean_text(body: bytes, comments: bool = True) -> bytes:
    """Text with comments removed, CRLF turned into LF, blank lines removed, ending in LF.

    After this, every line holds data, so counting newlines counts records.
    """
    if b"\r" in body:
        body = body.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if comments and (b"#" in body or b"//" in body):
        body = _COMMENT.sub(b"", body)
    body = b"\n" + body
    if b"\n\n" in body or re.search(rb"\n[ \t]+\n", body):
        body = _BLANK.sub(b"", body)
    body = body[1:]
    if body.startswith(b"\n"):
        body = body[1:]
    if body and not body.endswith(b"\n"):
        body += b"\n"
    if body.strip() == b"":
        return b""
    return body


class Lines:
    """Random access to the lines of cleaned text by index, without splitting it into a list."""

    def __init__(self, body: bytes):
        self.body = body
        ends = np.flatnonzero(np.frombuffer(body, np.uint8) == 10)
        self.ends = ends
        self.count = int(ends.size)

    def start(self, i: int) -> int:
        return 0 if i == 0 else int(self.ends[i - 1]) + 1

    def block(self, i: int, n: int) -> bytes:
        """Lines ``i .. i + n - 1`` as one bytes object (each ends with LF)."""
        if n <= 0:
            return b""
        return self.body[self.start(i): int(self.ends[i + n - 1]) + 1]

    def line(self, i: int) -> bytes:
        return self.body[self.start(i): int(self.ends[i])]


def parse_table(path: Path, block: bytes | Path, rows: int | None, what: str, first_line: int = 1,
                delimiter: str | None = None, dtype=np.float64, comments: str | None = None) -> np.ndarray:
    """Parse numeric text lines into a ``(rows, cols)`` array with numpy's C parser.

    ``block`` is the text, or a Path to hand to the parser directly (no copy in Python).
    Raises an InputError naming the file, the data line and the text when a line is not
    numbers or the rows differ in length.
    """
    if isinstance(block, bytes) and not block.strip():
        return np.zeros((0, 0), dtype)
    source = io.BytesIO(block) if isinstance(block, bytes) else block
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            table = np.loadtxt(source, dtype=dtype, ndmin=2, comments=comments, delimiter=delimiter)
    except ValueError as exc:
        raise InputError(_table_error(path, source, what, first_line, delimiter, comments, str(exc))) from None
    except MemoryError:
        raise InputError(f"{path}: {what} do not fit in memory") from None
    if rows is not None and table.shape[0] != rows:
        raise InputError(f"{path}: expected {rows:,} {what}, found {table.shape[0]:,}")
    return table


_NUMPY_ROW = re.compile(r"row (\d+)")


def _table_error(path: Path, source, what: str, first_line: int, delimiter: str | None, comments: str | None,
                 numpy_message: str) -> str:
    """The one-line message for a table numpy could not parse: the first bad line, found again in Python.

    With ``comments`` the text is the file as it is, so the line number is the file's;
    without, comment and blank lines were removed before, so it counts data lines from
    ``first_line``. Only reached on failure: the Python loop costs nothing on good files.
    """
    if isinstance(source, io.BytesIO):
        source.seek(0)
        handle = source
    else:
        handle = open(source, "rb")
    split = (lambda t: [x.strip() for x in t.split(b",")]) if delimiter == "," else bytes.split
    sep = "commas" if delimiter == "," else "spaces or tabs"
    label = "line" if comments is not None else "data line"
    width = first = None
    try:
        for number, raw in enumerate(handle, start=1 if comments is not None else first_line):
            text = raw.split(comments.encode(), 1)[0] if comments is not None else raw
            text = text.strip()
            if not text:
                continue
            fields = split(text)
            bad = next((f for f in fields if not is_number(f)), None)
            if bad is not None or (width is not None and len(fields) != width):
                if width is not None and len(fields) != width:
                    detail = (f"{len(fields)} value{'s' if len(fields) != 1 else ''} separated by {sep}, "
                              f"where {label} {first} has {width}")
                else:
                    detail = f"{bad[:30].decode('utf-8', 'replace')!r} is not a number"
                mixed = (delimiter == ",") != (b"," in text)
                hint = "; the file mixes commas and spaces as separators" if mixed else ""
                shown = text[:60].decode("utf-8", "replace")
                return f"{path}: {what}: not a table of numbers at {label} {number} ({shown!r}: {detail}{hint})"
            if width is None:
                width, first = len(fields), number
    finally:
        if handle is not source:
            handle.close()
    # numpy saw what the loop above did not (a number Python reads and numpy does not)
    m = _NUMPY_ROW.search(numpy_message)
    detail = numpy_message.splitlines()[0].split(";")[0]
    lineno = f" near data line {first_line + int(m.group(1))}" if m else ""
    return f"{path}: {what}: not a table of numbers{lineno} ({detail})"


def is_number(token: bytes | str) -> bool:
    """Whether ``float(token)`` reads it."""
    try:
        float(token)
        return True
    except ValueError:
        return False


def columns_to_float64(columns) -> np.ndarray:
    """Stack 1-D columns (any numeric dtype, strided fields of a record array) into a
    C-contiguous ``(N, k)`` float64 array: one pass per column, no intermediate copies."""
    columns = list(columns)
    out = np.empty((len(columns[0]), len(columns)), dtype=np.float64)
    for i, c in enumerate(columns):
        out[:, i] = c
    return out


def nonfinite_rows(array: np.ndarray) -> np.ndarray:
    """Boolean mask of the rows of ``(N, k)`` holding a NaN or infinite value.

    The row sums are a cheap first test (a NaN or infinity anywhere makes the sum
    non-finite); only when some sum is non-finite, which overflow can also cause,
    are the values checked one by one.
    """
    if array.ndim == 1:
        return ~np.isfinite(array)
    total = array[:, 0].copy()
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is caught by the exact check below
        for i in range(1, array.shape[1]):
            total += array[:, i]
    bad = ~np.isfinite(total)
    if bad.any():
        bad = ~np.isfinite(array).all(axis=1)
    return bad


_SINGULAR = {"vertices": "vertex", "points": "point", "normals": "normal", "faces": "face", "colors": "color"}


def check_finite(path: Path, array: np.ndarray, what: str) -> None:
    """InputError naming the first row with a NaN or infinite value."""
    if array.size == 0:
        return
    bad = nonfinite_rows(array.reshape(array.shape[0], -1))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{path}: {what} contain NaN or infinite values (first at {_SINGULAR.get(what, what)} {row}: "
            f"{array[row].tolist()})"
        )


def integers(path: Path, values, what: str) -> np.ndarray:
    """``values`` as int64, or an InputError when one is not a whole number int64 can hold.

    Text readers parse every column as float64; a face index or a label read as NaN,
    2.5 or 1e30 must not be cast silently (numpy turns them into garbage integers).
    """
    arr = np.asarray(values)
    if arr.dtype.kind in "iub":
        if arr.dtype == np.uint64 and arr.size and int(arr.max()) >= 2**63:
            raise InputError(f"{path}: {what} must hold integers below 2^63, found {int(arr.max())}")
        return arr.astype(np.int64)
    if arr.dtype.kind != "f":
        raise InputError(f"{path}: {what} must hold integers, found values of type {arr.dtype}")
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(arr) | (arr != np.rint(arr)) | (np.abs(arr) >= 2.0**63)
    if bad.any():
        raise InputError(f"{path}: {what} must hold integers, found {arr[bad].flat[0]!r}")
    return arr.astype(np.int64)


def colors_to_uint8(values: np.ndarray, path: Path | None = None) -> np.ndarray:
    """Colours as uint8: integer types clipped to 0..255, floats in [0, 1] scaled by 255.

    NaN or infinite colours are an InputError (naming ``path``), not a silent 0.
    """
    values = np.asarray(values)
    if values.dtype.kind == "f":
        if values.size and not np.isfinite(values).all():
            where = f"{path}: " if path is not None else ""
            raise InputError(f"{where}colours contain NaN or infinite values")
        if values.size and np.nanmax(values) <= 1.0:
            values = values * 255.0
        return np.clip(np.rint(values), 0, 255).astype(np.uint8)
    return np.clip(values, 0, 255).astype(np.uint8)


def to_numpy(values):
    """A torch tensor as a numpy array (detached, on the CPU); anything else unchanged.

    torch is looked up among the loaded modules, not imported: a tensor can only exist
    once torch is loaded, and the io layer stays importable without paying for torch.
    """
    torch = sys.modules.get("torch")
    if torch is not None and isinstance(values, torch.Tensor):
        return values.detach().cpu().numpy()
    return values


def as_points(points, what: str = "points") -> np.ndarray:
    """Validate an ``(N, 3)`` array given to a writer; returns float64 contiguous."""
    points = to_numpy(points)
    arr = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise OptionError(f"{what} must have shape (N, 3), got {arr.shape}")
    return arr


def as_attribute(values, n: int, what: str, cols: tuple[int, ...] | None, dtype) -> np.ndarray | None:
    """Validate an optional per-point attribute for a writer (None passes through)."""
    if values is None:
        return None
    values = to_numpy(values)
    arr = np.asarray(values)
    if cols is None:
        if arr.shape != (n,):
            raise OptionError(f"{what} must have shape ({n},) to match the points, got {arr.shape}")
    elif arr.ndim != 2 or arr.shape[0] != n or arr.shape[1] not in cols:
        want = " or ".join(f"({n}, {c})" for c in cols)
        raise OptionError(f"{what} must have shape {want} to match the points, got {arr.shape}")
    if dtype is np.uint8:
        return np.ascontiguousarray(colors_to_uint8(arr))
    if dtype is np.int64 and arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.rint(arr)) or np.any(np.abs(arr) >= 2.0**63):
            raise OptionError(f"{what} must be integers that int64 holds")
    if dtype is np.int64 and arr.dtype == np.uint64 and arr.size and int(arr.max()) >= 2**63:
        raise OptionError(f"{what} must be integers that int64 holds, found {int(arr.max())}")
    return np.ascontiguousarray(arr.astype(dtype))


def as_faces(faces, num_vertices: int) -> np.ndarray:
    """Validate ``(F, 3)`` triangle indices for a writer."""
    faces = to_numpy(faces)
    arr = np.asarray(faces)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise OptionError(f"faces must have shape (F, 3), got {arr.shape}")
    if arr.size and arr.dtype.kind not in "iu":
        raise OptionError(f"faces must be integer indices, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= num_vertices):
        raise OptionError(
            f"faces index vertices {int(arr.min())}..{int(arr.max())}, but there are {num_vertices} vertices"
        )
    return np.ascontiguousarray(arr)


def check_faces(path: Path, faces: np.ndarray, num_vertices: int) -> None:
    """InputError when a face index points outside the vertex list."""
    if faces.size == 0:
        return
    lo, hi = int(faces.min()), int(faces.max())
    if lo < 0 or hi >= num_vertices:
        bad = lo if lo < 0 else hi
        raise InputError(f"{path}: a face refers to vertex {bad}, but the file has {num_vertices} vertices")


def fan_triangulate(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Triangles ``(T, 3)`` from polygons given as per-polygon sizes and their concatenated indices.

    A polygon ``(a, b, c, d, ...)`` becomes ``(a, b, c), (a, c, d), ...`` (a fan from its first
    corner). Polygons with fewer than 3 corners give no triangle.

    Example:
        >>> fan_triangulate(np.array([4]), np.array([0, 1, 2, 3])).tolist()
        [[0, 1, 2], [0, 2, 3]]
    """
    counts = np.asarray(counts, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    ntri = np.clip(counts - 2, 0, None)
    first = np.repeat(offsets, ntri)
    # position of each triangle within its polygon: 0, 1, ..., ntri-1
    within = np.arange(int(ntri.sum()), dtype=np.int64) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    tri = np.stack([indices[first], indices[first + within + 1], indices[first + within + 2]], axis=1)
    return tri.astype(np.int64)

