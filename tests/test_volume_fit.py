"""fit_silhouettes end to end on drawings made by code (small sizes; ~seconds each)."""

import pytest
import torch

import nurbskit
from nurbskit.errors import OptionError
from nurbskit.volume import VolumeFitConfig, fit_silhouettes, get_preset, visual_hull_iou
from nurbskit.volume.shapes import paper_drawings, solid_drawings, sphere_and_box

from _assert import assert_close


@pytest.fixture(scope="module")
def sphere_box():
    return solid_drawings(sphere_and_box, 96)


@pytest.fixture(scope="module")
def paper_set():
    return paper_drawings(96)


SMALL = dict(control_size=16, grid=48, mesh_resolution=96, iou_resolution=128)


def fit(drawings, callback=None, **settings):
    """fit_silhouettes with a VolumeFitConfig of ``settings`` (init 'auto': by the loss)."""
    return fit_silhouettes(drawings, VolumeFitConfig(**{"init": "auto", **settings}), callback=callback)


def test_consistent_silhouettes_are_reproduced(sphere_box):
    d = sphere_box
    result = fit(d, loss="silhouette", **SMALL)
    assert result.hull_iou == {"front": 1.0, "left": 1.0, "top": 1.0}  # consistent by construction
    assert result.costs["total"] < result.costs["initial_total"]
    for view, score in result.iou.items():
        assert score >= 0.95, (view, result.iou)


def test_paper_loss_on_consistent_silhouettes(sphere_box):
    d = sphere_box
    result = fit(d, loss="paper", **SMALL)
    assert min(result.iou.values()) >= 0.93, result.iou
    assert result.costs["total"] < 0.1 * result.costs["initial_total"]
    assert result.history[0] == result.costs["initial_total"]


def test_inconsistent_set_gets_close_to_the_visual_hull(paper_set):
    d = paper_set
    hull = visual_hull_iou(d, 128)
    assert hull["top"] < 0.99  # no solid matches all three: the hull misses part of the heart
    result = fit(d, loss="silhouette", **SMALL)
    assert result.hull_iou == hull
    assert result.costs["total"] < result.costs["initial_total"]
    for view in hull:
        assert result.iou[view] >= 0.9 * hull[view], (view, result.iou, hull)
    assert not result.mesh.is_empty


def test_result_volume_is_a_scalar_field_with_positive_weights(paper_set):
    d = paper_set
    seen = []
    result = fit(
        d, control_size=(6, 7, 5), grid=12, iterations=5,
        callback=lambda stage, done, total, cost: seen.append((stage, done, total)),
    )
    volume, mesh = result  # unpacks as (volume, mesh)
    assert volume.control_points.shape == (6, 7, 5, 1) and volume.degrees == (2, 2, 2)
    assert (volume.weights > 0).all()
    assert volume.dtype == torch.float32
    assert mesh is result.mesh
    assert seen[-1] == ("mesh", 1, 1) and ("fit", 5, 5) in seen
    # the volume evaluates, through the core, to the field the mesh was cut from
    grid = volume.sample(12)[..., 0]
    from nurbskit.volume.mesh import isosurface

    again = isosurface(grid, 0.5)
    assert again.vertices.shape == mesh.vertices.shape
    report = result.report()
    assert set(report["iou"]) == {"front", "left", "top"} and report["config"]["grid"] == [12, 12, 12]


def test_zero_iterations_keeps_the_initial_field(paper_set):
    d = paper_set
    result = fit(d, control_size=5, grid=8, iterations=0)
    assert torch.equal(result.volume.control_points, torch.zeros(5, 5, 5, 1))
    assert result.mesh.is_empty and "no surface at isovalue 0.5" in result.message
    assert result.iterations == 0


def test_float64_inputs_give_a_float64_volume(paper_set):
    d = {k: v.double() for k, v in paper_set.items()}
    result = fit(d, control_size=5, grid=8, iterations=2)
    assert result.volume.dtype == torch.float64


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(control_size=2), r"control_size must be one or three integers in \[3, 4096\]"),
        (dict(grid=(10, 10)), "grid must be one or three integers"),
        (dict(degree=0), r"degree must be an integer in \[1, 7\]"),
        (dict(iterations=-1), r"iterations must be an integer in \[0, 100,000\]"),
        (dict(loss="chamfer"), "loss must be one of"),
        (dict(init="random"), "init must be one of"),
        (dict(shape_weight=0.0), r"shape_weight must be in \(0, 1e\+06\], got 0 \(without it"),
        (dict(smooth_weight=-1.0), r"smooth_weight must be in \[0, 1e\+06\]"),
        (dict(isovalue=float("nan")), "isovalue must be a finite number"),
        (dict(tolerance=-1.0), r"tolerance must be in \[0, 1\]"),
        (dict(laplacian_unit=0.0), r"laplacian_unit must be in \(0, 1\]"),
        (dict(smooth_samples="all"), "smooth_samples must be one of"),
        (dict(sharpness=-2.0), r"sharpness must be in \(0, 1e\+06\]"),
    ],
)
def test_nonsense_options_are_rejected(paper_set, kwargs, message):
    d = paper_set
    with pytest.raises(OptionError, match=message):
        fit(d, **kwargs)


def test_lazy_top_level_name():
    assert nurbskit.fit_silhouettes is fit_silhouettes


def test_smoothness_samples_are_the_grid_or_the_span_midpoints():
    from nurbskit.core.knots import clamped_uniform
    from nurbskit.volume.fit import _smoothness_axis

    kv = clamped_uniform(7, 2, dtype=torch.float64)  # 5 knot spans of width 0.2
    coarse = torch.linspace(0, 1, 5, dtype=torch.float64)
    assert _smoothness_axis(kv, 2, 7, coarse) is coarse
    fine = torch.linspace(0, 1, 40, dtype=torch.float64)
    assert_close(_smoothness_axis(kv, 2, 7, fine), torch.tensor([0.1, 0.3, 0.5, 0.7, 0.9], dtype=torch.float64))


def test_auto_smoothness_samples_equal_grid_samples_when_the_grid_is_coarse(paper_set):
    d = paper_set
    kw = dict(control_size=12, grid=8, iterations=3)  # 8 grid points < 10 knot spans
    a = fit(d, smooth_samples="auto", **kw)
    b = fit(d, smooth_samples="grid", **kw)
    assert a.history == b.history
    # on a fine grid they differ, and both still fit
    kw = dict(control_size=8, grid=24, iterations=10)
    c = fit(d, smooth_samples="auto", **kw)
    e = fit(d, smooth_samples="grid", **kw)
    assert c.costs["smooth"] != e.costs["smooth"]
    assert c.costs["total"] < c.costs["initial_total"] and e.costs["total"] < e.costs["initial_total"]


def test_zero_tolerance_runs_every_iteration(sphere_box):
    d = sphere_box
    result = fit(d, control_size=12, grid=8, iterations=15, tolerance=0.0)
    assert result.iterations == 15


def test_history_holds_one_cost_per_iteration(sphere_box):
    d = sphere_box
    seen = []
    result = fit(
        d, control_size=8, grid=10, iterations=12, tolerance=0.0,
        callback=lambda stage, done, total, cost: seen.append((stage, done, cost)),
    )
    assert result.iterations == 12 and len(result.history) == 13
    assert [s[1] for s in seen if s[0] == "fit"] == list(range(1, 13))
    assert [s[2] for s in seen if s[0] == "fit"] == result.history[1:]
    assert result.history[-1] == result.costs["total"]
    # L-BFGS with a strong Wolfe line search accepts only decreasing steps
    assert all(b <= a * (1 + 1e-6) for a, b in zip(result.history, result.history[1:]))
