"""``nurbskit patches`` end to end on a small labelled cloud, and bad input as one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nurbskit.cli import main
from nurbskit.core.trim import TrimmedSurface
from nurbskit.io import read_mesh
from nurbskit.patches import fit_patches

from conftest import shared_file


@pytest.fixture
def box_corner(tmp_path):
    """Three faces of a box (one label each) as an .xyzc file: 3 x 300 points."""
    rng = np.random.default_rng(0)
    pts, lab = [], []
    for axis in range(3):
        p = rng.random((300, 3))
        p[:, axis] = 0.0
        pts.append(p)
        lab += [axis] * 300
    path = tmp_path / "corner.xyzc"
    np.savetxt(path, np.c_[np.vstack(pts), lab], fmt="%.9f %.9f %.9f %d")
    return path


def test_patches_writes_everything(box_corner, tmp_path, capsys):
    out = tmp_path / "out"
    # --crease-seam 75 (the default, given to test the option) keeps the corner's sharp
    # edges; 90 lets the energy round them, as the paper does: this sparse corner then
    # becomes 2 patches
    assert main(["patches", str(box_corner), "--out", str(out), "--quiet", "--crease-seam", "75"]) == 0
    text = capsys.readouterr().out
    assert "3 patches" in text and "IoU" in text
    for name in ("patches.json", "patches.ply", "labels.txt", "report.json", "config.json",
                 "planar.png", "patches.png", "energy.png", "patches/000.json", "meshes/000.ply"):
        assert (out / name).is_file(), name
    report = json.loads((out / "report.json").read_text())
    m = report["metrics"]
    assert m["N"] == 3 and m["completeness"] > 95 and m["P_cov_i"] > 95 and m["iou"] > 90
    assert set(report["timings"]) >= {"normals", "planar", "merge", "finalise", "trim", "metrics"}
    labels = np.loadtxt(out / "labels.txt", dtype=int)
    assert labels.shape == (900,) and set(np.unique(labels)) <= {-1, 0, 1, 2}
    index = json.loads((out / "patches.json").read_text())
    assert len(index["patches"]) == 3 and "history" in index and index["energy"]
    face = TrimmedSurface.from_dict(json.loads((out / "patches/000.json").read_text()))
    assert face.outer is not None
    mesh = read_mesh(out / "patches.ply")
    assert mesh.colors is not None and len(mesh.faces) > 0
    config = json.loads((out / "config.json").read_text())
    assert config["eps"] == 0.01 and config["weights"] == [0.3, 0.4, 0.3] and config["crease_seam"] == 75
    # an existing output directory is not replaced without --overwrite
    assert main(["patches", str(box_corner), "--out", str(out), "--quiet"]) == 2
    assert "--overwrite" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.xyz"], "no such file"),
        (["{cloud}", "--weights", "0.3,0.4"], "--weights: expected three"),
        (["{cloud}", "--eps", "2"], "--eps: expected a fraction"),
        (["{cloud}", "--max-ctrl", "3"], "--max-ctrl"),
        (["{cloud}", "--init", "nothing.vg"], "--init: expected 'auto' or an existing .vg file"),
        (["{cloud}", "--device", "tpu"], "--device: expected cpu or cuda"),
    ],
)
def test_bad_input_is_one_line(box_corner, tmp_path, capsys, args, message):
    args = [a.replace("{cloud}", str(box_corner)) for a in args]
    rc = main(["patches", *args, "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_too_few_points_is_an_input_error(tmp_path, capsys):
    path = tmp_path / "few.xyz"
    np.savetxt(path, np.random.default_rng(0).random((5, 3)))
    assert main(["patches", str(path), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "at least 20 points" in capsys.readouterr().err


@pytest.mark.slow
def test_fit_patches_on_an_abc_cloud(shared_data):
    """A 3,000-point subset of a real ABC cloud: few patches, most points covered, labels recovered."""
    from nurbskit.io import read_points

    cloud = read_points(shared_file(shared_data, "abc/abc_00470.xyzc"))
    keep = np.random.default_rng(0).choice(len(cloud.points), 3000, replace=False)
    res = fit_patches(cloud.points[keep], truth=cloud.labels[keep])
    m = res.metrics
    # measured on this subset: 6 patches, completeness and P_cov^i 98 %, IoU 69 %
    assert m["completeness"] > 90 and m["P_cov_i"] > 90 and m["iou"] > 55
    assert 2 <= m["N"] <= 10 < res.planar["planes"]


def test_help_lists_every_option(capsys):
    """--help prints (a percent sign in a field's help once broke argparse's formatting)."""
    with pytest.raises(SystemExit) as exc:
        main(["patches", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "--leftover" in out and "--crease-seam" in out and "1 %" in out
