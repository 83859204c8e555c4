"""What `fit` refuses before it starts and what it refuses to call a success (issues 8 and 17).

Each case here ended, before these checks, in a traceback (an 8 TB allocation), in a
silent "surface" through collinear points, or in exit 0 with garbage.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from _cli import one_line, run
from nurbskit.cli import main
from nurbskit.core import NURBSSurface
from nurbskit.errors import InputError, OptionError
from nurbskit.fit import fit_surface, get_pipeline
from nurbskit.fit.api import denormalise, initial_state, normalise, prepare_target, resolve_config, run_stages
from nurbskit.fit.checks import FitFailed, check_fit_size, check_result
from nurbskit.fit.loop import Target

F64 = torch.float64


def patch_points(n: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    uv = torch.rand(n, 2, generator=g, dtype=F64)
    return torch.stack([uv[:, 0], uv[:, 1], 0.2 * torch.sin(3 * uv[:, 0])], -1)


@pytest.fixture
def cloud(tmp_path):
    path = tmp_path / "cloud.npy"
    np.save(path, patch_points(500).numpy())
    return path


def test_more_control_points_than_points_is_refused_with_what_fits(cloud, tmp_path, capsys):
    rc = run(["fit", str(cloud), "--ctrl", "1000x1000", "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and one_line(err), err
    assert "1000000 control points cannot be determined by 500 fitted points" in err
    assert "--ctrl 22x22" in err
    assert not (tmp_path / "o").exists()


def test_huge_resolution_is_refused_before_any_sampling(cloud, tmp_path, capsys):
    rc = run(["fit", str(cloud), "--resolution", "1000000x1000000", "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and one_line(err), err
    assert "--resolution 1000000x1000000 needs about" in err and "fits" in err
    assert not (tmp_path / "o").exists()


def test_memory_estimate_names_what_would_fit():
    # A supervised 400 x 400 net on a 600 x 600 grid: a dense least-squares matrix of
    # 360,000 x 160,000 doubles (460 GB). With a 1 GB budget the message says what fits.
    cfg = dataclasses.replace(get_pipeline("SC"), ctrl=(400, 400), degree=(3, 3), resolution=(600, 600)).validate()
    grid = torch.zeros(600, 600, 3, dtype=F64)
    target = Target(points=grid.reshape(-1, 3), grid=grid)
    with pytest.raises(OptionError, match=r"needs about .* of memory but about 1\.0 GB is available; --ctrl (\d+)x\1"):
        check_fit_size(cfg, target, budget=2**30)
    check_fit_size(dataclasses.replace(cfg, ctrl=(5, 5)), target, budget=2**30)  # fits: no error


def test_collinear_points_do_not_determine_a_surface(tmp_path, capsys):
    t = torch.linspace(0, 1, 300, dtype=F64)[:, None]
    line = t * torch.tensor([1.0, 2.0, -0.5], dtype=F64) + torch.tensor([3.0, 0.0, 1.0], dtype=F64)
    with pytest.raises(InputError, match="lie on a line .* a surface is not determined"):
        fit_surface(line, "default")
    np.save(tmp_path / "line.npy", line.numpy())
    rc = run(["fit", str(tmp_path / "line.npy"), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and one_line(err) and "a surface is not determined" in err
    # a thin but honest strip is still a surface
    strip = torch.cat([line, line + torch.tensor([0.0, 0.0, 0.05], dtype=F64)])
    cfg = get_pipeline("default").with_iters(2)
    cfg.ctrl = (4, 4)
    assert fit_surface(strip, cfg).surface.sizes == (4, 4)


def test_learning_rate_out_of_range_is_refused_before_work(cloud, tmp_path, capsys):
    rc = run(["fit", str(cloud), "--lr", "1e30", "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and one_line(err) and "(0, 10]" in err
    cfg = get_pipeline("UCDL")
    cfg.stages[0].lr = 1e30
    with pytest.raises(OptionError, match=r"lr must be in \(0, 10\]"):
        fit_surface(patch_points(300), cfg)


def test_a_fit_that_ends_far_worse_than_it_started_fails_with_one_line(cloud, tmp_path, capsys):
    # Adam at the largest allowed step throws the Chamfer fit away from the data.
    rc = run(["fit", str(cloud), "--pipeline", "UCDL", "--lr", "10", "--iters", "5", "--ctrl", "6x6",
              "--out", str(tmp_path / "o"), "--quiet", "--no-figures"])
    err = capsys.readouterr().err
    assert rc != 0 and one_line(err), err
    assert "farther from the input than the surface it started from" in err and "--lr" in err
    assert not (tmp_path / "o").exists()


def test_a_non_finite_result_fails():
    pts = patch_points(100)
    cfg = dataclasses.replace(get_pipeline("UCDL"), ctrl=(4, 4), degree=(3, 3)).validate()
    good = NURBSSurface(torch.rand(4, 4, 3, dtype=F64), (3, 3))
    bad = good._replace(control_points=torch.full((4, 4, 3), float("nan"), dtype=F64))
    check_result(good, good, Target(points=pts), cfg)
    with pytest.raises(FitFailed, match="NaN or infinite; lower the learning rate"):
        check_result(bad, good, Target(points=pts), cfg)


def test_the_stages_compose_to_fit_surface():
    pts = patch_points(300)
    cfg = get_pipeline("default").with_iters(4)
    cfg.ctrl = (6, 6)
    whole = fit_surface(pts, cfg)
    c = dataclasses.replace(resolve_config(cfg, False), degree=(3, 3))
    target, center, scale = normalise(prepare_target(pts, c), c)
    surface, topology, alternation, _ = initial_state(target, c)
    fitted, history = run_stages(surface, topology, target, c)
    staged = denormalise(fitted, center, scale)
    assert torch.equal(staged.control_points, whole.surface.control_points)
    assert [h["loss"] for h in history] == [h["loss"] for h in whole.history]
    assert alternation == whole.alternation


def test_report_names_dtype_and_device(cloud, tmp_path):
    import json

    assert run(["fit", str(cloud), "--ctrl", "5x5", "--iters", "2", "--dtype", "float32", "--resolution", "12x12",
                "--out", str(tmp_path / "o"), "--quiet", "--no-figures"]) == 0
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["dtype"] == "float32" and report["device"] == "cpu"
    assert math.isfinite(report["metrics"]["to_surface_mean"])


def test_cli_parser_does_not_skip_a_missing_command_module(monkeypatch):
    import nurbskit.cli as cli

    monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("nurbskit.cli.no_such_command",))
    with pytest.raises(ModuleNotFoundError):
        cli.build_parser()
