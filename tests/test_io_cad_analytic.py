"""Surfaces of revolution and extrusion written as OpenCASCADE's analytic surfaces
(STEP ``SURFACE_OF_REVOLUTION`` / ``SURFACE_OF_LINEAR_EXTRUSION``, IGES 120 / 122):
valid for OCC's checker, and read back (OCC converts them to B-splines) onto the same
points as ``nurbskit.core.construct.revolve`` / ``extrude``, both ways.

Oracles: ``nurbskit.core.construct`` (the exact NURBS), OCC's ``BRepCheck_Analyzer``;
distances measured with ``nurbskit.core.project.project_points`` from samples of one
surface to the other.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from _cad import require_extra
from _cli import run_shape_cli

import nurbskit
from nurbskit.core.construct import extrude, revolve
from nurbskit.core.project import project_points
from nurbskit.errors import InputError, OptionError

OCP = require_extra("OCP")

from nurbskit.io import cad  # noqa: E402
from nurbskit.io.cad import ExtrudedSurface, RevolvedSurface, swept_from_report  # noqa: E402

ENTITY = {"step": {"revolution": "SURFACE_OF_REVOLUTION", "extrusion": "SURFACE_OF_LINEAR_EXTRUSION"},
          # IGES: the entity type opens the directory entry's first line (columns 1-8)
          "iges": {"revolution": "     120", "extrusion": "     122"}}


def _profile() -> nurbskit.NURBSCurve:
    """A rational cubic away from the axis used below (so the surface has no pole)."""
    cp = torch.tensor([[1.0, 0.2, 0.0], [1.6, 0.3, 0.8], [0.7, 0.1, 1.5], [1.1, 0.0, 2.4], [0.9, -0.1, 3.0]],
                      dtype=torch.float64)
    return nurbskit.NURBSCurve(cp, degree=3, weights=torch.tensor([1.0, 0.8, 1.3, 1.0, 1.1], dtype=torch.float64))


def _samples(surface, n: int = 150, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    (u0, u1), (v0, v1) = surface.domain
    t = torch.rand(n, 2, generator=g, dtype=torch.float64)
    uv = torch.stack([u0 + (u1 - u0) * t[:, 0], v0 + (v1 - v0) * t[:, 1]], -1)
    return surface.evaluate(uv)


def _diagonal(surface) -> float:
    cp = surface.control_points.reshape(-1, 3)
    return float((cp.amax(0) - cp.amin(0)).norm())


def _distance(points: torch.Tensor, surface) -> float:
    proj = project_points(surface, points, starts=3)
    return float((surface.evaluate(proj.params) - points).norm(dim=-1).max())


def _same_point_set(exact, back):
    """Samples of each surface lie on the other within 1e-9 of the diagonal."""
    diag = _diagonal(exact)
    assert _distance(_samples(exact), back) <= 1e-9 * diag
    assert _distance(_samples(back, seed=1), exact) <= 1e-9 * diag


def _half_circle() -> nurbskit.NURBSCurve:
    """Pole to pole in the xz-plane (rational quadratic, exact): revolved about z, the unit sphere."""
    w = math.sqrt(0.5)
    cp = torch.tensor([[0, 0, -1], [1, 0, -1], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=torch.float64)
    return nurbskit.NURBSCurve(cp, degree=2, knot_vector=torch.tensor([0, 0, 0, .5, .5, 1, 1, 1.0], dtype=torch.float64),
                               weights=torch.tensor([1, w, 1, w, 1], dtype=torch.float64))


SWEPT = {
    "sphere (profile on the axis at both ends)": lambda: RevolvedSurface(_half_circle(), [0, 0, 0], [0, 0, 1]),
    "full turn": lambda: RevolvedSurface(_profile(), [0.1, -0.2, 0.0], [0.1, 0.05, 1.0]),
    "partial turn": lambda: RevolvedSurface(_profile(), [0.1, -0.2, 0.0], [0.1, 0.05, 1.0], 2.0),
    "extrusion": lambda: ExtrudedSurface(_profile(), [0.3, 1.0, 0.2], 2.5),
    "negative extrusion": lambda: ExtrudedSurface(_profile(), [0.3, 1.0, 0.2], -1.5),
}


@pytest.mark.parametrize("fmt", ["step", "iges", "brep"])
@pytest.mark.parametrize("name", list(SWEPT))
def test_swept_surface_is_written_analytic_valid_and_on_the_exact_nurbs(tmp_path, name, fmt):
    obj = SWEPT[name]()
    path = tmp_path / f"swept.{fmt}"
    report = cad.write_cad(obj, path)
    assert report["valid"] and report["faces"] == 1
    text = path.read_text(errors="replace")
    if fmt in ENTITY:
        assert ENTITY[fmt][obj.kind] in text
    model = cad.read_cad(path)
    assert model.face_types == ["SurfaceOfRevolution" if obj.kind == "revolution" else "SurfaceOfLinearExtrusion"]
    exact = (revolve(obj.profile, list(obj.axis_point), list(obj.axis_direction), obj.angle)
             if obj.kind == "revolution" else extrude(obj.profile, list(obj.direction), obj.length))
    _same_point_set(exact, model.faces[0].surface)


def test_analytic_false_writes_the_exact_nurbs(tmp_path):
    obj = SWEPT["partial turn"]()
    cad.write_cad(obj, tmp_path / "b.step", analytic=False)
    text = (tmp_path / "b.step").read_text()
    assert "SURFACE_OF_REVOLUTION" not in text and "B_SPLINE_SURFACE_WITH_KNOTS" in text
    back = cad.read_cad(tmp_path / "b.step")
    assert back.face_types == ["BSplineSurface"]
    # the NURBS itself, exactly (STEP keeps every bit)
    exact = obj.to_nurbs()
    uv = torch.rand(50, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    diff = back.faces[0].surface.evaluate(uv) - exact.evaluate(uv)
    assert float(diff.abs().max()) <= 1e-12 * _diagonal(exact)


def test_bad_sweeps_are_refused():
    with pytest.raises(OptionError, match="angle"):
        RevolvedSurface(_profile(), [0, 0, 0], [0, 0, 1], 7.0)
    with pytest.raises(OptionError, match="must not be zero"):
        RevolvedSurface(_profile(), [0, 0, 0], [0, 0, 0])
    with pytest.raises(OptionError, match="length"):
        ExtrudedSurface(_profile(), [0, 0, 1], 0.0)
    flat = nurbskit.NURBSCurve(torch.rand(4, 2, dtype=torch.float64), degree=3)
    with pytest.raises(OptionError, match="3-D"):
        ExtrudedSurface(flat, [0, 0, 1], 1.0)


# ---- `nurbskit shape` -> `nurbskit export` ---------------------------------------------------

@pytest.fixture(scope="module")
def shape_outputs(tmp_path_factory):
    """`nurbskit shape` on a synthetic vase and an extruded wave (no refinement: fast)."""
    from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud

    clouds = {"revolution": vase_cloud(600, 0.0, 4, angle=4.0), "extrusion": extrusion_cloud(600, 0.0, 5)}
    return run_shape_cli(tmp_path_factory.mktemp("shapes"), clouds)


@pytest.mark.parametrize("kind", ["revolution", "extrusion"])
def test_shape_report_exports_as_the_analytic_surface_of_its_nurbs(tmp_path, shape_outputs, kind, capsys):
    from nurbskit.cli import main

    folder = shape_outputs[kind]
    surface = nurbskit.load(folder / "surface.json")
    swept = swept_from_report(folder / "report.json")
    assert swept.kind == kind
    # the report rebuilds the very surface `nurbskit shape` wrote
    uv = torch.rand(40, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    (u0, u1), (v0, v1) = surface.domain
    uv = torch.stack([u0 + (u1 - u0) * uv[:, 0], v0 + (v1 - v0) * uv[:, 1]], -1)
    diff = swept.to_nurbs().evaluate(uv) - surface.evaluate(uv)
    assert float(diff.abs().max()) <= 1e-12 * _diagonal(surface)

    out = tmp_path / "shape.step"
    assert main(["export", str(folder / "report.json"), str(out)]) == 0
    assert ENTITY["step"][kind] in out.read_text()
    model = cad.read_cad(out)
    _same_point_set(surface, model.faces[0].surface)
    # the folder is accepted as well; --bspline writes the NURBS
    assert main(["export", str(folder), str(tmp_path / "b.step"), "--bspline"]) == 0
    assert ENTITY["step"][kind] not in (tmp_path / "b.step").read_text()
    # formats without swept surfaces get the NURBS
    assert main(["export", str(folder / "report.json"), str(tmp_path / "s.json")]) == 0
    back = nurbskit.load(tmp_path / "s.json")
    assert back.sizes == surface.sizes


def test_free_form_and_broken_reports_fail_in_one_line(tmp_path, capsys):
    from nurbskit.cli import main

    (tmp_path / "free.json").write_text(json.dumps({"kind": "freeform", "profile": None, "axis": None}))
    assert main(["export", str(tmp_path / "free.json"), str(tmp_path / "o.step")]) == 2
    err = capsys.readouterr().err
    assert "free-form" in err and "Traceback" not in err and err.count("\n") == 1
    with pytest.raises(InputError, match="not a complete"):
        swept_from_report({"kind": "revolution", "profile": {"frame": {}}, "axis": {}})
    assert swept_from_report({"kind": "freeform"}) is None
    assert math.isclose(swept_from_report(_report_of(SWEPT["partial turn"]())).angle, 2.0)


def _report_of(obj: RevolvedSurface) -> dict:
    """A hand-made revolution report: the profile in its (r, z) plane about the axis."""
    o = np.array(obj.axis_point)
    a = np.array(obj.axis_direction) / np.linalg.norm(obj.axis_direction)
    cp = obj.profile.control_points.numpy()
    rel = cp - o
    z = rel @ a
    radial = rel - z[:, None] * a
    e1 = radial[0] / np.linalg.norm(radial[0])
    r = radial @ e1
    return {"kind": "revolution", "axis": {"point": o.tolist(), "direction": a.tolist()}, "angle": obj.angle,
            "profile": {"frame": {"origin": o.tolist(), "radial": e1.tolist(), "axial": a.tolist()},
                        "control_points": np.stack([r, z], 1).tolist(), "weights": obj.profile.weights.tolist(),
                        "knot_vector": obj.profile.knot_vector.tolist(), "degree": obj.profile.degree}}
