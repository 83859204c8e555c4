"""`nurbskit info`, `convert` and `sample`, and every bad input of the issue: one line on
stderr naming the file and the problem, a non-zero exit, never a traceback, inputs untouched."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from nurbskit.cli import main

from _assert import assert_close
from nurbskit.io import read_mesh, read_nurbs, read_points, write_mesh, write_points

TETRA = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
         np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(err: str, *needles: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def test_info_json_for_mesh_points_and_nurbs(tmp_path, capsys):
    write_mesh(tmp_path / "t.ply", *TETRA)
    rc, out, _ = run(capsys, "info", tmp_path / "t.ply", "--json")
    info = json.loads(out)
    assert rc == 0 and info["kind"] == "mesh" and info["num_points"] == 4 and info["num_faces"] == 4
    assert info["bbox"] == [[0, 0, 0], [1, 1, 1]]
    write_points(tmp_path / "p.xyzc", TETRA[0], labels=[1, 1, 2, 3])
    info = json.loads(run(capsys, "info", tmp_path / "p.xyzc", "--json")[1])
    assert info["kind"] == "points" and info["num_points"] == 4 and info["attributes"] == ["labels"]
    assert info["num_labels"] == 3
    import nurbskit
    import torch

    nurbskit.save(nurbskit.NURBSSurface(torch.rand(4, 5, 3), (3, 2)), tmp_path / "s.json")
    info = json.loads(run(capsys, "info", tmp_path / "s.json", "--json")[1])
    assert info["kind"] == "surface" and info["num_points"] == 20 and info["sizes"] == [4, 5]
    rc, out, _ = run(capsys, "info", tmp_path / "t.ply")
    assert rc == 0 and "faces       4" in out


def test_info_on_real_pcd(shared_data, capsys):
    rc, out, _ = run(capsys, "info", shared_data / "kinect_scans/test0.pcd", "--json")
    info = json.loads(out)
    assert rc == 0 and info["num_points"] == 189198 and info["dropped_nan_points"] == 118002
    assert info["width"] == 640 and info["height"] == 480


@pytest.mark.parametrize("src_ext, dst_ext", [(".ply", ".obj"), (".obj", ".off"), (".off", ".stl"), (".stl", ".ply"),
                                              (".ply", ".xyz"), (".ply", ".pcd"), (".ply", ".npz")])
def test_convert_by_extension(tmp_path, capsys, src_ext, dst_ext):
    src, dst = tmp_path / f"in{src_ext}", tmp_path / f"out{dst_ext}"
    write_mesh(src, *TETRA)
    rc, _, err = run(capsys, "convert", src, dst)
    assert rc == 0
    back = read_points(dst)
    # PCD and STL keep float32: the coordinates are O(1), so float32 rounding stays below 1e-7
    assert_close(np.unique(back.points, axis=0), np.unique(np.asarray(TETRA[0], np.float64), axis=0), atol=1e-7)
    if dst_ext in (".obj", ".off", ".stl", ".ply", ".npz"):
        assert read_mesh(dst).faces.shape == (4, 3)
    else:
        assert "cannot store faces" in err


def test_convert_nurbs_and_ctrlpts_options(tmp_path, capsys):
    pts = np.random.default_rng(0).normal(size=(12, 3))
    np.savetxt(tmp_path / "c.ctrlpts", pts)
    rc, _, err = run(capsys, "convert", tmp_path / "c.ctrlpts", tmp_path / "c.json")
    assert rc == 2
    one_line_error(err, "c.ctrlpts", "give sizes")
    rc, _, _ = run(capsys, "convert", tmp_path / "c.ctrlpts", tmp_path / "c.json", "--sizes", 4, 3, "--degrees", 2, 2)
    assert rc == 0
    s = read_nurbs(tmp_path / "c.json")
    assert s.sizes == (4, 3)
    np.testing.assert_array_equal(s.control_points.reshape(-1, 3).numpy(), pts)
    rc, _, _ = run(capsys, "convert", tmp_path / "c.json", tmp_path / "g.json", "--geomdl")
    assert rc == 0 and "shape" in json.loads((tmp_path / "g.json").read_text())


def test_convert_onto_itself_is_refused_and_keeps_the_file(tmp_path, capsys):
    path = tmp_path / "self.ply"
    write_mesh(path, *TETRA)
    before = path.read_bytes()
    rc, _, err = run(capsys, "convert", path, path, "--ascii")
    assert rc == 2 and "never writes over its inputs" in err and len(err.strip().splitlines()) == 1
    assert path.read_bytes() == before


def test_interrupted_convert_leaves_input_and_output_untouched(tmp_path, capsys, monkeypatch):
    src, dst = tmp_path / "in.ply", tmp_path / "out.obj"
    write_mesh(src, *TETRA)
    dst.write_text("previous content\n")
    src_bytes = src.read_bytes()
    import nurbskit.io.obj as obj_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(obj_module, "format_rows", interrupted)
    rc, _, err = run(capsys, "convert", src, dst)
    assert rc == 130 and "interrupted" in err
    assert src.read_bytes() == src_bytes and dst.read_text() == "previous content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out.obj"]  # no temporary left


def test_sample_command(tmp_path, capsys):
    write_mesh(tmp_path / "t.off", *TETRA)
    rc, _, _ = run(capsys, "sample", tmp_path / "t.off", "-n", 200, "--seed", 3, "-o", tmp_path / "s.ply")
    assert rc == 0
    cloud = read_points(tmp_path / "s.ply")
    assert cloud.num_points == 200 and cloud.normals.shape == (200, 3)
    rc, _, _ = run(capsys, "sample", tmp_path / "t.off", "-n", 200, "--seed", 3, "-o", tmp_path / "s2.ply")
    np.testing.assert_array_equal(read_points(tmp_path / "s2.ply").points, cloud.points)  # seeded
    rc, _, _ = run(capsys, "sample", tmp_path / "t.off", "-n", 50, "--method", "uniform", "-o", tmp_path / "u.xyz",
                   "--no-normals")
    assert rc == 0 and read_points(tmp_path / "u.xyz").num_points == 50
    rc, _, err = run(capsys, "sample", tmp_path / "t.off", "-n", 0, "-o", tmp_path / "z.ply")
    assert rc == 2
    one_line_error(err, "-n must be a positive integer")


def _bad_inputs(tmp_path):
    """Every bad input the issue lists: (file, words the message must contain)."""
    cases = {}
    cases["missing"] = (tmp_path / "missing.ply", ["missing.ply", "no such file"])
    (tmp_path / "folder.ply").mkdir()
    cases["directory"] = (tmp_path / "folder.ply", ["folder.ply", "is a directory"])
    (tmp_path / "empty.off").write_bytes(b"")
    cases["empty"] = (tmp_path / "empty.off", ["empty.off", "empty"])
    write_mesh(tmp_path / "full.ply", *TETRA)
    (tmp_path / "truncated.ply").write_bytes((tmp_path / "full.ply").read_bytes()[:-20])
    cases["truncated binary PLY"] = (tmp_path / "truncated.ply", ["truncated.ply", "truncated"])
    (tmp_path / "lies.off").write_text("OFF\n10 0 0\n0 0 0\n1 1 1\n")
    cases["header lies"] = (tmp_path / "lies.off", ["lies.off", "declares 10 vertices"])
    (tmp_path / "garbage.xyz").write_text("this is not\na point cloud\n")
    cases["garbage text"] = (tmp_path / "garbage.xyz", ["garbage.xyz", "not a table of numbers"])
    (tmp_path / "unknown.abc").write_text("1 2 3\n")
    cases["unknown extension"] = (tmp_path / "unknown.abc", ["unknown.abc", "unknown file type '.abc'"])
    (tmp_path / "nan.xyz").write_text("0 0 0\nnan 1 1\n")
    cases["NaN"] = (tmp_path / "nan.xyz", ["nan.xyz", "NaN or infinite"])
    (tmp_path / "inf.off").write_text("OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n")
    cases["infinite"] = (tmp_path / "inf.off", ["inf.off", "NaN or infinite"])
    huge = tmp_path / "huge.ply"
    huge.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n" + b"\0" * 64)
    cases["does not fit"] = (huge, ["huge.ply", "1,000,000,000,000"])
    return cases


def test_every_bad_input_is_one_line(tmp_path, capsys):
    for name, (path, needles) in _bad_inputs(tmp_path).items():
        before = path.read_bytes() if path.is_file() else None
        for argv in (["info", path], ["convert", path, tmp_path / "out.ply"]):
            rc, out, err = run(capsys, *argv)
            assert rc == 2, (name, argv)
            one_line_error(err, *needles)
        assert not (tmp_path / "out.ply").exists(), name
        if before is not None:
            assert path.read_bytes() == before, name


def test_file_that_does_not_fit_in_memory(tmp_path, capsys, monkeypatch):
    """A real, consistent file larger than the memory the machine reports (faked small)."""
    path = tmp_path / "big.ply"
    write_points(path, np.zeros((1000, 3)))
    import nurbskit.io._base as base

    monkeypatch.setattr(base, "available_memory", lambda: 10_000)
    rc, _, err = run(capsys, "info", path)
    assert rc == 2
    one_line_error(err, "big.ply", "of memory but only")


def test_no_traceback_through_a_real_process(tmp_path):
    (tmp_path / "bad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                                      "property float z\nend_header\n0 0 0\n")
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.run([sys.executable, "-m", "nurbskit", "info", str(tmp_path / "bad.ply")],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"nurbskit info: error: {tmp_path / 'bad.ply'}: header declares 2 records but the body has only 1 lines"]


def test_info_on_bare_ctrlpts_then_with_sizes(tmp_path, capsys):
    np.savetxt(tmp_path / "c.ctrlpts", np.arange(36.0).reshape(12, 3))
    info = json.loads(run(capsys, "info", tmp_path / "c.ctrlpts", "--json")[1])
    assert info["kind"] == "control points" and info["num_points"] == 12 and "--sizes" in info["note"]
    rc, out, _ = run(capsys, "info", tmp_path / "c.ctrlpts", "--json", "--sizes", 4, 3, "--degrees", 3, 2)
    info = json.loads(out)
    assert rc == 0 and info["kind"] == "surface" and info["sizes"] == [4, 3] and info["degrees"] == [3, 2]
    rc, _, err = run(capsys, "info", tmp_path / "c.ctrlpts", "--sizes", 5, 3, "--degrees", 3, 2)
    assert rc == 2
    one_line_error(err, "c.ctrlpts", "holds 12 control points but sizes [5, 3] need 15")


def test_two_gigabyte_file_that_does_not_fit(tmp_path, capsys, monkeypatch):
    """A consistent 2 GB binary PLY (sparse on disk) on a machine reporting 1 GB free:
    refused from its size before a byte of the body is read."""
    n = 2 * 1024**3 // 12
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nend_header\n").encode()
    path = tmp_path / "two_gb.ply"
    with open(path, "wb") as handle:
        handle.write(head)
        handle.truncate(len(head) + 12 * n)  # sparse: no disk space used
    import nurbskit.io._base as base

    monkeypatch.setattr(base, "available_memory", lambda: 1024**3)
    rc, _, err = run(capsys, "convert", path, tmp_path / "out.xyz")
    assert rc == 2
    one_line_error(err, "two_gb.ply", "needs about 2.0 GB of memory but only 1.0 GB is available")
    assert not (tmp_path / "out.xyz").exists()


def test_sample_nurbs_surface_on_a_grid(tmp_path, capsys):
    import nurbskit
    import torch

    surface = nurbskit.NURBSSurface(torch.rand(4, 5, 3, dtype=torch.float64), (3, 2))
    nurbskit.save(surface, tmp_path / "s.json")
    rc, _, _ = run(capsys, "sample", tmp_path / "s.json", "--grid", 6, 7, "-o", tmp_path / "g.ply")
    assert rc == 0
    cloud = read_points(tmp_path / "g.ply")
    expected = surface.sample((6, 7)).reshape(-1, 3).numpy()
    np.testing.assert_array_equal(cloud.points, expected)  # u slowest, as evaluate_grid lays it out
    assert_close(np.linalg.norm(cloud.normals, axis=1), np.ones(len(cloud.normals)), atol=1e-12)
    rc, _, _ = run(capsys, "sample", tmp_path / "s.json", "-n", 100, "-o", tmp_path / "n.xyz")
    assert rc == 0 and read_points(tmp_path / "n.xyz").num_points == 100
    rc, _, err = run(capsys, "sample", tmp_path / "s.json", "--grid", 6, "-o", tmp_path / "x.ply")
    assert rc == 2
    one_line_error(err, "--grid needs 2 positive integer(s) for a surface")
