"""`nurbskit volume` end to end: outputs, report, and one-line errors."""

import json

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from _cli import run
from nurbskit import load
from nurbskit.cli import main
from nurbskit.volume.shapes import solid_drawings, sphere_and_box


@pytest.fixture
def drawings(tmp_path):
    paths = {}
    for view, mask in solid_drawings(sphere_and_box, 64).items():
        path = tmp_path / f"{view}.png"
        Image.fromarray(((1 - mask.numpy()) * 255).astype(np.uint8)).save(path)  # ink on paper
        paths[view] = str(path)
    return paths


def args(drawings, out, *extra):
    return ["volume", "--front", drawings["front"], "--left", drawings["left"], "--top", drawings["top"],
            "--out", str(out), *extra]


def test_volume_command_writes_everything(tmp_path, drawings, capsys):
    out = tmp_path / "fit"
    rc = main(args(drawings, out, "--control-size", "10", "--grid", "24", "--iters", "30",
                   "--mesh-resolution", "40", "--loss", "silhouette"))
    err = capsys.readouterr().err
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir()) == [
        ".nurbskit-manifest.json", "mesh.obj", "mesh.ply", "report.json", "views.png", "volume.json"]
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["control_size"] == [10, 10, 10] and report["config"]["loss"] == "silhouette"
    assert set(report["iou"]) == {"front", "left", "top"} and min(report["iou"].values()) > 0.8
    assert report["seconds"]["total"] > 0 and report["empty"] is False
    assert report["cost_history"][-1] < report["cost_history"][0]  # the loss went down
    volume = load(out / "volume.json")
    assert volume.kind == "volume" and volume.control_points.shape == (10, 10, 10, 1)
    mesh = trimesh.load(out / "mesh.obj", process=False, force="mesh")
    assert mesh.vertices.min() >= 0 and mesh.vertices.max() <= 1 and len(mesh.faces) == report["mesh"]["faces"]
    assert len(trimesh.load(out / "mesh.ply", process=False, force="mesh").faces) == len(mesh.faces)
    with Image.open(out / "views.png") as png:
        assert png.size[0] > png.size[1] > 100
    assert "IoU front" in err and "disagree" not in err


def test_drawings_that_disagree_are_written_with_a_warning(tmp_path, drawings, capsys):
    # the top view narrowed to a third of its width: no solid shows all three
    top = np.asarray(Image.open(drawings["top"]))
    narrow = np.full_like(top, 255)
    w = top.shape[1]
    narrow[:, w // 3: w // 3 + w // 3] = np.asarray(Image.fromarray(top).resize((w // 3, top.shape[0])))
    Image.fromarray(narrow).save(tmp_path / "narrow.png")
    out = tmp_path / "fit"
    rc = main(args({**drawings, "top": str(tmp_path / "narrow.png")}, out, "--control-size", "8", "--grid", "16",
                   "--iters", "2", "--quiet"))
    err = capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    worst = min(report["visual_hull_iou"], key=report["visual_hull_iou"].get)
    assert rc == 0 and report["visual_hull_iou"][worst] < 0.9
    assert err.startswith(f"nurbskit volume: warning: the drawings disagree: no solid shows the {worst} drawing "
                          f"{drawings[worst] if worst != 'top' else tmp_path / 'narrow.png'} better than IoU "), err
    assert len(err.strip().splitlines()) == 1


def test_existing_output_needs_overwrite(tmp_path, drawings, capsys):
    out = tmp_path / "fit"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    rc = main(args(drawings, out, "--iters", "1", "--quiet"))
    assert rc == 2 and "--overwrite" in capsys.readouterr().err
    assert (out / "keep.txt").exists()
    # --overwrite never removes what nurbskit did not write: a foreign file is refused
    rc = main(args(drawings, out, "--control-size", "5", "--grid", "10", "--iters", "3", "--overwrite", "--quiet"))
    assert rc == 2 and "keep.txt" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "x" and not (out / "report.json").exists()
    # a folder that holds only an earlier run's outputs is replaced with --overwrite
    (out / "keep.txt").unlink()
    out.rmdir()
    assert main(args(drawings, out, "--control-size", "5", "--grid", "10", "--iters", "3", "--quiet")) in (0, 1)
    first = (out / "report.json").stat().st_mtime_ns
    assert main(args(drawings, out, "--control-size", "5", "--grid", "10", "--iters", "3", "--overwrite", "--quiet")) in (0, 1)
    assert (out / "report.json").stat().st_mtime_ns >= first


def test_empty_result_is_reported_not_hidden(tmp_path, drawings, capsys):
    out = tmp_path / "fit"
    rc = main(args(drawings, out, "--control-size", "5", "--grid", "10", "--iters", "0", "--quiet"))
    assert rc == 1
    assert "no surface at isovalue 0.5" in capsys.readouterr().err
    assert json.loads((out / "report.json").read_text())["empty"] is True


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--iters", "-3"], "expected an integer in [0, 100000]"),
        (["--isovalue", "nan"], "expected a finite number"),
        (["--loss", "chamfer"], "invalid choice"),
        (["--grid", "1"], "--grid: expected one integer or 3, each in [2, 4096]"),
        (["--grid", "10x10"], "--grid: expected one integer or 3, each in [2, 4096]"),
        (["--control-size", "2"], "control_size must be one or three integers in [3, 4096]"),
        (["--shape-weight", "0"], "--shape-weight: expected a number in (0, 1e+06], got 0"),
        (["--device", "tpu9"], "--device"),
        (["--preset", "best"], "invalid choice"),
    ],
)
def test_nonsense_options_give_one_line(tmp_path, drawings, capsys, extra, message):
    rc = run(args(drawings, tmp_path / "o", "--quiet", *extra))
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("content, message", [("text", "cannot be read as an image"), ("blank", "drawing is empty")])
def test_bad_drawings_give_one_line(tmp_path, drawings, capsys, content, message):
    bad = tmp_path / "bad.png"
    if content == "text":
        bad.write_text("hello")
    else:
        Image.fromarray(np.full((30, 30), 250, np.uint8)).save(bad)
    drawings = dict(drawings, left=str(bad))
    rc = main(args(drawings, tmp_path / "o", "--quiet"))
    err = capsys.readouterr().err
    assert rc == 2 and message in err and "left drawing" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_format_writes_the_mesh_in_another_format(tmp_path, drawings):
    out = tmp_path / "fit"
    rc = main(args(drawings, out, "--control-size", "6", "--grid", "10", "--iters", "3", "--quiet", "--format", "stl"))
    assert rc in (0, 1)
    obj = trimesh.load(out / "mesh.obj", process=False, force="mesh")
    stl = trimesh.load(out / "mesh.stl", force="mesh")  # a second reader of the same surface
    assert len(stl.faces) == len(obj.faces) > 0
    assert abs(stl.area - obj.area) <= 1e-6 * obj.area
