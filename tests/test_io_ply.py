"""PLY dialects written by hand: ASCII, binary little/big endian, any property order, extra
properties, float/double, polygons, triangle strips, and the ways a PLY file can be broken."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from nurbskit.errors import InputError
from nurbskit.io import read_mesh, read_points, write_mesh, write_points
from nurbskit.io.ply import strips_to_triangles

RNG = np.random.default_rng(7)
POINTS = RNG.normal(size=(5, 3))
NORMALS = RNG.normal(size=(5, 3))


def _binary_ply(path, order: str, coord: str, with_faces=True, extra_first=True):
    """A PLY with an extra 'quality' property before x, normals after, and a uchar colour."""
    ctype = {"float": "f4", "double": "f8"}[coord]
    fields = ([("quality", order + "f4")] if extra_first else []) + [
        ("x", order + ctype), ("nz", order + "f4"), ("y", order + ctype), ("z", order + ctype),
        ("nx", order + "f4"), ("ny", order + "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1"),
        ("label", order + "i4")]
    rec = np.zeros(5, fields)
    rec["x"], rec["y"], rec["z"] = POINTS.T
    rec["nx"], rec["ny"], rec["nz"] = NORMALS.T
    rec["red"], rec["green"], rec["blue"] = 10, 20, 30
    rec["label"] = np.arange(5) - 2
    names = {"f4": "float", "f8": "double", "u1": "uchar", "i4": "int"}
    fmt = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    head = ["ply", f"format {fmt} 1.0", "comment hand made", "obj_info test", "element vertex 5"]
    head += [f"property {names[t[-2:]]} {n}" for n, t in fields]
    faces = b""
    if with_faces:
        head += ["element face 2", "property uchar flags", "property list uchar int vertex_indices"]
        f = np.zeros(2, [("flags", "u1"), ("n", "u1"), ("v", order + "i4", (3,))])
        f["n"] = 3
        f["v"] = [[0, 1, 2], [2, 3, 4]]
        faces = f.tobytes()
    path.write_bytes(("\n".join(head) + "\nend_header\n").encode() + rec.tobytes() + faces)
    return path


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize("coord", ["float", "double"])
def test_binary_any_order_extra_properties(tmp_path, order, coord):
    path = _binary_ply(tmp_path / "a.ply", order, coord)
    cloud = read_points(path)
    tol = 1e-7 if coord == "float" else 0
    np.testing.assert_allclose(cloud.points, POINTS, rtol=tol, atol=tol)
    np.testing.assert_allclose(cloud.normals, NORMALS, rtol=1e-7, atol=1e-7)
    assert cloud.colors.tolist() == [[10, 20, 30]] * 5
    assert cloud.labels.tolist() == [-2, -1, 0, 1, 2]
    mesh = read_mesh(path)
    assert mesh.faces.tolist() == [[0, 1, 2], [2, 3, 4]]
    ref = trimesh.load(path, process=False)
    np.testing.assert_allclose(mesh.vertices, ref.vertices, rtol=1e-7)


def test_ascii_with_polygons_and_extra_properties(tmp_path):
    text = """ply
format ascii 1.0
comment quads and a pentagon
element vertex 6
property float y
property float x
property float z
property uchar intensity
element face 3
property list uchar int vertex_indices
property int material
end_header
0 0 0 9
0 1 0 9
1 1 0 9
1 0 0 9

2 0 1 9
2 1 1 9
4 0 1 2 3 7
3 0 3 4 7
5 1 2 5 4 3 7
"""
    path = tmp_path / "poly.ply"
    path.write_text(text)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.vertices[:, 0], [0, 1, 1, 0, 0, 1])  # x is the second column
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 2, 5], [1, 5, 4], [1, 4, 3]]


def test_triangle_strips_with_restart(tmp_path):
    text = """ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
element tristrips 1
property list int int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
1 1 0
0 2 0
1 2 0
9 0 1 2 3 -1 2 3 4 5
"""
    path = tmp_path / "strips.ply"
    path.write_text(text)
    mesh = read_mesh(path)
    assert mesh.faces.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4], [4, 3, 5]]
    # every triangle of a strip keeps one orientation: all normals point the same way (+z or -z)
    tri = mesh.vertices[mesh.faces]
    nz = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    assert np.all(nz > 0) or np.all(nz < 0)


def test_strips_oracle_loop():
    """The vectorised strip decoder against the textbook loop."""
    rng = np.random.default_rng(3)
    strips = [np.where(rng.random(40) < 0.1, -1, rng.integers(0, 30, 40)) for _ in range(5)]

    def naive(strips):
        out = []
        for s in strips:
            run = []
            for x in list(s) + [-1]:
                if x < 0:
                    for i in range(len(run) - 2):
                        a, b, c = run[i: i + 3]
                        t = (a, b, c) if i % 2 == 0 else (b, a, c)
                        if len({a, b, c}) == 3:
                            out.append(t)
                    run = []
                else:
                    run.append(int(x))
        return out

    assert [tuple(t) for t in strips_to_triangles(strips).tolist()] == naive(strips)


def test_binary_variable_length_lists(tmp_path):
    head = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\n" \
           b"property double z\nelement face 2\nproperty list uchar uint vertex_indices\nend_header\n"
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], "<f8").tobytes()
    faces = bytes([4]) + np.array([0, 1, 2, 3], "<u4").tobytes() + bytes([3]) + np.array([0, 2, 3], "<u4").tobytes()
    path = tmp_path / "var.ply"
    path.write_bytes(head + verts + faces)
    assert read_mesh(path).faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 3]]


@pytest.mark.parametrize("binary", [True, False])
def test_write_read_round_trip(tmp_path, binary):
    pts = RNG.normal(size=(50, 3))
    colors = RNG.integers(0, 256, (50, 4)).astype(np.uint8)
    labels = RNG.integers(-5, 5, 50)
    path = tmp_path / "rt.ply"
    assert write_points(path, pts, NORMALS[[0] * 50], colors, labels, binary=binary) == []
    back = read_points(path)
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.colors, colors)
    np.testing.assert_array_equal(back.labels, labels)
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    write_mesh(path, pts, faces, binary=binary)
    ref = trimesh.load(path, process=False)
    np.testing.assert_array_equal(ref.faces, faces)
    np.testing.assert_allclose(ref.vertices, pts, rtol=1e-15)


def test_truncated_binary(tmp_path):
    path = _binary_ply(tmp_path / "t.ply", "<", "float", with_faces=False)
    data = path.read_bytes()
    path.write_bytes(data[:-7])
    with pytest.raises(InputError, match=r"t\.ply: .*5 'vertex' records.*truncated"):
        read_points(path)


def test_header_lies_more_vertices(tmp_path):
    path = _binary_ply(tmp_path / "lie.ply", "<", "double", with_faces=False)
    path.write_bytes(path.read_bytes().replace(b"element vertex 5", b"element vertex 9"))
    with pytest.raises(InputError, match="header declares 9"):
        read_points(path)


def test_header_lies_fewer_vertices(tmp_path):
    path = _binary_ply(tmp_path / "lie.ply", "<", "double", with_faces=False)
    path.write_bytes(path.read_bytes().replace(b"element vertex 5", b"element vertex 3"))
    with pytest.raises(InputError, match="bytes follow the last element"):
        read_points(path)


def test_ascii_header_lies(tmp_path):
    path = tmp_path / "lie.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n0 0 0\n1 1 1\n")
    with pytest.raises(InputError, match="declares 4 records but the body has only 2 lines"):
        read_points(path)


def test_absurd_count_refused_before_allocating(tmp_path):
    path = _binary_ply(tmp_path / "huge.ply", "<", "float", with_faces=False)
    path.write_bytes(path.read_bytes().replace(b"element vertex 5", b"element vertex 1000000000000"))
    with pytest.raises(InputError, match="1,000,000,000,000 'vertex' records"):
        read_points(path)


def test_face_index_out_of_range(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    with pytest.raises(InputError, match="refers to vertex 7, but the file has 3 vertices"):
        read_mesh(path)


@pytest.mark.parametrize("header, message", [
    ("ply\nformat binary_middle_endian 1.0\nend_header\n", "format must be one of"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no 'end_header'"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n0\n", "property TYPE NAME"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n", "no 'y' property"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
     "end_header\n0 zero 0\n", "not a table of numbers at data line 1"),
])
def test_broken_headers(tmp_path, header, message):
    path = tmp_path / "broken.ply"
    path.write_text(header)
    with pytest.raises(InputError, match=message):
        read_points(path)
