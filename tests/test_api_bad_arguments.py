"""The Python API refuses arguments it cannot serve with one clear NurbskitError, instead of
a result for the wrong object, a torch error from deep inside, or an allocation the
machine cannot make (the twenty-third session's sweep of the public functions)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nurbskit
from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume, NurbskitError
from nurbskit.io import read_nurbs, to_geomdl_json, write_nurbs

F64 = torch.float64


@pytest.fixture
def surface():
    return NURBSSurface(torch.rand(5, 5, 3, dtype=F64, generator=torch.Generator().manual_seed(0)))


def test_a_batch_is_not_flattened_into_one_spline_on_export(tmp_path):
    batch = NURBSSurface(torch.rand(2, 4, 4, 3, dtype=F64))
    single = "works on one surface, got a batch of shape \\(2,\\): select an element first"
    with pytest.raises(NurbskitError, match="to_geomdl " + single):
        nurbskit.to_geomdl(batch)
    with pytest.raises(NurbskitError, match="to_geomdl_json " + single):
        to_geomdl_json(batch)
    for name in ("b.ctrlpts", "b.cptw", "b.smesh"):
        with pytest.raises(NurbskitError, match=single):
            write_nurbs(tmp_path / name, batch)
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    write_nurbs(tmp_path / "b.json", batch)  # nurbskit JSON holds a batch
    assert read_nurbs(tmp_path / "b.json").batch_shape == (2,)
    # one element converts
    g = nurbskit.to_geomdl(batch[1])
    assert len(g.ctrlpts) == 16


def test_project_points_checks_its_warm_start_and_options(surface):
    points = torch.rand(3, 3, dtype=F64)
    bad = [
        (dict(params=torch.full((3, 2), float("nan"), dtype=F64)), "params \\(the warm start\\) contain NaN"),
        (dict(params=torch.rand(4, 2, dtype=F64)), "params must have shape \\(3, 2\\), one start per point, got \\(4, 2\\)"),
        (dict(tol=-1.0), "tol must be a positive number, got -1.0"),
        (dict(tol=float("nan")), "tol must be a positive number, got nan"),
        (dict(check_every=-1), "check_every must be >= 0"),
    ]
    for options, message in bad:
        with pytest.raises(NurbskitError, match=message):
            nurbskit.project_points(surface, points, **options)
    warm = nurbskit.project_points(surface, points).params
    again = nurbskit.project_points(surface, points, params=warm)
    assert torch.equal(again.params.isfinite(), torch.ones_like(warm, dtype=torch.bool))
    curve = NURBSCurve(torch.rand(5, 2, dtype=F64))
    assert nurbskit.project_points(curve, torch.rand(4, 2, dtype=F64), params=torch.rand(4, dtype=F64)).params.shape == (4,)


def test_parameters_orders_and_axes_are_checked(surface):
    curve = NURBSCurve(torch.rand(5, 2, dtype=F64))
    with pytest.raises(NurbskitError, match=r"curve parameters must have shape \(\.\.\., M\), got the single number 0\.5: pass \[u\]"):
        curve.evaluate(0.5)
    assert curve.evaluate([0.5]).shape == (1, 2)
    for call in (lambda: surface.sample(3, order=-1), lambda: surface.derivatives([[0.5, 0.5]], order=1.5),
                 lambda: surface.evaluate_grid([0.5], [0.5], order=None)):
        with pytest.raises(NurbskitError, match="derivative order must be an integer >= 0"):
            call()
    with pytest.raises(NurbskitError, match=r"the u axis must have shape \(R,\), got \(3, 4\)"):
        surface.evaluate_grid(torch.rand(3, 4, dtype=F64), torch.rand(5, dtype=F64))
    flat = NURBSSurface(torch.rand(4, 4, 2, dtype=F64))
    for call, op in ((lambda: flat.normals([[0.5, 0.5]]), "normals"), (lambda: flat.normals_grid([0.5], [0.5]), "normals_grid")):
        with pytest.raises(NurbskitError, match=op + " needs a surface in 3-D, got control points of dimension 2"):
            call()


def test_resolutions_are_whole_numbers(surface):
    # integers of any kind serve
    assert nurbskit.tessellate(surface, np.int64(4)).vertices.shape == (16, 3)
    assert surface.sample(torch.tensor(4)).shape == (4, 4, 3)
    assert surface.sample(np.array([4, 5])).shape == (4, 5, 3)
    for call, op, low in ((lambda r: surface.sample(r), "sample", 1), (lambda r: nurbskit.tessellate(surface, r), "tessellate", 2)):
        for r in (2.5, None, (2.5, 3), (4, 5, 6), "4"):
            with pytest.raises(NurbskitError, match=f"{op}: resolution must be an int or 2 ints, each >= {low}"):
                call(r)


def test_grids_that_cannot_fit_are_refused_before_they_start(surface):
    for call, op in ((lambda: surface.sample(10**6), "sample"), (lambda: nurbskit.tessellate(surface, 10**7), "tessellate")):
        with pytest.raises(NurbskitError, match=op + r" at resolution .* needs about .* of memory but about .* is available"):
            call()


def test_degrees_are_integers():
    assert NURBSSurface(torch.rand(4, 4, 3), degrees=3).degrees == (3, 3)  # one for every direction
    assert NURBSSurface(torch.rand(4, 4, 3), degrees=np.array([2, 3])).degrees == (2, 3)
    with pytest.raises(NurbskitError, match="curve degree must be an integer, got 2.7"):
        NURBSCurve(torch.rand(4, 3), degree=2.7)
    with pytest.raises(NurbskitError, match="curve degree must be an integer, got None"):
        NURBSCurve(torch.rand(4, 3), degree=None)
    with pytest.raises(NurbskitError, match=r"surface degrees must be 2 integers, got \(3, 2.5\)"):
        NURBSSurface(torch.rand(4, 4, 3), degrees=(3, 2.5))


def test_files_and_conversions_name_what_they_need(tmp_path, surface):
    with pytest.raises(NurbskitError, match="save needs a NURBSCurve, NURBSSurface or NURBSVolume, got Tensor"):
        nurbskit.save(torch.rand(3), tmp_path / "x.json")
    with pytest.raises(NurbskitError, match="is a directory, expected a file name"):
        nurbskit.save(surface, tmp_path)
    with pytest.raises(NurbskitError, match="from_geomdl needs a geomdl curve, surface or volume, got str"):
        nurbskit.from_geomdl("abc")
    with pytest.raises(NurbskitError, match="geomdl holds volumes with 3-D control points, this one's are 1-D"):
        nurbskit.to_geomdl(NURBSVolume(torch.rand(4, 4, 4, 1)))
    path = tmp_path / "one.json"
    nurbskit.save(surface, path)
    with pytest.raises(NurbskitError, match="index 5 is out of range; the file holds one object"):
        read_nurbs(path, index=5)
    for call in (lambda: read_nurbs(path, dtype=torch.int64), lambda: nurbskit.load(path, dtype=torch.int64)):
        with pytest.raises(NurbskitError, match="dtype: expected a floating-point dtype, got torch.int64"):
            call()
    assert read_nurbs(path, index=-1).sizes == (5, 5)


def test_curves_from_image_checks_its_iterations():
    image = np.full((32, 32), 255, np.uint8)
    image[16, 4:28] = 0
    with pytest.raises(NurbskitError, match="refine_iterations: expected an integer >= 0, got -1"):
        nurbskit.curves_from_image(image, refine=True, refine_iterations=-1)
