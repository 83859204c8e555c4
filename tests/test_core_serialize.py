"""nurbskit JSON, geomdl adapters and construction errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import nurbskit
from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume, NurbskitError
from nurbskit.core import from_geomdl, to_geomdl

from _splines import random_params, random_spline


@pytest.mark.parametrize("cls,degrees,sizes", [
    (NURBSCurve, (3,), (7,)), (NURBSSurface, (3, 2), (6, 5)), (NURBSVolume, (2, 1, 3), (4, 3, 5)),
])
def test_json_round_trip_is_exact(tmp_path, cls, degrees, sizes):
    s = random_spline(cls, np.random.default_rng(0), degrees, sizes, 3, True)
    path = tmp_path / "obj.json"
    nurbskit.save(s, path)
    data = json.loads(path.read_text())
    assert data["format"] == "nurbskit" and data["version"] == 1 and data["kind"] == s.kind
    assert np.asarray(data["control_points"]).shape == tuple(sizes) + (3,)
    assert np.asarray(data["weights"]).shape == tuple(sizes)
    back = nurbskit.load(path)
    assert type(back) is cls and back.degrees == s.degrees
    assert torch.equal(back.control_points, s.control_points) and torch.equal(back.weights, s.weights)
    for a, b in zip(back.knot_vectors, s.knot_vectors):
        assert torch.equal(a, b)


@pytest.mark.parametrize("cls,degrees,sizes", [
    (NURBSCurve, (4,), (9,)), (NURBSSurface, (2, 3), (5, 7)), (NURBSVolume, (2, 1, 3), (4, 3, 5)),
])
def test_geomdl_round_trip(cls, degrees, sizes):
    rng = np.random.default_rng(1)
    s = random_spline(cls, rng, degrees, sizes, 3, True, domains=[(0.0, 1.0)] * len(degrees))
    back = from_geomdl(to_geomdl(s))
    torch.testing.assert_close(back.control_points, s.control_points, atol=1e-14, rtol=1e-14)
    torch.testing.assert_close(back.weights, s.weights, atol=1e-15, rtol=0)
    params = random_params(rng, s, 10)
    if cls is NURBSCurve:
        params = params[:, 0]
    torch.testing.assert_close(back.evaluate(params), s.evaluate(params), atol=1e-13, rtol=0)


def test_geomdl_surface_order_is_v_fastest():
    cp = torch.arange(2 * 3 * 3, dtype=torch.float64).reshape(2, 3, 3)
    g = to_geomdl(NURBSSurface(cp, (1, 2)))
    assert g.ctrlpts[1] == cp[0, 1].tolist()  # index iu * n_v + iv
    assert g.ctrlpts[3] == cp[1, 0].tolist()


@pytest.mark.parametrize("make,message", [
    (lambda: NURBSSurface(torch.rand(14, 13, 3), (3, 3), [torch.linspace(0, 1, 17), None]), "has 17 knots; degree 3 with 14 control points needs 18"),
    (lambda: NURBSCurve(torch.rand(5, 2), 2, torch.tensor([0, 0, 0, .6, .4, 1, 1, 1.])), "decreases at index 4"),
    (lambda: NURBSCurve(torch.rand(5, 2), 2, weights=torch.tensor([1, 1, 0, 1, 1.])), "positive"),
    (lambda: NURBSCurve(torch.rand(5, 2), 2, weights=torch.ones(4)), "shape (5,)"),
    (lambda: NURBSSurface(torch.rand(5, 3), (2, 2)), "(n_u, n_v, dim)"),
    (lambda: NURBSSurface(torch.rand(3, 5, 3), (3, 2)), "needs at least 4 control points, got 3"),
    (lambda: NURBSCurve(torch.tensor([[0.0, float("nan")], [1, 1], [2, 2]]), 1), "NaN"),
    (lambda: NURBSCurve(torch.rand(5, 2), 2, torch.tensor([0, 0, 0, 0, 0, 0, 0, 0.])), "empty domain"),
])
def test_construction_errors_say_what_and_where(make, message):
    with pytest.raises(NurbskitError) as info:
        make()
    assert message in str(info.value)


def test_load_reports_bad_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(NurbskitError, match="not valid JSON"):
        nurbskit.load(bad)
    bad.write_text(json.dumps({"format": "other"}))
    with pytest.raises(NurbskitError, match="format"):
        nurbskit.load(bad)
    with pytest.raises(NurbskitError, match="no such file"):
        nurbskit.load(tmp_path / "missing.json")
    bad.write_text(json.dumps({"format": "nurbskit", "version": 1, "kind": "curve", "degrees": [2],
                               "knot_vectors": [[0, 0, 0, 1, 1]], "control_points": [[0, 0], [1, 1], [2, 0]],
                               "weights": [1, 1, 1]}))
    with pytest.raises(NurbskitError, match="needs 6"):
        nurbskit.load(bad)
