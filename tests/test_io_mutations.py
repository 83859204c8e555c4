"""Readers that survive any file: a mutation corpus.

For every format a small valid file is mutated systematically: truncated at every byte,
each header count set to 0, -1, 2^31, 2^63 (and 4e9, 1e12), each PLY property
duplicated, retyped and made a list, numbers replaced by NaN, inf and text, JSON
nested deeply; hypothesis adds random byte edits. Every mutant must end in a correct
read (checked for consistency: shapes, dtypes, face indices in range) or a
:class:`~nurbskit.errors.NurbskitError`, never another exception.

CI runs the corpus derandomized and small; ``make fuzz`` runs 100x the hypothesis examples.
"""

from __future__ import annotations

import io
import itertools
import json
import re
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from nurbskit.cli.io_commands import describe
from nurbskit.errors import NurbskitError
from nurbskit.io import read_mesh, read_nurbs, read_points

from _property import examples

# ---- valid seeds ------------------------------------------------------------------------

_PLY_ASCII = (
    b"ply\nformat ascii 1.0\ncomment seed\nelement vertex 4\nproperty float x\nproperty float y\n"
    b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
    b"element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    b"0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0 9 9 9\n3 0 1 2\n3 0 2 3\n"
)


def _ply_binary(order: str = "<") -> bytes:
    name = "binary_little_endian" if order == "<" else "binary_big_endian"
    head = (f"ply\nformat {name} 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
            "property double z\nproperty float nx\nproperty float ny\nproperty float nz\n"
            "element face 2\nproperty list uchar int vertex_indices\nend_header\n").encode()
    v = np.zeros(4, [("p", order + "f8", 3), ("n", order + "f4", 3)])
    v["p"] = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    v["n"] = [0, 0, 1]
    f = np.zeros(2, [("k", "u1"), ("i", order + "i4", 3)])
    f["k"] = 3
    f["i"] = [[0, 1, 2], [0, 2, 3]]
    return head + v.tobytes() + f.tobytes()


_OFF = b"OFF\n# seed\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 1 2 3\n"
_NOFF = b"NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n"
_OBJ = b"# seed\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf -4 -2 -1\n"
_STL_ASCII = (b"solid s\nfacet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 0 1 0\n"
              b" endloop\nendfacet\nendsolid s\n")


def _stl_binary() -> bytes:
    rec = np.zeros(2, [("n", "<f4", 3), ("c", "<f4", (3, 3)), ("a", "<u2")])
    rec["c"][0] = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    rec["c"][1] = [[1, 0, 0], [1, 1, 0], [0, 1, 0]]
    return b"seed".ljust(80, b" ") + struct.pack("<I", 2) + rec.tobytes()


_PCD_HEAD = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb label\nSIZE 4 4 4 4 4\nTYPE F F F F U\n"
             "COUNT 1 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA {}\n")


def _pcd(mode: str) -> bytes:
    rec = np.zeros(3, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"), ("label", "<u4")])
    rec["x"], rec["y"], rec["z"] = [0, 1, np.nan], [0, 1, 2], [0.5, 0.25, 1]
    rec["rgb"] = [0xFF0000, 0x00FF00, 0x0000FF]
    rec["label"] = [1, 2, 3]
    head = _PCD_HEAD.format(mode).encode()
    if mode == "ascii":
        return head + b"0 0 0.5 1.0 1\n1 1 0.25 2.0 2\nnan 2 1 3.0 3\n"
    if mode == "binary":
        return head + rec.tobytes()
    from nurbskit.io.lzf import compress_literal

    soa = b"".join(np.ascontiguousarray(rec[n]).tobytes() for n in rec.dtype.names)
    packed = compress_literal(soa)
    return head + struct.pack("<II", len(packed), len(soa)) + packed


def _npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.arange(12, dtype=np.float64).reshape(4, 3))
    return buf.getvalue()


def _npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, points=np.eye(3), faces=np.array([[0, 1, 2]]), labels=np.array([1, 2, 3]))
    return buf.getvalue()


_XYZ = b"# seed\n0 0 0\n1 0 0 \n\n0 1 0\n"
_XYZ_PLAIN = b"0 0 0 1\n1 0 0 2\n0 1 0 3\n"
_PTS = b"3\n0 0 0 10 255 0 0\n1 0 0 20 0 255 0\n0 1 0 30 0 0 255\n"

_NURBSKIT_JSON = json.dumps({
    "format": "nurbskit", "version": 1, "kind": "curve", "degrees": [2], "sizes": [3],
    "knot_vectors": [[0, 0, 0, 1, 1, 1]], "control_points": [[0, 0, 0], [1, 1, 0], [2, 0, 0]],
}).encode()
_GEOMDL_JSON = json.dumps({"shape": {"type": "surface", "count": 1, "data": [{
    "type": "spline", "rational": False, "dimension": 3, "degree_u": 1, "degree_v": 1,
    "knotvector_u": [0, 0, 1, 1], "knotvector_v": [0, 0, 1, 1], "size_u": 2, "size_v": 2,
    "control_points": {"points": [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]]}}]}}).encode()
_CTRLPTS = b"0 0 0\n0 1 0\n1 0 0\n1 1 1\n"
_SIDE = json.dumps({"sizes": [2, 2], "degrees": [1, 1], "knot_vectors": [[0, 0, 1, 1], [0, 0, 1, 1]]}).encode()

SEEDS = {
    "ascii.ply": _PLY_ASCII, "binary.ply": _ply_binary("<"), "big.ply": _ply_binary(">"),
    "mesh.off": _OFF, "normals.off": _NOFF, "mesh.obj": _OBJ, "ascii.stl": _STL_ASCII,
    "binary.stl": _stl_binary(), "ascii.pcd": _pcd("ascii"), "binary.pcd": _pcd("binary"),
    "compressed.pcd": _pcd("binary_compressed"), "cloud.npy": _npy(), "cloud.npz": _npz(),
    "cloud.xyz": _XYZ, "labels.xyzc": _XYZ_PLAIN, "cloud.pts": _PTS,
}
NURBS_SEEDS = {"curve.json": _NURBSKIT_JSON, "geomdl.json": _GEOMDL_JSON}


# ---- the oracle -------------------------------------------------------------------------

def _check_cloud(cloud) -> None:
    pts = cloud.points
    assert pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 3
    n = pts.shape[0]
    for name, cols in (("normals", (3,)), ("colors", (3, 4))):
        value = getattr(cloud, name)
        if value is not None:
            assert value.shape[0] == n and value.shape[1] in cols, name
    if cloud.colors is not None:
        assert cloud.colors.dtype == np.uint8
    if cloud.labels is not None:
        assert cloud.labels.shape == (n,) and cloud.labels.dtype == np.int64


def _check_mesh(mesh) -> None:
    assert mesh.vertices.dtype == np.float64 and mesh.vertices.shape[1] == 3
    assert mesh.faces.dtype == np.int64 and mesh.faces.ndim == 2 and mesh.faces.shape[1] == 3
    if mesh.faces.size:
        assert mesh.faces.min() >= 0 and mesh.faces.max() < mesh.vertices.shape[0]


_FRESH = itertools.count()


def survives(path: Path, data: bytes | None) -> None:
    """Every reader on ``data`` (named like ``path``): a consistent result or a NurbskitError.

    Each mutant goes to a fresh file beside ``path`` (rewriting one file in place is ten
    times slower on ext4); ``data=None`` reads ``path`` as it is.
    """
    if data is not None:
        path = path.with_name(f"m{next(_FRESH)}-{path.name}")
        path.write_bytes(data)
    if path.suffix == ".json" or path.suffix == ".ctrlpts":
        calls = [lambda: read_nurbs(path), lambda: describe(path)]
    else:  # read_mesh only where the seed has faces: for the others it differs only in the last check
        calls = [lambda: _check_cloud(read_points(path)), lambda: describe(path)]
        if path.suffix in (".ply", ".off", ".obj", ".stl", ".npz"):
            calls.append(lambda: _check_mesh(read_mesh(path)))
    for call in calls:
        try:
            call()
        except NurbskitError as exc:
            assert "\n" not in str(exc), f"a multi-line message: {exc}"


# ---- mutators ---------------------------------------------------------------------------

COUNTS = ("0", "-1", str(2**31), str(2**63), "4000000000", "1000000000000", "1e12", "x")


def truncations(data: bytes, limit: int = 250):
    step = 1 if len(data) <= limit else max(1, len(data) // limit)
    return [data[:i] for i in range(0, len(data), step)]


def _sub_each(data: bytes, pattern: bytes, values) -> list[bytes]:
    """Every match of ``pattern``'s first group replaced by each value, one at a time."""
    out = []
    for m in re.finditer(pattern, data, re.MULTILINE):
        for v in values:
            out.append(data[: m.start(1)] + v.encode() + data[m.end(1):])
    return out


HEADER_COUNTS = {
    ".ply": rb"^element \w+ (\d+)",
    ".off": rb"^(\d+) \d+ \d+$|^\d+ (\d+) \d+$",
    ".pcd": rb"^(?:WIDTH|HEIGHT|POINTS|SIZE|COUNT) (\d+)",
    ".pts": rb"\A(\d+)",
}


def header_mutants(name: str, data: bytes) -> list[bytes]:
    ext = Path(name).suffix
    out = []
    if ext == ".off":
        m = re.search(rb"^(\d+) (\d+) (\d+)$", data, re.MULTILINE)
        for group in (1, 2):
            for v in COUNTS:
                out.append(data[: m.start(group)] + v.encode() + data[m.end(group):])
    elif ext in HEADER_COUNTS:
        out += _sub_each(data, HEADER_COUNTS[ext], COUNTS)
    if ext == ".pcd":
        out += _sub_each(data, rb"^SIZE (?:\d+ )*(\d+)", ("3", "16", "0"))
        out += _sub_each(data, rb"^TYPE (?:\w )*(\w)", ("Q", "I", "F"))
        out += _sub_each(data, rb"^DATA (\w+)", ("binary", "ascii", "binary_compressed", "zip"))
    if name == "binary.stl":
        for v in (0, 1, 3, 2**31, 2**32 - 1):
            out.append(data[:80] + struct.pack("<I", v) + data[84:])
    if name == "compressed.pcd":
        pos = data.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
        for c, u in ((0, 0), (2**32 - 1, 60), (10, 2**32 - 1), (1, 1)):
            out.append(data[:pos] + struct.pack("<II", c, u) + data[pos + 8:])
    if ext == ".npy":
        for shape in ("(0, 3)", "(-1, 3)", f"({2**31}, 3)", f"({2**63}, 3)", "(4,)", "(2, 2, 3)", "()"):
            out.append(data.replace(b"(4, 3)", shape.encode().ljust(6)))
    return out


_PLY_TYPES = ("char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int64", "list")


def ply_property_mutants(data: bytes) -> list[bytes]:
    """Each property line duplicated, retyped and turned into a list (and a list's types changed)."""
    out = []
    lines = data.split(b"\n")
    end = lines.index(b"end_header")
    for i, line in enumerate(lines[:end]):
        if not line.startswith(b"property"):
            continue
        words = line.split()
        variants = [line + b"\n" + line]  # duplicated
        name = words[-1]
        for t in _PLY_TYPES:
            variants.append(b"property " + t.encode() + b" " + name)
        variants.append(b"property list uchar int " + name)
        variants.append(b"property list int float " + name)
        variants.append(b"property list float int " + name)
        for v in variants:
            out.append(b"\n".join(lines[:i] + [v] + lines[i + 1:]))
    out.append(data.replace(b"element face", b"element vertex", 1))  # a duplicated element
    out.append(data.replace(b"vertex_indices", b"x"))
    return out


def number_mutants(data: bytes) -> list[bytes]:
    """Each number of a text body replaced by nan, inf, -inf, text, a huge integer, in turn."""
    out = []
    body = data.find(b"end_header\n")
    start = body + len(b"end_header\n") if body >= 0 else 0
    if data.startswith(b"# .PCD"):
        start = data.index(b"DATA ascii\n") + len(b"DATA ascii\n")
    for m in list(re.finditer(rb"(?<![\w.])-?\d+(?:\.\d+)?(?![\w.])", data[start:]))[:40]:
        a, b = start + m.start(), start + m.end()
        for v in (b"nan", b"inf", b"-inf", b"abc", b"1e999", b"99999999999999999999999", b"-5", b"3.5"):
            out.append(data[:a] + v + data[b:])
    return out


def deep_json(depth: int) -> bytes:
    return b'{"format": "nurbskit", "kind": ' + b"[" * depth + b"]" * depth + b"}"


def json_mutants(name: str, data: bytes) -> list[bytes]:
    obj = json.loads(data)
    out = [deep_json(100_000), b"[" * 100_000, b'{"shape": ' + b"{" * 50_000, b"{}", b"[]", b"1", b"null"]
    scalars = (0, -1, 2**63, 1e308, "x", None, [], {}, [[]])

    def walk(node, path=()):
        yield path
        if isinstance(node, dict):
            for k, v in node.items():
                yield from walk(v, path + (k,))
        elif isinstance(node, list):
            for i, v in enumerate(node[:3]):
                yield from walk(v, path + (i,))

    for path in list(walk(obj))[1:]:
        for s in scalars:
            clone = json.loads(data)
            target = clone
            for key in path[:-1]:
                target = target[key]
            target[path[-1]] = s
            out.append(json.dumps(clone).encode())
    return out


# ---- the corpus -------------------------------------------------------------------------

def _ids(d):
    return sorted(d)


@pytest.mark.parametrize("name", _ids(SEEDS))
def test_seed_files_read_correctly(tmp_path, name):
    """The seeds are valid: the corpus starts from files that read."""
    path = tmp_path / name
    path.write_bytes(SEEDS[name])
    cloud = read_points(path)
    _check_cloud(cloud)
    assert cloud.num_points >= 2


@pytest.mark.parametrize("name", _ids(SEEDS) + _ids(NURBS_SEEDS))
def test_every_truncation(tmp_path, name):
    data = {**SEEDS, **NURBS_SEEDS}[name]
    for mutant in truncations(data):
        survives(tmp_path / name, mutant)


@pytest.mark.parametrize("name", [n for n in _ids(SEEDS) if header_mutants(n, SEEDS[n])])
def test_every_header_count(tmp_path, name):
    for mutant in header_mutants(name, SEEDS[name]):
        survives(tmp_path / name, mutant)


@pytest.mark.parametrize("name", ["ascii.ply", "binary.ply", "big.ply"])
def test_every_ply_property_duplicated_retyped_and_made_a_list(tmp_path, name):
    for mutant in ply_property_mutants(SEEDS[name]):
        survives(tmp_path / name, mutant)


@pytest.mark.parametrize("name", ["ascii.ply", "mesh.off", "normals.off", "mesh.obj", "ascii.stl", "ascii.pcd",
                                  "cloud.xyz", "labels.xyzc", "cloud.pts"])
def test_every_number_replaced(tmp_path, name):
    for mutant in number_mutants(SEEDS[name]):
        survives(tmp_path / name, mutant)


@pytest.mark.parametrize("name", _ids(NURBS_SEEDS))
def test_every_json_field_replaced_and_deep_nesting(tmp_path, name):
    for mutant in json_mutants(name, NURBS_SEEDS[name]):
        survives(tmp_path / name, mutant)


def test_ctrlpts_and_side_json_mutants(tmp_path):
    path = tmp_path / "duck.ctrlpts"
    side = tmp_path / "duck.ctrlpts.json"
    path.write_bytes(_CTRLPTS)
    side.write_bytes(_SIDE)
    assert read_nurbs(path).sizes == (2, 2)
    for mutant in json_mutants("side.json", _SIDE) + truncations(_SIDE):
        side.write_bytes(mutant)
        survives(path, None)
    side.unlink()
    for sizes in ([-1, -4], [0, 0], [2**31, 2], ["a", 2], [2.5, 2], [[2], 2], [2**63, 2**63]):
        for degrees in ([1, 1], [-1, 1], [2**31, 1]):
            try:
                read_nurbs(path, sizes=sizes, degrees=degrees)
            except NurbskitError:
                pass
    for mutant in number_mutants(_CTRLPTS) + truncations(_CTRLPTS):
        survives(path, mutant)


# ---- the cases the tester found ---------------------------------------------------

EMPTY = {
    "empty.ply": b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                 b"property float z\nend_header\n",
    "empty_binary.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n"
                        b"property float y\nproperty float z\nend_header\n",
    "empty.off": b"OFF\n0 0 0\n",
    "empty.pcd": _PCD_HEAD.format("ascii").replace("WIDTH 3", "WIDTH 0").replace("POINTS 3", "POINTS 0").encode(),
}


def _empty_npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.zeros((0, 3)))
    return buf.getvalue()


EMPTY["empty.npy"] = _empty_npy()


@pytest.mark.parametrize("name", sorted(EMPTY))
def test_files_with_no_points_are_one_line_errors_or_described(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(EMPTY[name])
    with pytest.raises(NurbskitError, match="no points"):
        read_points(path)
    with pytest.raises(NurbskitError):
        read_mesh(path)
    info = describe(path)
    assert info["num_points"] == 0 and info["bbox"] is None


@pytest.mark.parametrize("body, match", [
    (b"element vertex 1\nproperty float x\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3 4\n",
     "declared twice"),
    (b"element vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n1 0 2 3\n",
     "list"),
])
def test_ply_duplicated_and_list_coordinates(tmp_path, body, match):
    path = tmp_path / "bad.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\n" + body)
    with pytest.raises(NurbskitError, match=match):
        read_points(path)


@pytest.mark.parametrize("count", [-1, 4_000_000_000, 255])
def test_ply_face_list_counts_beyond_the_data(tmp_path, count):
    ctype = "int" if count < 0 else "uint"
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list " + ctype.encode() + b" int vertex_indices\nend_header\n")
    body = (np.eye(3, dtype="<f4").tobytes() + struct.pack("<i" if count < 0 else "<I", count)
            + struct.pack("<3i", 0, 1, 2))
    path = tmp_path / "faces.ply"
    path.write_bytes(head + body)
    with pytest.raises(NurbskitError):
        read_mesh(path)
    ascii_path = tmp_path / "faces_ascii.ply"
    ascii_path.write_bytes(head.replace(b"binary_little_endian", b"ascii") + b"1 0 0\n0 1 0\n0 0 1\n"
                           + f"{count} 0 1 2\n".encode())
    with pytest.raises(NurbskitError):
        read_mesh(ascii_path)


def test_obj_face_index_beyond_int64(tmp_path):
    path = tmp_path / "big.obj"
    path.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n")
    with pytest.raises(NurbskitError, match="vertex"):
        read_mesh(path)


def test_pcd_declaring_1e12_points(tmp_path):
    path = tmp_path / "huge.pcd"
    path.write_bytes(_pcd("binary").replace(b"WIDTH 3", b"WIDTH 1000000000000")
                     .replace(b"POINTS 3", b"POINTS 1000000000000"))
    with pytest.raises(NurbskitError, match="1,000,000,000,000"):
        read_points(path)


def test_json_nested_100000_levels(tmp_path):
    path = tmp_path / "deep.json"
    path.write_bytes(deep_json(100_000))
    with pytest.raises(NurbskitError, match="nested"):
        read_nurbs(path)


@pytest.mark.parametrize("change", [
    {"control_points": {"points": 5}},
    {"size_u": -2, "size_v": -2},
    {"size_u": 2**40},
])
def test_geomdl_json_scalar_points_and_negative_sizes(tmp_path, change):
    data = json.loads(_GEOMDL_JSON)
    data["shape"]["data"][0].update(change)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(NurbskitError):
        read_nurbs(path)


@pytest.mark.parametrize("side", [
    {"sizes": [-2, -2], "degrees": [1, 1]},
    {"sizes": ["two", 2], "degrees": [1, 1]},
    {"sizes": [2, 2], "degrees": [1, 1], "knot_vectors": [["a", 0, 1, 1], [0, 0, 1, 1]]},
    {"sizes": [2, 2], "degrees": ["one", 1]},
    {"sizes": 7},
])
def test_ctrlpts_negative_and_non_numeric_side_json(tmp_path, side):
    path = tmp_path / "c.ctrlpts"
    path.write_bytes(_CTRLPTS)
    (tmp_path / "c.ctrlpts.json").write_text(json.dumps(side))
    with pytest.raises(NurbskitError):
        read_nurbs(path)


def test_ctrlpts_negative_sizes_option(tmp_path):
    path = tmp_path / "c.ctrlpts"
    path.write_bytes(_CTRLPTS)
    with pytest.raises(NurbskitError):
        read_nurbs(path, sizes=[-2, -2], degrees=[1, 1])


def test_zip_with_a_damaged_member(tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as archive:
        archive.writestr("cloud.ply", _PLY_ASCII.replace(b"element vertex 4", b"element vertex 400"))
    survives(tmp_path / "cloud.zip", buf.getvalue())


# ---- random edits -----------------------------------------------------------------------

_ALL = sorted(SEEDS) + sorted(NURBS_SEEDS)


@st.composite
def edited(draw):
    name = draw(st.sampled_from(_ALL))
    data = bytearray({**SEEDS, **NURBS_SEEDS}[name])
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, max(0, len(data) - 1)))
        kind = draw(st.sampled_from(("flip", "insert", "delete", "digit")))
        if kind == "flip" and data:
            data[pos] = draw(st.integers(0, 255))
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=8))
        elif kind == "delete":
            del data[pos: pos + draw(st.integers(1, 8))]
        else:
            data[pos:pos] = draw(st.sampled_from((b"9999999999", b"-1", b"nan", b" ", b"\n", b"\x00")))
    return name, bytes(data)


@settings(max_examples=examples(100))
@given(edited())
@example(("binary.ply", _ply_binary().replace(b"uchar int vertex_indices", b"int int vertex_indices")))
@example(("cloud.npy", _npy().replace(b"'shape': (", b"'s", 1)))  # found by make fuzz: a TokenError
def test_random_edits(tmp_path_factory, case):
    name, data = case
    survives(tmp_path_factory.mktemp("edit") / name, data)
