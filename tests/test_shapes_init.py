"""The network-initialiser hook of the shape fitter (``init="network"``).

The learned model lives in ``nurbskit.shapes.nets`` (another package); here a fake
``initial_guess`` stands in for it (monkeypatched into ``sys.modules``), returning the
true axis and profile (or a perturbed one), so the hook, the contract's frames and the
refinement after it are tested without any trained weights.
"""

from __future__ import annotations

import json
import math
import sys
import types

import numpy as np
import pytest
import torch

from nurbskit.cli import main
from nurbskit.core.curve import NURBSCurve
from nurbskit.errors import NurbskitError, OptionError
from nurbskit.shapes import axis_angle_degrees, fit_shape, plane_basis
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud

F64 = torch.float64


def _true_guess(cloud, kind: str) -> dict:
    """The contract's guess made from the synthetic truth: profile control points in the
    (r, z) frame (revolution) or the plane_basis frame (extrusion)."""
    o, d = cloud.axis_point, cloud.axis_direction
    P = cloud.surface.control_points[0]  # row u = 0: the 3-D profile
    rel = P - o
    if kind == "revolution":
        z = rel @ d
        r = (rel - z[:, None] * d).norm(dim=-1)
        xy = torch.stack([r, z], -1)
    else:
        e1, e2 = plane_basis(d)
        xy = torch.stack([rel @ e1, rel @ e2], -1)
    kv = cloud.surface.knot_vectors[1]
    return {"axis_point": o.clone(), "axis_direction": d.clone(),
            "profile": NURBSCurve(xy, degree=cloud.surface.degrees[1], knot_vector=kv)}


def _install(monkeypatch, guess_fn):
    calls = []

    def initial_guess(points, kind):
        calls.append((tuple(points.shape), kind))
        return guess_fn(points, kind)

    fake = types.ModuleType("nurbskit.shapes.nets")
    fake.initial_guess = initial_guess
    monkeypatch.setitem(sys.modules, "nurbskit.shapes.nets", fake)
    return calls


@pytest.mark.parametrize("kind", ["revolution", "extrusion"])
def test_true_guess_without_refinement_is_the_true_surface(monkeypatch, kind):
    c = vase_cloud(800, 0.0, 3) if kind == "revolution" else extrusion_cloud(800, 0.0, 3, "smooth")
    calls = _install(monkeypatch, lambda p, k: _true_guess(c, k))
    fit = fit_shape(c.points, kind, refine=False, init="network")
    assert calls == [((800, 3), kind)]
    assert fit.init == "network" and fit.iterations == 0
    # the contract's frames are the ones the fitter uses: the truth fits to round-off
    assert fit.distance_mean < 1e-9
    assert axis_angle_degrees(fit.axis["direction"], c.axis_direction) < 1e-9


@pytest.mark.parametrize("kind", ["revolution", "extrusion"])
def test_perturbed_guess_is_refined(monkeypatch, kind):
    c = vase_cloud(1000, 0.0, 4) if kind == "revolution" else extrusion_cloud(1000, 0.0, 4, "smooth")

    def tilted(p, k):
        g = _true_guess(c, k)
        e1, _ = plane_basis(g["axis_direction"])
        g["axis_direction"] = g["axis_direction"] + math.tan(math.radians(3)) * e1  # 3 degrees off
        return g

    _install(monkeypatch, tilted)
    start = fit_shape(c.points, kind, refine=False, init="network")
    fit = fit_shape(c.points, kind, iterations=30, init="network")
    assert axis_angle_degrees(start.axis["direction"], c.axis_direction) == pytest.approx(3.0, abs=1e-6)
    assert axis_angle_degrees(fit.axis["direction"], c.axis_direction) < 0.5
    assert fit.distance_mean < start.distance_mean / 5


def test_missing_network_is_a_one_line_option_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "nurbskit.shapes.nets", None)  # import fails as if absent
    c = vase_cloud(300, 0.0, 1)
    with pytest.raises(OptionError, match="trained point-cloud model"):
        fit_shape(c.points, "revolution", init="network")
    src = tmp_path / "vase.npy"
    np.save(src, c.points.numpy())
    assert main(["shape", str(src), "--init", "network", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nurbskit train revolve" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_bad_guess_and_bad_init(monkeypatch):
    c = vase_cloud(300, 0.0, 1)
    _install(monkeypatch, lambda p, k: {"axis_point": torch.zeros(3), "axis_direction": torch.zeros(3),
                                        "profile": None})
    with pytest.raises(NurbskitError, match="axis_direction"):
        fit_shape(c.points, "revolution", init="network")
    _install(monkeypatch, lambda p, k: {"axis_point": torch.zeros(3), "axis_direction": torch.ones(3),
                                        "profile": NURBSCurve(torch.rand(5, 3, dtype=F64), degree=3)})
    with pytest.raises(NurbskitError, match=r"\(n, 2\)"):
        fit_shape(c.points, "revolution", init="network")
    with pytest.raises(OptionError, match="init"):
        fit_shape(c.points, "revolution", init="neural")


def test_cli_network_init_report(monkeypatch, tmp_path):
    c = vase_cloud(600, 0.0, 5)
    _install(monkeypatch, lambda p, k: _true_guess(c, k))
    src = tmp_path / "vase.npy"
    np.save(src, c.points.numpy())
    out = tmp_path / "o"
    assert main(["shape", str(src), "--kind", "revolution", "--init", "network", "--iters", "3",
                 "--no-figures", "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["init"] == "network" and rep["metrics"]["to_surface_mean"] < 1e-4
