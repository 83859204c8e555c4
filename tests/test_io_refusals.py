"""What info, convert, sample and export refuse, and how (the twenty-third session's sweep):
work that cannot fit is refused by the memory it needs, a set of files is written whole
or not at all, messages name the file or the field, and nothing is printed on stdout by
OpenCASCADE's parsers."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

import nurbskit
from _cli import one_line, refused, run
from nurbskit import NURBSSurface


@pytest.fixture
def surface_file(tmp_path) -> Path:
    path = tmp_path / "s.json"
    g = torch.Generator().manual_seed(3)
    nurbskit.save(NURBSSurface(torch.rand(5, 4, 3, dtype=torch.float64, generator=g), (3, 2),
                               weights=torch.rand(5, 4, dtype=torch.float64, generator=g) + 0.5), path)
    return path


def test_sample_refuses_what_the_memory_cannot_hold(tmp_path, capsys, monkeypatch, surface_file):
    import nurbskit._budget as budget

    monkeypatch.setattr(budget, "available_bytes", lambda: 2**30)  # a machine with 1 GB to spare
    out = tmp_path / "g.npy"
    # a NURBS grid: about 560 bytes a point, so 2,000^2 needs 2.1 GB
    refused(capsys, ["sample", surface_file, "--grid", "2000", "2000", "-o", out],
            "--grid 2000 2000 (grid, 4,000,000 samples) needs about 2.1 GB", f"at most about {2**30 // 560:,} samples fit")
    mesh = tmp_path / "m.off"
    mesh.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    # Poisson elimination: about 2.4 KB a sample; uniform: about 400 bytes
    refused(capsys, ["sample", mesh, "-n", "1000000", "-o", out], "-n 1,000,000 (poisson, 1,000,000 samples)")
    refused(capsys, ["sample", mesh, "-n", "3000000", "--method", "uniform", "-o", out], "(uniform, 3,000,000 samples)")
    assert not out.exists()


def test_sample_refuses_options_that_do_not_apply(tmp_path, capsys, surface_file):
    out = tmp_path / "g.npy"
    refused(capsys, ["sample", surface_file, "-n", "100", "--grid", "10", "10", "-o", out], "not both")
    refused(capsys, ["sample", surface_file, "--method", "uniform", "-n", "100", "-o", out],
            "--method applies to meshes")
    assert run(["sample", str(surface_file), "--grid", "6", "5", "-o", str(out)]) == 0
    assert np.load(out).shape[0] == 30


def test_a_zero_area_mesh_is_named_by_sample_and_export(tmp_path, capsys):
    flat = tmp_path / "flat.off"
    flat.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n")
    refused(capsys, ["sample", flat, "-n", "10", "-o", tmp_path / "s.xyz"], "flat.off: the mesh has zero surface area")
    refused(capsys, ["export", flat, tmp_path / "f.step"], "flat.off: every triangle of the mesh has zero area")
    assert not (tmp_path / "f.step").exists()


def test_coordinates_whose_squares_overflow_are_refused_on_reading(tmp_path, capsys, surface_file):
    data = json.loads(surface_file.read_text())
    data["control_points"][2][1][0] = 1e308
    big = tmp_path / "big.json"
    big.write_text(json.dumps(data))
    for argv in (["export", big, tmp_path / "x.stl"], ["sample", big, "--grid", "8", "8", "-o", tmp_path / "x.ply"]):
        refused(capsys, argv, "big.json: control points up to 1e+308: their squares", "overflow float64")
    with pytest.raises(nurbskit.NurbskitError, match="control points up to 1e\\+308"):
        nurbskit.io.read_nurbs(big)


def test_control_point_files_hold_2d_or_3d_points_and_are_written_whole(tmp_path, capsys, surface_file, monkeypatch):
    four = NURBSSurface(torch.rand(4, 4, 4, dtype=torch.float64), (3, 3))
    for ext in ("ctrlpts", "cptw"):
        with pytest.raises(nurbskit.NurbskitError, match=f"\\.{ext} lines hold 2-D or 3-D points; this surface's are 4-D"):
            nurbskit.io.write_nurbs(tmp_path / f"f.{ext}", four)
    # a disk that fills up while the second file of the set is written: none of the three is left,
    real = Path.write_bytes
    calls = []

    def full_disk(self, data):
        calls.append(self)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", full_disk)
    target = tmp_path / "set" / "x.ctrlpts"
    refused(capsys, ["convert", surface_file, target], f"{target}: No space left on device")
    assert not target.parent.exists()  # nor the folder made for them
    monkeypatch.setattr(Path, "write_bytes", real)
    assert run(["convert", str(surface_file), str(target)]) == 0
    assert sorted(p.name for p in target.parent.iterdir()) == ["x.ctrlpts", "x.ctrlpts.json", "x.weights"]
    # a .cptw holds its weights: the .weights beside its input is not an input, and may be written
    assert run(["convert", str(target), str(target.with_suffix(".cptw"))]) == 0
    assert run(["convert", str(target.with_suffix(".cptw")), str(target)]) == 0
    back = nurbskit.io.read_nurbs(target)
    assert torch.equal(back.weights, nurbskit.load(surface_file).weights)


def test_an_output_under_a_file_names_the_output(tmp_path, capsys, surface_file):
    (tmp_path / "afile").write_text("x")
    refused(capsys, ["convert", surface_file, tmp_path / "afile" / "x.json"],
            "afile/x.json: its folder cannot be made (a file of that name is in the way)")


@pytest.mark.parametrize("change, says", [
    (dict(control_points=[[1, 2, 3], [1, 2]]), "field 'control_points' must be a rectangular array of numbers"),
    (dict(knot_vectors=5), "field 'knot_vectors' must be a list of knot vectors, found int"),
    (dict(knot_vectors=[[0, 0, "a"], None]), "field 'knot_vectors[0]' must be a rectangular array of numbers"),
    (dict(degrees=[10**30, 2]), "degree 1000000000000000000000000000000 in u needs at least"),
    (dict(degrees=["2", 2]), "degrees must be integers, found '2'"),
])
def test_nurbskit_json_fields_are_named(tmp_path, capsys, surface_file, change, says):
    data = {**json.loads(surface_file.read_text()), **change}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    err = refused(capsys, ["info", path], f"bad.json: {says}")
    assert err.count("bad.json") == 1


def test_an_integer_of_5000_digits_is_named(tmp_path, capsys, surface_file):
    path = tmp_path / "digits.json"
    path.write_text(surface_file.read_text().replace('"degrees": [3, 2]', '"degrees": [' + "9" * 5000 + ", 2]"))
    err = refused(capsys, ["info", path], "digits.json: JSON holds an integer of more than")
    assert "sys." not in err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_pipe_is_not_a_file(tmp_path, capsys):
    pipe = tmp_path / "p.xyz"
    os.mkfifo(pipe)
    refused(capsys, ["info", pipe], "p.xyz: is not a regular file (a pipe or a device)")


def test_a_broken_step_file_prints_nothing_on_stdout(tmp_path, capfd):
    bad = tmp_path / "bad.step"
    bad.write_text('ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION((""),"2;1");\nENDSEC;\nDATA;\n#1=FOO(;\nENDSEC;\nEND-ISO-10303-21;\n')
    assert run(["info", str(bad)]) == 2
    out, err = capfd.readouterr()
    assert out == "" and one_line(err) and "could not read it as STEP" in err, (out, err)


@pytest.mark.parametrize("extra, out, says", [
    (["--pcd-data", "ascii"], "x.ply", "--pcd-data applies to a .pcd output, not '.ply'"),
    (["--geomdl"], "x.xyz", "--geomdl applies to a .json output"),
    (["--ascii"], "x.npy", "--ascii applies to .ply, .stl and .pcd outputs"),
])
def test_convert_refuses_options_its_output_ignores(tmp_path, capsys, extra, out, says):
    src = tmp_path / "p.xyz"
    np.savetxt(src, np.random.default_rng(0).random((20, 3)))
    refused(capsys, ["convert", src, tmp_path / out, *extra], says)
    assert not (tmp_path / out).exists()
