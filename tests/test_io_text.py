"""Text point files (XYZ, TXT, CSV, PTS, XYZC) and NumPy files, written by hand, against
numpy as the oracle."""

from __future__ import annotations

import re

import numpy as np
import pytest
from _property import examples
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from nurbskit.errors import InputError, OptionError
from nurbskit.io import read_points, write_points

RNG = np.random.default_rng(11)


def test_xyz_with_comments_blank_lines_tabs_and_crlf(tmp_path):
    text = "# scanner output\r\n\r\n1 2 3\r\n4\t5\t6   # trailing comment\r\n   \r\n7.5e-1 -8 +9\r\n"
    path = tmp_path / "a.xyz"
    path.write_bytes(text.encode())
    np.testing.assert_array_equal(read_points(path).points, [[1, 2, 3], [4, 5, 6], [0.75, -8, 9]])


@pytest.mark.parametrize("cols, attrs", [(3, []), (4, ["labels"]), (6, ["normals"]), (7, ["normals", "labels"])])
def test_xyz_columns(tmp_path, cols, attrs):
    table = RNG.normal(size=(20, cols))
    if cols in (4, 7):
        table[:, -1] = RNG.integers(0, 5, 20)
    path = tmp_path / "c.txt"
    np.savetxt(path, table)
    cloud = read_points(path)
    assert cloud.attributes == attrs
    np.testing.assert_array_equal(cloud.points, np.loadtxt(path)[:, :3])
    if "normals" in attrs:
        np.testing.assert_array_equal(cloud.normals, table[:, 3:6])
    if "labels" in attrs:
        np.testing.assert_array_equal(cloud.labels, table[:, -1].astype(int))


def test_xyzc_needs_label_column(tmp_path):
    path = tmp_path / "a.xyzc"
    path.write_text("0 0 0 1\n1 1 1 2\n")
    assert read_points(path).labels.tolist() == [1, 2]
    path.write_text("0 0 0\n1 1 1\n")
    with pytest.raises(InputError, match=r"\.xyzc point lines need 4 columns, found 3"):
        read_points(path)
    path.write_text("0 0 0 1.5\n")
    with pytest.raises(InputError, match="label column must hold integers"):
        read_points(path)


def test_csv(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("1,2,3\n4,5,6\n")
    np.testing.assert_array_equal(read_points(path).points, [[1, 2, 3], [4, 5, 6]])


def test_pts_with_count_intensity_and_colour(tmp_path):
    path = tmp_path / "a.pts"
    path.write_text("2\n1 2 3 -120 255 0 10\n4 5 6 7 0 128 255\n")
    cloud = read_points(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    assert cloud.colors.tolist() == [[255, 0, 10], [0, 128, 255]]
    path.write_text("3\n1 2 3\n4 5 6\n7 8 9\n10 11 12\n")
    with pytest.raises(InputError, match="declares 3 points but 4 point lines follow"):
        read_points(path)


def test_rows_file_with_level_comments(tmp_path):
    path = tmp_path / "rows.txt"
    path.write_text("# level# level 0 2\n0 0 0\n1 0 0\n# level 1 1\n0 1 0\n")
    assert read_points(path).num_points == 3


@pytest.mark.parametrize("text, message", [
    ("1 2 3\n4 5\n", "not a table of numbers"),
    ("1 2 3\n4 five 6\n", "at line 2 ('4 five 6': 'five' is not a number)"),
    ("1 2\n3 4\n", "need 3, 4, 6, 7 columns, found 2"),
    ("just some words\nand more\n", "not a table of numbers at line 1"),
])
def test_garbage_text(tmp_path, text, message):
    path = tmp_path / "g.xyz"
    path.write_text(text)
    with pytest.raises(InputError, match=re.escape(message)):
        read_points(path)


def test_binary_junk_with_text_extension(tmp_path):
    path = tmp_path / "junk.xyz"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match="found binary data"):
        read_points(path)


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_nonfinite_coordinates(tmp_path, bad):
    path = tmp_path / "n.xyz"
    path.write_text(f"0 0 0\n1 {bad} 1\n2 2 2\n")
    with pytest.raises(InputError, match=r"n\.xyz: points contain NaN or infinite values \(first at point 1"):
        read_points(path)
    cloud = read_points(path, nonfinite="drop")
    assert cloud.num_points == 2 and cloud.dropped == 1
    with pytest.raises(OptionError):
        read_points(path, nonfinite="ignore")


@pytest.mark.parametrize("ext", [".xyz", ".txt", ".csv", ".pts", ".xyzc"])
def test_text_round_trip_is_exact(tmp_path, ext):
    pts = RNG.normal(size=(40, 3)) * 10.0 ** RNG.integers(-8, 8, (40, 1))
    labels = RNG.integers(0, 100, 40)
    path = tmp_path / f"r{ext}"
    write_points(path, pts, labels=labels if ext in (".xyzc", ".xyz") else None)
    back = read_points(path)
    np.testing.assert_array_equal(back.points, pts)  # 17 significant digits: float64 exactly


@settings(max_examples=examples(25), deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 30), st.just(3)),
              elements=st.floats(allow_nan=False, allow_infinity=False, width=64)))
def test_xyz_round_trip_property(tmp_path_factory, pts):
    path = tmp_path_factory.mktemp("h") / "p.xyz"
    write_points(path, pts)
    np.testing.assert_array_equal(read_points(path).points, pts)


def test_npy_and_npz(tmp_path):
    pts = RNG.normal(size=(10, 3))
    nrm = RNG.normal(size=(10, 3))
    np.save(tmp_path / "a.npy", np.concatenate([pts, nrm], axis=1).astype(np.float32))
    cloud = read_points(tmp_path / "a.npy")
    np.testing.assert_array_equal(cloud.points, pts.astype(np.float32))
    np.testing.assert_array_equal(cloud.normals, nrm.astype(np.float32))
    np.savez(tmp_path / "b.npz", points=pts, labels=np.arange(10))
    assert read_points(tmp_path / "b.npz").labels.tolist() == list(range(10))
    np.save(tmp_path / "c.npy", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"must have shape \(N, 3\) or \(N, 6\), got \(4, 2\)"):
        read_points(tmp_path / "c.npy")
    np.save(tmp_path / "d.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InputError, match="Python objects"):
        read_points(tmp_path / "d.npy")
    np.savez(tmp_path / "e.npz", other=pts)
    with pytest.raises(InputError, match="no 'points' or 'vertices' array"):
        read_points(tmp_path / "e.npz")


def test_truncated_npy(tmp_path):
    path = tmp_path / "t.npy"
    np.save(path, np.zeros((100, 3)))
    path.write_bytes(path.read_bytes()[:-50])
    with pytest.raises(InputError, match="truncated"):
        read_points(path)


def test_write_points_validates(tmp_path):
    with pytest.raises(OptionError, match=r"points must have shape \(N, 3\)"):
        write_points(tmp_path / "a.ply", np.zeros((3, 2)))
    with pytest.raises(OptionError, match=r"normals must have shape \(3, 3\)"):
        write_points(tmp_path / "a.ply", np.zeros((3, 3)), normals=np.zeros((2, 3)))
    with pytest.raises(OptionError, match="cannot write points as '.doc'"):
        write_points(tmp_path / "a.doc", np.zeros((3, 3)))
    with pytest.raises(OptionError, match="NaN"):
        write_points(tmp_path / "a.xyz", np.full((1, 3), np.nan))
    with pytest.raises(OptionError, match="do not apply"):
        write_points(tmp_path / "a.xyz", np.zeros((1, 3)), binary=True)
    assert write_points(tmp_path / "a.off", np.zeros((1, 3)), labels=[3]) == ["labels"]


def test_torch_tensors_accepted(tmp_path):
    import torch

    pts = torch.rand(5, 3, dtype=torch.float32)
    write_points(tmp_path / "t.ply", pts)
    np.testing.assert_array_equal(read_points(tmp_path / "t.ply").points, pts.double().numpy())


def test_huge_but_finite_coordinates_are_not_mistaken_for_infinity(tmp_path):
    pts = np.array([[1e308, 1e308, 1e308], [-1e308, 5.0, -1e308]])
    write_points(tmp_path / "big.xyz", pts)
    np.testing.assert_array_equal(read_points(tmp_path / "big.xyz").points, pts)
    write_points(tmp_path / "big.ply", pts)
    np.testing.assert_array_equal(read_points(tmp_path / "big.ply").points, pts)
