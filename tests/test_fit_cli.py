"""``nurbskit fit``, ``python -m nurbskit.demo`` and fits on the thesis data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from _cli import run
from nurbskit.cli import main
from nurbskit.core import NURBSSurface, save

from conftest import shared_file

F64 = torch.float64
ALL = {"surface.json", "points.off", "control_points.off", "report.json", "config.json",
       "wireframe.png", "clouds.png", "error_map.png", "loss.png", ".nurbskit-manifest.json"}


@pytest.fixture
def cloud(tmp_path):
    g = np.random.default_rng(0)
    uv = g.random((150, 2))
    pts = np.column_stack([uv, 0.2 * np.sin(3 * uv[:, 0]) * uv[:, 1]])
    path = tmp_path / "cloud.xyz"
    np.savetxt(path, pts)
    return path


def test_fit_writes_everything(cloud, tmp_path, capsys):
    out = tmp_path / "fit"
    rc = main(["fit", str(cloud), "--ctrl", "6x6", "--iters", "3", "--resolution", "16x16", "--out", str(out)])
    assert rc == 0
    assert {p.name for p in out.iterdir()} == ALL
    text = capsys.readouterr().out
    assert "wrote" in text and "input-to-surface mean" in text
    report = json.loads((out / "report.json").read_text())
    assert report["pipeline"] == "default" and report["iterations"] == 3
    assert report["final_loss"] < report["initial_loss"]  # the loss went down
    config = json.loads((out / "config.json").read_text())
    assert config["ctrl"] == [6, 6] and config["resolution"] == [16, 16]
    pts = (out / "points.off").read_text().split("\n")
    assert pts[1].split()[0] == "256"


def test_fit_named_pipeline_without_figures_and_overwrite(cloud, tmp_path, capsys):
    out = tmp_path / "fit"
    args = ["fit", str(cloud), "--pipeline", "ucdl", "--ctrl", "5", "--iters", "2", "--out", str(out), "--no-figures",
            "--laplacian-on", "control", "--quiet"]
    assert main(args) == 0
    assert not any(p.suffix == ".png" for p in out.iterdir())
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["pipeline"] == "UCDL" and cfg["stages"][0]["loss"]["laplacian_on"] == "control"
    # A second run into the same folder needs --overwrite.
    assert main(args) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--pipeline", "NOPE"], "unknown pipeline"),
        (["--ctrl", "axb"], "--ctrl"),
        (["--ctrl", "2x9"], "ctrl"),
        (["--resolution", "1x5"], "--resolution"),
        (["--iters", "-4"], "--iters: expected an integer in [0, 1000000], got -4"),
        (["--iters", "10000000"], "--iters: expected an integer in [0, 1000000]"),
        (["--pipeline", "SC"], "supervised"),
        (["--device", "tpu"], "--device"),
        (["--lr", "0"], "--lr: expected a number in (0, 10], got 0"),
        (["--lr", "1e30"], "--lr: expected a number in (0, 10], got 1e30"),
        (["--threads", "0"], "--threads: expected an integer in [1, 4096], got 0"),
        (["--max-points", "-1"], "--max-points"),
        (["--degree", "40x3", "--ctrl", "50x50"], "degree: expected two integers in [1, 15]"),
        (["--dtype", "float16"], "invalid choice"),
    ],
)
def test_bad_options_are_one_line_errors(cloud, tmp_path, capsys, extra, message):
    rc = run(["fit", str(cloud), "--out", str(tmp_path / "o"), "--quiet"] + extra)
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_bad_inputs_are_one_line_errors(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((4, 4)))
    assert main(["fit", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "(R, S, 3) or (N, 3)" in capsys.readouterr().err


def test_supervised_from_a_nurbs_file_and_an_ordered_grid(tmp_path, capsys):
    g = torch.Generator().manual_seed(0)
    s = NURBSSurface(torch.rand(5, 5, 3, generator=g, dtype=F64), (3, 3))
    save(s, tmp_path / "s.json")
    out = tmp_path / "sc"
    assert main(["fit", str(tmp_path / "s.json"), "--pipeline", "SC", "--resolution", "20x20", "--out", str(out), "--no-figures", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["rms_normalized"] < 1e-8
    assert "RMS to target" in capsys.readouterr().out
    np.save(tmp_path / "grid.npy", s.sample((12, 12)).numpy())
    out2 = tmp_path / "soc"
    assert main(["fit", str(tmp_path / "grid.npy"), "--pipeline", "SOC", "--ctrl", "5x5", "--iters", "3", "--out", str(out2), "--no-figures", "--quiet"]) == 0
    assert json.loads((out2 / "report.json").read_text())["supervised"] is True


def test_help_lists_pipelines(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = capsys.readouterr().out
    for name in ("UCDL", "UP2P", "UM", "SB", "default"):
        assert name in text


def test_demo_without_shared_data(tmp_path, capsys):
    from nurbskit.demo import main as demo

    out = tmp_path / "out"
    assert demo(["--out", str(out), "--data", str(tmp_path / "nowhere"), "--no-figures"]) == 0
    assert {p.name for p in (out / "egg").iterdir()} == {"egg.json", "egg_points.off", "egg.obj", ".nurbskit-manifest.json"}
    assert not (out / "duck").exists()  # no duck without the thesis data
    assert {"surface.json", "points.off", "control_points.off", "report.json", "config.json"} <= {p.name for p in (out / "fit").iterdir()}
    assert "built-in" in capsys.readouterr().out
    # A second run replaces the outputs.
    assert demo(["--out", str(out), "--data", str(tmp_path / "nowhere"), "--no-figures"]) == 0


@pytest.mark.shared_data
def test_duck_supervised_sc_is_exact(shared_data):
    from nurbskit.demo import load_duck
    from nurbskit.fit import fit_surface
    from nurbskit.fit.outputs import fit_report

    shared_file(shared_data, "thesis_nurbsdiff/ducky/duck1.ctrlpts")
    duck = load_duck(shared_data / "thesis_nurbsdiff")
    assert duck.sizes == (14, 13) and duck.is_rational
    result = fit_surface(config="SC", target_surface=duck)
    assert fit_report(result)["rms_normalized"] <= 1e-6


@pytest.mark.shared_data
def test_horse_unsupervised_runs_on_the_real_file(shared_data, tmp_path):
    path = shared_file(shared_data, "thesis_nurbsdiff/meshes/horse_2500.off")
    out = tmp_path / "horse"
    rc = main(["fit", str(path), "--pipeline", "UCDL", "--ctrl", "20x20", "--iters", "3", "--out", str(out), "--no-figures", "--quiet"])
    assert rc == 0
    report = json.loads((out / "report.json").read_text())
    assert report["points"] == 2512 and report["topology"]["closed_v"] is True


def test_demo_finds_its_data_from_the_environment_or_the_working_directory(tmp_path, monkeypatch):
    import nurbskit.demo as demo

    monkeypatch.delenv("NURBSKIT_DATA", raising=False)
    assert demo.data_root() == Path("..") / "shared" / "data"  # relative: resolved in the working directory
    assert demo.data_root(str(tmp_path)) == tmp_path
    monkeypatch.setenv("NURBSKIT_DATA", str(tmp_path / "elsewhere"))
    assert demo.data_root() == tmp_path / "elsewhere"
    assert demo.data_root(str(tmp_path)) == tmp_path  # --data wins
    # found through the working directory, whatever the module's own location
    monkeypatch.delenv("NURBSKIT_DATA")
    (tmp_path / "shared" / "data" / "thesis_nurbsdiff").mkdir(parents=True)
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    assert demo.thesis_data_dir(demo.data_root()).resolve() == (tmp_path / "shared" / "data" / "thesis_nurbsdiff").resolve()
    assert not hasattr(demo, "SHARED_DATA")
