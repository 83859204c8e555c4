"""Every registered pipeline, the default pipeline's accuracy, supervised exactness, config."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
import torch

from nurbskit.core import NURBSSurface
from nurbskit.errors import NurbskitError, OptionError
from nurbskit.fit import PIPELINES, FitConfig, config_from_dict, config_to_dict, fit_surface, get_pipeline
from nurbskit.fit.init import initial_surface, looks_closed, plane_frame
from nurbskit.fit.outputs import fit_report, write_fit_outputs

from _assert import assert_close

F64 = torch.float64
OUTPUT_FILES = {"surface.json", "points.off", "control_points.off", "report.json", "config.json",
                "wireframe.png", "clouds.png", "error_map.png", "loss.png"}



def _gen(seed):
    return torch.Generator().manual_seed(seed)


def smooth_patch(n_points: int, noise: float, seed: int, n_ctrl: int = 6, amplitude: float = 0.25):
    """A random smooth open patch sampled at random parameters, plus Gaussian noise.

    ``noise`` is the standard deviation per coordinate as a fraction of the bounding-box
    diagonal. Returns ``(points (N, 3), surface)``.
    """
    g = _gen(seed)
    t = torch.linspace(0, 1, n_ctrl, dtype=F64)
    u, v = torch.meshgrid(t, t, indexing="ij")
    z = amplitude * (2 * torch.rand(n_ctrl, n_ctrl, generator=g, dtype=F64) - 1)
    surface = NURBSSurface(torch.stack([u, v, z], -1), (3, 3))
    uv = torch.rand(n_points, 2, generator=g, dtype=F64)
    x = surface.evaluate(uv)
    diag = float((x.max(0).values - x.min(0).values).norm())
    return x + noise * diag * torch.randn(x.shape, generator=g, dtype=F64), surface


def sphere_points(n: int, seed: int = 0):
    g = _gen(seed)
    x = torch.randn(n, 3, generator=g, dtype=F64)
    return x / x.norm(dim=-1, keepdim=True)


def _tiny(name: str) -> FitConfig:
    """The preset with few iterations and small grids, for a smoke run."""
    cfg = get_pipeline(name).with_iters(3)
    cfg.resolution = (10, 10)
    cfg.alternation = dataclasses.replace(cfg.alternation, rounds=min(cfg.alternation.rounds, 2))
    for s in cfg.stages:
        if s.resolution is not None:
            s.resolution = (12, 12)
        if s.rematch_every:
            s.rematch_every = 2
    return cfg


@pytest.mark.parametrize("name", list(PIPELINES))
def test_every_pipeline_runs_and_writes_all_outputs(name, tmp_path):
    pts, surface = smooth_patch(81, 0.0, seed=1, n_ctrl=5)
    cfg = _tiny(name)
    if PIPELINES[name].supervised:
        result = fit_surface(config=cfg, target_surface=surface)
    else:
        cfg.ctrl = (6, 6)
        result = fit_surface(pts, cfg)
    # SC may stop early at its loss threshold (its least-squares start is already exact).
    assert 1 <= result.iterations <= cfg.total_iters
    assert result.iterations == cfg.total_iters or cfg.stages[-1].loss_threshold > 0
    assert all(math.isfinite(h["loss"]) for h in result.history)
    # The loss went down in every stage that ran more than one iteration (stages differ in
    # their loss, so they are compared with themselves). SC starts at the exact
    # least-squares solution, and SB on a target of its own sizes gets there after its knot
    # placement: nothing is left to lower.
    stages = {}
    for h in result.history:
        stages.setdefault(h["stage"], []).append(h["loss"])
    if name in ("SC", "SB"):
        assert result.history[-1]["loss"] <= result.history[0]["loss"] < 1e-20
    else:
        compared = [losses for losses in stages.values() if len(losses) > 1]
        assert compared and all(losses[-1] < losses[0] for losses in compared), stages
    report = write_fit_outputs(result, tmp_path)
    assert {p.name for p in tmp_path.iterdir()} == OUTPUT_FILES
    saved = json.loads((tmp_path / "report.json").read_text())
    assert saved["pipeline"] == name and saved["iterations"] == result.iterations
    for key in ("chamfer", "hausdorff", "laplacian", "combined", "to_surface_mean", "to_surface_p95"):
        assert math.isfinite(saved["metrics"][key]), key
    assert saved["seconds_per_iteration"] >= 0
    assert config_from_dict(json.loads((tmp_path / "config.json").read_text())).pipeline == name
    assert report["files"] == saved["files"]


def test_supervised_sc_recovers_a_known_surface_exactly():
    g = _gen(3)
    target = NURBSSurface(torch.rand(7, 6, 3, generator=g, dtype=F64), (3, 2),
                          weights=0.5 + torch.rand(7, 6, generator=g, dtype=F64))
    result = fit_surface(config="SC", target_surface=target)
    grid = result.surface.sample((64, 64))
    truth = target.sample((64, 64))
    rel = float((grid - truth).norm() / truth.norm())
    assert rel < 1e-8
    assert_close(result.surface.control_points, target.control_points, atol=1e-8)


def test_supervised_sc_from_random_control_points_converges():
    # The thesis's start (random control points): L-BFGS on the same quadratic.
    _, target = smooth_patch(10, 0.0, seed=4, n_ctrl=5)
    cfg = get_pipeline("SC")
    cfg.init.kind = "target"
    cfg.stages[0].iters = 150
    result = fit_surface(config=cfg, target_surface=target)
    report = fit_report(result)
    assert report["rms_normalized"] < 1e-4


def test_supervised_sb_moves_the_knots_to_fit_a_non_uniform_surface():
    g = _gen(5)
    ku = torch.tensor([0, 0, 0, 0, 0.15, 0.2, 1, 1, 1, 1], dtype=F64)
    _, base = smooth_patch(10, 0.0, seed=5, n_ctrl=6)
    target = NURBSSurface(base.control_points, (3, 3), [ku, None])
    cfg = get_pipeline("SB")
    cfg.stages[0].iters, cfg.stages[1].iters = 60, 10
    cfg.resolution = (24, 24)
    result = fit_surface(config=cfg, target_surface=target)
    del g
    assert fit_report(result)["rms_normalized"] < 1e-3
    # Fixed uniform knots cannot do as well (SC-like fit at uniform knots).
    uniform = dataclasses.replace(get_pipeline("SC"), init=dataclasses.replace(get_pipeline("SC").init, kind="lstsq"))
    flat = fit_surface(config=uniform, target_grid=target.sample((24, 24)))
    assert fit_report(result)["rms_normalized"] < 0.5 * fit_report(flat)["rms_normalized"]


@pytest.mark.parametrize("seed", [0, 1])
def test_default_recovers_noisy_smooth_patches(seed):
    pts, surface = smooth_patch(2000, 0.001, seed=seed)
    cfg = get_pipeline("default")
    cfg.ctrl = (10, 10)
    result = fit_surface(pts, cfg)
    m = fit_report(result)["metrics_normalized"]
    assert not result.closed_v
    assert m["to_surface_mean"] <= 0.003
    assert m["to_surface_p95"] <= 0.008
    assert m["overshoot_p95"] <= 0.03
    # Fit units: the noise itself is about 0.0008 of the diagonal on average along the normal.
    clean = surface.evaluate(torch.rand(500, 2, generator=_gen(9), dtype=F64))
    from nurbskit.core.project import project_points

    d = project_points(result.surface, clean).distance / fit_report(result)["metrics"]["diagonal"]
    assert float(d.mean()) < 0.003


def test_closed_shape_with_the_cylinder_cage():
    pts = sphere_points(1500)
    cfg = get_pipeline("default")
    cfg.init.kind = "cylinder"
    cfg.ctrl = (12, 12)
    result = fit_surface(pts, cfg)
    assert result.closed_v
    m = fit_report(result)["metrics_normalized"]
    assert m["to_surface_mean"] <= 0.01
    # The seam stays closed.
    u = torch.linspace(0, 1, 9, dtype=F64)
    a = result.surface.evaluate(torch.stack([u, torch.zeros_like(u)], -1))
    b = result.surface.evaluate(torch.stack([u, torch.ones_like(u)], -1))
    assert_close(a, b, atol=1e-9)


def test_auto_topology_and_rectangle_frame():
    assert looks_closed(sphere_points(800))
    pts, _ = smooth_patch(800, 0.0, seed=2)
    assert not looks_closed(pts)
    # A square rotated by 30 degrees in its plane keeps a square parameter box.
    c, s = math.cos(0.52), math.sin(0.52)
    R = torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=F64)
    sq = torch.rand(500, 2, generator=_gen(3), dtype=F64)
    rot = torch.cat([sq, torch.zeros(500, 1, dtype=F64)], -1) @ R.T
    _, axes = plane_frame(rot)
    xy = rot @ axes[:2].T
    extent = xy.max(0).values - xy.min(0).values
    assert_close(extent, torch.ones(2, dtype=F64), atol=0.03)


def test_random_start_follows_the_seed():
    pts, _ = smooth_patch(100, 0.0, seed=6)
    a, _ = initial_surface(pts, "random", (4, 4), (3, 3), generator=_gen(7))
    b, _ = initial_surface(pts, "random", (4, 4), (3, 3), generator=_gen(7))
    c, _ = initial_surface(pts, "random", (4, 4), (3, 3), generator=_gen(8))
    assert torch.equal(a.control_points, b.control_points)
    assert not torch.equal(a.control_points, c.control_points)


def test_callback_threshold_and_iteration_sharing():
    pts, _ = smooth_patch(200, 0.0, seed=7)
    cfg = get_pipeline("UCDC").with_iters(30)
    cfg.ctrl = (8, 8)
    cfg.stages[0].resolution = (16, 16)
    cfg.stages[0].loss_threshold = 1.0  # any loss is below: stop after the first iteration
    seen = []
    result = fit_surface(pts, cfg, callback=seen.append)
    assert len(seen) == 1 == result.iterations
    assert seen[0].stage == "train" and seen[0].loss > 0
    um = get_pipeline("UM").with_iters(11)
    assert [s.iters for s in um.stages] == [6, 5] or sum(s.iters for s in um.stages) == 11


def test_thesis_loss_weights_are_the_defaults():
    w = {name: get_pipeline(name).stages[0].loss for name in ("UCDL", "UCDH", "UCDHL")}
    assert (w["UCDL"].chamfer, w["UCDL"].laplacian) == (1.0, 0.001)
    assert (w["UCDH"].chamfer, w["UCDH"].hausdorff) == (1.0, 0.01)
    assert (w["UCDHL"].laplacian, w["UCDHL"].hausdorff) == (0.001, 0.01)
    assert get_pipeline("UCD").stages[0].resolution == (100, 100)
    assert get_pipeline("UC").stages[0].same_size_as_input
    assert get_pipeline("UP2P").stages[0].loss.point_to_surface == 1.0
    assert get_pipeline("UM").stages[1].rematch_every > 0


def test_config_round_trip_and_validation():
    cfg = get_pipeline("UCDL")
    again = config_from_dict(json.loads(json.dumps(config_to_dict(cfg))))
    assert again == cfg
    with pytest.raises(OptionError, match="unknown pipeline"):
        get_pipeline("UXYZ")
    with pytest.raises(OptionError, match="ctrl"):
        dataclasses.replace(cfg, ctrl=(2, 15)).validate()
    bad = get_pipeline("UC")
    bad.stages[0].lr = -1.0
    with pytest.raises(OptionError, match=r"lr must be in \(0, 10\], got -1"):
        bad.validate()
    with pytest.raises(OptionError, match="unknown field"):
        config_from_dict({"pipeline": "x", "colour": 3})
    # files written when the configuration still named a device and a dtype
    assert config_from_dict({**config_to_dict(cfg), "device": "cpu", "dtype": "float64"}) == cfg


def test_bad_inputs_give_clear_errors():
    with pytest.raises(OptionError, match="supervised"):
        fit_surface(torch.rand(50, 3, dtype=F64), "SC")
    with pytest.raises(NurbskitError, match=r"shape \(N, 3\)"):
        fit_surface(torch.rand(50, 2, dtype=F64), "UC")
    with pytest.raises(NurbskitError, match="NaN"):
        fit_surface(torch.full((50, 3), float("nan"), dtype=F64), "UC")
    with pytest.raises(NurbskitError, match="coincide"):
        fit_surface(torch.ones(50, 3, dtype=F64), "UC")


def test_sparse_flat_sheet_is_not_closed():
    # 300 points on a unit square: neighbours in the projection are far apart in absolute
    # terms, but no farther in 3D than in the projection.
    g = _gen(11)
    flat = torch.cat([torch.rand(300, 2, generator=g, dtype=F64), torch.zeros(300, 1, dtype=F64)], -1)
    assert not looks_closed(flat)
    assert not looks_closed(torch.rand(10, 3, generator=g, dtype=F64))


def test_large_inputs_are_fitted_on_a_seeded_subset_and_reported_in_full(monkeypatch):
    import nurbskit.fit.api as api

    seen = []
    original = api.initial_surface

    def spy(points, *args, **kwargs):
        seen.append(points.shape[0])
        return original(points, *args, **kwargs)

    monkeypatch.setattr(api, "initial_surface", spy)
    pts, _ = smooth_patch(3000, 0.001, seed=3)
    cfg = get_pipeline("default").with_iters(4)
    cfg.max_points = 500
    cfg.alternation = dataclasses.replace(cfg.alternation, rounds=2)
    result = fit_surface(pts, cfg)
    assert seen == [500]  # the fit saw the subset
    assert result.points.shape[0] == 3000  # the report measures every point
    report = fit_report(result)
    assert report["points"] == 3000 and report["metrics_normalized"]["to_surface_mean"] < 0.01
    cfg.max_points = 0  # 0: all points
    fit_surface(pts, cfg)
    assert seen[-1] == 3000
    cfg.max_points = 2
    with pytest.raises(OptionError, match="max_points"):
        fit_surface(pts, cfg)


def test_progress_hears_every_alternation_round_and_iteration():
    # A large net's alternation round solves a large system (seconds each): the callback
    # hears of each round before the iterations, within config.progress_steps reports.
    g = torch.rand(600, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(5))
    pts = torch.stack([g[:, 0], g[:, 1], 0.2 * torch.sin(3 * g[:, 0]) * torch.cos(2 * g[:, 1])], -1)
    cfg = get_pipeline("default")
    reports = []
    fit_surface(pts, cfg, callback=reports.append)
    stages = [r.stage for r in reports]
    rounds = stages.count("alternation")
    assert 1 <= rounds <= cfg.alternation.rounds and set(stages[:rounds]) == {"alternation"}
    assert [r.iteration for r in reports[:rounds]] == list(range(1, rounds + 1))
    assert len(reports) - rounds == cfg.total_iters
    assert len(reports) <= cfg.progress_steps == cfg.total_iters + cfg.alternation.rounds
