"""Every output of ``write_result`` / ``nurbskit export`` read by a second, independent
reader: ``.3dm`` by rhino3dm (its own evaluator), meshes by trimesh; ``nurbskit info`` on
CAD files; the command line's errors. (.3dm tests taken over from test_io_nurbs.py.)"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from _assert import assert_close
from _cad import diagonal, random_surface, require_extra

import nurbskit
from _splines import small_curve as _curve, small_surface as _surface, small_volume as _volume
from nurbskit.cli import main
from nurbskit.core.trim import TrimLoop, TrimmedSurface
from nurbskit.errors import OptionError
from nurbskit.io import read_nurbs, write_nurbs


def _assert_same(a, b):
    assert a.kind == b.kind and a.sizes == b.sizes and a.degrees == b.degrees
    assert_close(a.control_points, b.control_points, atol=1e-14)
    assert_close(a.weights, b.weights, atol=1e-15)
    for x, y in zip(a.knot_vectors, b.knot_vectors):
        assert_close(x, y, atol=0)


# ---- .3dm: rhino3dm as the second reader ---------------------------------------------------

@pytest.mark.parametrize("make", [_curve, _surface])
def test_3dm_round_trip(tmp_path, make):
    rhino3dm = require_extra("rhino3dm")
    obj = make()
    write_nurbs(tmp_path / "o.3dm", obj)
    _assert_same(read_nurbs(tmp_path / "o.3dm"), obj)
    # rhino3dm evaluates the same geometry (its own evaluator as the oracle)
    geo = rhino3dm.File3dm.Read(str(tmp_path / "o.3dm")).Objects[0].Geometry
    if obj.kind == "curve":
        p = geo.PointAt(0.37)
        ours = obj.evaluate(torch.tensor([0.37], dtype=torch.float64))[0]
    else:
        p = geo.PointAt(0.37, 0.81)
        ours = obj.evaluate(torch.tensor([[0.37, 0.81]], dtype=torch.float64))[0]
    assert_close(np.array([p.X, p.Y, p.Z]), ours, atol=1e-12)


def test_3dm_rejects_volumes(tmp_path):
    require_extra("rhino3dm")
    with pytest.raises(OptionError, match="curves and surfaces"):
        write_nurbs(tmp_path / "v.3dm", _volume())


def test_write_result_3dm_holds_every_surface_and_rhino_evaluates_them(tmp_path):
    rhino3dm = require_extra("rhino3dm")
    from nurbskit.io.cad import read_3dm_all, write_result

    rng = np.random.default_rng(4)
    surfaces = [random_surface(rng, (p, q)) for p, q in [(1, 2), (3, 3), (5, 2)]]
    loop = TrimLoop.from_uv([[a + 0.2 * (b - a), c + 0.2 * (d - c)] for (a, b), (c, d) in [surfaces[0].domain]]
                            + [[surfaces[0].domain[0][1] - 0.1, surfaces[0].domain[1][0] + 0.3],
                               [surfaces[0].domain[0][0] + 0.4, surfaces[0].domain[1][1] - 0.1]])
    report = write_result([TrimmedSurface(surfaces[0], [loop])] + surfaces[1:], tmp_path / "set.3dm")
    assert report["left_out"] == ["trimming loops"]
    model = rhino3dm.File3dm.Read(str(tmp_path / "set.3dm"))
    assert len(model.Objects) == 3
    for obj, s in zip(model.Objects, surfaces):
        geo = obj.Geometry
        (u0, u1), (v0, v1) = s.domain
        for u, v in [(u0, v0), (0.3 * u0 + 0.7 * u1, 0.6 * v0 + 0.4 * v1), (u1, v1)]:
            p = geo.PointAt(u, v)
            assert_close(np.array([p.X, p.Y, p.Z]), s.evaluate(torch.tensor([[u, v]], dtype=torch.float64))[0],
                         atol=1e-12 * max(1.0, diagonal(s)))
    for back, s in zip(read_3dm_all(tmp_path / "set.3dm"), surfaces):
        _assert_same(back, s)


# ---- meshes: trimesh as the second reader ------------------------------------------------------

@pytest.mark.parametrize("ext", [".obj", ".ply", ".stl", ".gltf", ".glb"])
def test_tessellated_output_lies_on_the_surface(tmp_path, ext):
    require_extra("OCP")
    import trimesh

    from nurbskit.io.cad import write_result

    rng = np.random.default_rng(6)
    # a rational height field: a well-posed closest-point problem for every vertex
    xy = np.stack(np.meshgrid(np.linspace(0, 40, 7), np.linspace(0, 30, 6), indexing="ij"), axis=-1)
    cp = np.concatenate([xy, rng.normal(0, 3, (7, 6, 1))], axis=-1)
    s = nurbskit.NURBSSurface(torch.tensor(cp), (3, 2), None, torch.tensor(rng.uniform(0.6, 1.6, (7, 6))))
    tolerance = 1e-3 * diagonal(s)
    report = write_result(s, tmp_path / f"s{ext}", tolerance=tolerance)
    loaded = trimesh.load(str(tmp_path / f"s{ext}"), force="mesh", process=False)
    assert len(loaded.faces) == report["triangles"] > 0
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    # every vertex is a surface point: its closest point on the surface is itself
    _, _, distance = nurbskit.project_points(s, torch.tensor(vertices))
    # STL, glTF: float32 (1e-7 relative); trimesh writes OBJ and PLY to 8 decimals / float64
    bound = (1e-5 if ext in (".stl", ".gltf", ".glb") else 1e-7) * diagonal(s)
    assert distance.max().item() <= bound
    # and the triangles cover the surface: their area is the surface's (chordal error only)
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    from nurbskit.io.cad import face_of

    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face_of(s), props)
    assert abs(loaded.area - props.Mass()) <= 0.01 * props.Mass()


def test_tessellated_trimmed_patch_keeps_its_hole(tmp_path):
    require_extra("OCP")
    import trimesh

    from nurbskit.io.cad import write_result

    xy = np.stack(np.meshgrid([-1.0, 1.0], [-1.0, 1.0], indexing="ij"), axis=-1)
    plane = nurbskit.NURBSSurface(torch.tensor(np.concatenate([xy, np.zeros((2, 2, 1))], -1)), (1, 1))
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    hole = TrimLoop(np.stack([0.5 + 0.25 * np.cos(th), 0.5 + 0.25 * np.sin(th)], 1), "hole")
    write_result(TrimmedSurface(plane, [hole]), tmp_path / "h.stl", tolerance=1e-3)
    mesh = trimesh.load(str(tmp_path / "h.stl"), force="mesh")
    expected = 4.0 * (1.0 - hole.area)
    assert abs(mesh.area - expected) <= 0.005 * expected
    centroids = np.asarray(mesh.triangles_center)
    assert np.linalg.norm(centroids[:, :2], axis=1).min() >= 0.5 - 1e-3  # nothing inside the hole


# ---- the command line -------------------------------------------------------------------------

def test_export_and_info_on_the_command_line(tmp_path, capsys):
    require_extra("OCP")
    s = random_surface(np.random.default_rng(9), (3, 3), ("clamped", "periodic"))
    nurbskit.save(s, tmp_path / "s.json")
    assert main(["export", str(tmp_path / "s.json"), str(tmp_path / "s.igs")]) == 0
    assert "OpenCASCADE check passed" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "s.igs"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "iges" and info["num_faces"] == 1 and info["valid"]
    assert info["faces"][0]["degrees"] == [3, 3] and info["faces"][0]["type"] == "BSplineSurface"
    assert info["faces"][0]["sizes"] == list(s.sizes)
    assert main(["info", str(tmp_path / "s.igs")]) == 0
    text = capsys.readouterr().out
    assert "BSplineSurface" in text and "valid" in text
    # back to JSON and to STEP: the same surface
    assert main(["export", str(tmp_path / "s.igs"), str(tmp_path / "back.step")]) == 0
    assert main(["export", str(tmp_path / "back.step"), str(tmp_path / "back.json")]) == 0
    _assert_same(nurbskit.load(tmp_path / "back.json"), s)
    # a single surface through read_nurbs/write_nurbs too
    _assert_same(read_nurbs(tmp_path / "back.step"), s)


def test_export_mesh_to_step_solid_and_to_stl(tmp_path, capsys):
    require_extra("OCP")
    import trimesh

    trimesh.creation.box(extents=(2.0, 3.0, 4.0)).export(str(tmp_path / "box.obj"))
    assert main(["export", str(tmp_path / "box.obj"), str(tmp_path / "box.step")]) == 0
    info = json.loads((main(["info", str(tmp_path / "box.step"), "--json"]), capsys.readouterr().out)[1])
    assert info["solids"] == 1 and info["num_faces"] == 12 and info["valid"]
    assert main(["export", str(tmp_path / "box.step"), str(tmp_path / "box.stl"), "--tolerance", "0.01"]) == 0
    back = trimesh.load(str(tmp_path / "box.stl"), force="mesh")
    assert abs(back.volume - 24.0) <= 1e-5 * 24.0


@pytest.mark.parametrize("argv, message", [
    (["export", "{src}", "{dir}/out.xyz"], "unknown output type '.xyz'"),
    (["export", "{src}", "{dir}/out.stl", "--tolerance", "-1"], "--tolerance must be positive"),
    (["export", "{dir}/missing.json", "{dir}/out.step"], "missing.json"),
    (["export", "{bad}", "{dir}/out.step"], "not valid JSON"),
])
def test_export_errors_are_one_line(tmp_path, capsys, argv, message):
    nurbskit.save(_surface(), tmp_path / "s.json")
    (tmp_path / "bad.json").write_text("{not json")
    argv = [a.format(src=tmp_path / "s.json", dir=tmp_path, bad=tmp_path / "bad.json") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "out.step").exists()


def test_export_refuses_a_volume(tmp_path, capsys):
    require_extra("OCP")
    nurbskit.save(_volume(), tmp_path / "v.json")
    assert main(["export", str(tmp_path / "v.json"), str(tmp_path / "v.step")]) == 2
    assert "NURBS volume is a field" in capsys.readouterr().err


def test_add_format_option_and_write_result_for_result_commands(tmp_path):
    require_extra("OCP")
    import argparse

    from nurbskit.cli.export_command import add_format_option, write_result

    parser = argparse.ArgumentParser()
    add_format_option(parser)
    args = parser.parse_args(["--format", "step", "--mesh-tolerance", "0.5"])
    assert args.export_format == "step" and args.export_tolerance == 0.5
    report = write_result(_surface(), tmp_path / "surface.out", format=args.export_format)
    assert report["valid"] and report["format"] == "step"
    with pytest.raises(SystemExit):
        parser.parse_args(["--format", "dxf"])


def test_fit_and_volume_write_cad_formats(tmp_path):
    """`--format` on the result commands: the fitted surface as STEP, read back to the same surface."""
    rng = np.random.default_rng(0)
    uv = rng.random((400, 2))
    pts = np.c_[uv, 0.1 * np.sin(3 * uv[:, 0]) * uv[:, 1]]
    np.savetxt(tmp_path / "c.xyz", pts)
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "c.xyz"), "--ctrl", "6x6", "--iters", "3", "--resolution", "16x16",
                 "--no-figures", "--quiet", "--out", str(out), "--format", "step"]) == 0
    back = read_nurbs(out / "surface.step")
    ours = read_nurbs(out / "surface.json")
    grid = torch.rand(50, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    assert_close(back.evaluate(grid), ours.evaluate(grid), atol=1e-12)


def test_patches_result_exports_to_step_and_reads_back_valid(tmp_path):
    """A `nurbskit patches` result written as STEP (`--format step`) and read back by OCC."""
    require_extra("OCP")
    from nurbskit.io.cad import cad_info, read_cad

    rng = np.random.default_rng(0)
    pts, lab = [], []
    for axis in range(3):  # the corner of a box: three perpendicular squares
        p = rng.random((300, 3))
        p[:, axis] = 0.0
        pts.append(p)
        lab += [axis] * 300
    np.savetxt(tmp_path / "corner.xyzc", np.c_[np.vstack(pts), lab], fmt="%.9f %.9f %.9f %d")
    out = tmp_path / "out"
    assert main(["patches", str(tmp_path / "corner.xyzc"), "--out", str(out), "--quiet", "--no-figures",
                 "--format", "step"]) == 0
    info = cad_info(out / "patches.step")
    assert info["valid"] and len(info["faces"]) == 3
    model = read_cad(out / "patches.step")
    assert all(face.outer is not None for face in model.faces)


def test_a_result_commands_format_option_says_what_the_format_leaves_out(tmp_path, capsys):
    # `nurbskit patches --format 3dm` wrote trimmed patches untrimmed without a word;
    # the result commands now say it as `nurbskit export` does.
    require_extra("rhino3dm")
    from argparse import Namespace

    from nurbskit.cli.export_command import write_requested_format

    s = random_surface(np.random.default_rng(5), (3, 3))
    (a, b), (c, d) = s.domain
    loop = TrimLoop.from_uv([[a + 0.2 * (b - a), c + 0.2 * (d - c)], [b - 0.1 * (b - a), c + 0.3 * (d - c)],
                             [a + 0.4 * (b - a), d - 0.1 * (d - c)]])
    args = Namespace(export_format="3dm", export_tolerance=None, command="patches")
    write_requested_format(args, [TrimmedSurface(s, [loop])], tmp_path, "patches")
    assert (tmp_path / "patches.3dm").is_file()
    assert capsys.readouterr().err == ("nurbskit patches: note: .3dm cannot store trimming loops; "
                                       "left out of patches.3dm\n")


def test_3dm_breps_are_read_only_when_they_are_one_untrimmed_surface(tmp_path):
    # A trimmed face read without its trim is another shape (a disk read as its square), and
    # polysurfaces were skipped without a word: both are refused; a Brep that is one
    # untrimmed surface reads as that surface.
    rhino3dm = require_extra("rhino3dm")
    from nurbskit.io.cad import read_3dm_all

    plane = rhino3dm.NurbsSurface.Create(3, False, 2, 2, 2, 2)  # bilinear: (u, v) -> (2 u, v, 0)
    for i in range(2):
        for j in range(2):
            plane.Points[(i, j)] = rhino3dm.Point4d(2.0 * i, 1.0 * j, 0.0, 1.0)
    for knots in (plane.KnotsU, plane.KnotsV):
        knots[0], knots[1] = 0.0, 1.0
    model = rhino3dm.File3dm()
    model.Objects.AddBrep(rhino3dm.Brep.CreateFromSurface(plane))
    model.Write(str(tmp_path / "plain.3dm"), 7)
    (back,) = read_3dm_all(tmp_path / "plain.3dm")
    assert_close(back.evaluate(torch.tensor([[1.0, 1.0]], dtype=torch.float64)),
                 torch.tensor([[2.0, 1.0, 0.0]], dtype=torch.float64), atol=1e-15)
    model = rhino3dm.File3dm()
    model.Objects.AddBrep(rhino3dm.Brep.CreateFromBox(rhino3dm.Box(rhino3dm.BoundingBox(0, 0, 0, 1, 2, 3))))
    model.Write(str(tmp_path / "box.3dm"), 7)
    with pytest.raises(nurbskit.NurbskitError, match="1 trimmed or multi-face Brep"):
        read_3dm_all(tmp_path / "box.3dm")
