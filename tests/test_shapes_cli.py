"""``nurbskit shape`` end to end: outputs, report contents, one-line errors, warnings."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from nurbskit import load
from nurbskit.cli import main
from nurbskit.metrics import surface_distances
from nurbskit.shapes import axis_angle_degrees
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud


def test_revolution_end_to_end(tmp_path, capsys):
    c = vase_cloud(1200, 0.0, 11)
    src = tmp_path / "vase.npy"
    np.save(src, c.points.numpy())
    out = tmp_path / "out"
    assert main(["shape", str(src), "--kind", "revolution", "--iters", "15", "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["kind"] == "revolution"
    assert axis_angle_degrees(rep["axis"]["direction"], c.axis_direction) < 0.5
    assert rep["metrics"]["to_surface_mean"] < 1e-3 and rep["metrics"]["to_surface_p95"] < 3e-3
    assert rep["profile"]["coordinates"] == ["r", "z"] and len(rep["profile"]["control_points"]) >= 4
    assert sorted(p.name for p in out.iterdir()) == [".nurbskit-manifest.json", "cloud.png", "error_map.png", "profile.png", "report.json", "surface.json"]
    surface = load(out / "surface.json")
    assert surface.degrees[0] == 2 and surface.sizes[0] == 9
    # the file holds the surface the report measured
    m = surface_distances(surface, c.points)
    assert abs(m["to_surface_mean"] - rep["metrics"]["to_surface_mean"]) < 1e-9
    assert "revolution" in capsys.readouterr().out
    # an existing output is refused without --overwrite, in one line
    assert main(["shape", str(src), "--kind", "revolution", "--out", str(out), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err and err.count("\n") == 1


def test_auto_extrusion_end_to_end(tmp_path):
    c = extrusion_cloud(1000, 0.0, 12, "L")
    src = tmp_path / "l.npy"
    np.save(src, c.points.numpy())
    out = tmp_path / "out"
    assert main(["shape", str(src), "--iters", "15", "--out", str(out), "--no-figures"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["kind"] == "extrusion" and "extrusion" in rep["reason"]
    assert set(rep["candidates"]) == {"revolution", "extrusion"}
    assert axis_angle_degrees(rep["axis"]["direction"], c.axis_direction) < 0.5
    assert rep["metrics"]["to_surface_mean"] < 1e-3


def test_plane_is_a_one_line_error(tmp_path, capsys):
    g = np.random.default_rng(0)
    pts = np.c_[g.random((400, 2)), np.zeros(400)]
    src = tmp_path / "plane.npy"
    np.save(src, pts)
    assert main(["shape", str(src), "--kind", "revolution", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "plane" in err and "plane.npy" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_poor_fit_warns(tmp_path, capsys):
    g = torch.Generator().manual_seed(0)
    pts = torch.rand(800, 3, generator=g, dtype=torch.float64)  # a solid box of points: no surface
    src = tmp_path / "blob.npy"
    np.save(src, pts.numpy())
    assert main(["shape", str(src), "--kind", "revolution", "--iters", "3", "--out", str(tmp_path / "o"),
                 "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert "warning: poor fit" in err
    assert json.loads((tmp_path / "o" / "report.json").read_text())["poor_fit"] is True


def test_missing_input(tmp_path, capsys):
    assert main(["shape", str(tmp_path / "nope.ply"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file" in capsys.readouterr().err
