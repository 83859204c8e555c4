"""Closed profiles are fitted as periodic curves: smooth across the seam, and the surface
still round-trips through JSON and STEP.

Oracles: closed forms (circle, ellipse, rounded square sampled by arc length), the core's
own derivatives on both sides of the seam (a clamped curve whose ends are merely tied
has a corner there: its one-sided tangents differ), OpenCASCADE's reader (through
``nurbskit.io.cad``) and the core's projection for point-set comparisons.
"""

from __future__ import annotations

import math

import pytest
import torch

from _assert import assert_close
from _cli import run_shape_cli
from _extras import require_extra
from test_shapes import _assert_smooth_seam, _extrude_rings, _rounded_rectangle

import nurbskit
from nurbskit.core.project import periodic_directions, project_points
from nurbskit.fit.params import periodic_knots
from nurbskit.metrics import surface_distances
from nurbskit.shapes import fit_shape
from nurbskit.shapes.profile import closing_matrix, fit_curve_lsq, fit_profile
from nurbskit.shapes.synthetic import torus_cloud, tube_cloud

F64 = torch.float64


def _section(shape: str, count: int, offset: float = 0.0) -> torch.Tensor:
    """``count`` points ``(count, 2)`` evenly spaced in angle (circle, ellipse 1 : 0.6) or arc
    length (a 2 x 2 square with corners rounded to radius 0.4), ``offset`` of a spacing along."""
    if shape == "rounded_square":
        return _rounded_rectangle(count, 2.0, 2.0, 0.4, offset)
    t = (torch.arange(count, dtype=F64) + offset) * 2 * math.pi / count
    return torch.stack([t.cos(), (0.6 if shape == "ellipse" else 1.0) * t.sin()], -1)


def test_closing_matrix_ties_the_last_p_points_to_the_first():
    E = closing_matrix(7, True, 3)
    free = torch.arange(8, dtype=F64).reshape(4, 2)
    P = E @ free
    assert torch.equal(P[:3], P[-3:]) and torch.equal(P[:4], free)
    assert torch.equal(closing_matrix(5, False), torch.eye(5, dtype=F64))
    assert torch.equal((closing_matrix(5, True) @ torch.arange(4, dtype=F64))[[0, -1]], torch.tensor([0.0, 0.0], dtype=F64))


@pytest.mark.parametrize("shape", ["circle", "ellipse", "rounded_square"])
def test_closed_lsq_curve_is_periodic_and_c2_at_the_seam(shape):
    """fit_curve_lsq(closed=True): the core's periodic knots, the last 3 control points the
    first 3, and value, first and second derivatives equal at u = 0 and u = 1 (to rounding);
    within 1e-4 of the true section (the rounded square 1.5e-2: its curvature jumps from 0
    to 2.5 where arcs meet lines, which 16 cubic spans cannot follow)."""
    xy = _section(shape, 200)
    u = torch.arange(200, dtype=F64) / 200  # the samples go once round, the seam between the last and the first
    curve = fit_curve_lsq(xy, u, 16 + 3, 3, closed=True)
    P = curve.control_points
    assert_close(curve.knot_vector, periodic_knots(19, 3, dtype=F64), atol=1e-15, rtol=0)
    assert torch.equal(P[:3], P[-3:])
    d = curve.derivatives(torch.tensor([0.0, 1.0], dtype=F64), 2)  # (2, 3, 2): value, d1, d2
    scale = float(d[:, 1].norm(dim=-1).max())
    for order in range(3):
        assert_close(d[0, order], d[1, order], atol=1e-10 * scale * (1 + order * 10), rtol=0)
    dense = _section(shape, 1000, 0.5)
    err = project_points(curve, dense, periodic=(True,)).distance
    assert float(err.max()) < (1e-4 if shape != "rounded_square" else 1.5e-2)


@pytest.mark.parametrize("shape", ["circle", "ellipse", "rounded_square"])
def test_extruded_closed_sections_are_smooth_at_the_seam(shape):
    """A circle, an ellipse and a rounded square, sampled (80 points a ring, 12 rings, noise
    0.5 % of the diagonal) and extruded along z: the fit's profile is closed and periodic,
    the surface's tangents agree on both sides of the seam, the fit sits at the noise
    (mean distance <= 0.5 % of the diagonal) and the true section is within 0.15 % of the
    diagonal on average (0.4 % at worst) of the fitted surface."""
    g = torch.Generator().manual_seed(7)
    ring = _section(shape, 80)
    pts = _extrude_rings(ring, torch.linspace(0, 2.0, 12, dtype=F64))
    diag = float((pts.amax(0) - pts.amin(0)).norm())
    noisy = pts + 0.005 * diag * torch.randn(pts.shape, generator=g, dtype=F64)
    fit = fit_shape(noisy, "extrusion", iterations=10)
    assert fit.closed
    _assert_smooth_seam(fit)
    assert fit.distance_mean < 5e-3
    d = surface_distances(fit.surface, _extrude_rings(_section(shape, 400, 0.5), [0.4, 1.6]))
    assert d["to_surface_mean"] < 1.5e-3 * diag and d["to_surface_max"] < 4e-3 * diag, d


def test_closed_profile_seam_is_not_where_the_ordering_starts():
    """The periodic curve does not care where the points begin: the same ring started at
    another point gives the same curve (to the fit's accuracy), which a curve clamped at its
    first point could not."""
    a = fit_profile(_section("ellipse", 300).numpy()).curve
    b = fit_profile(torch.roll(_section("ellipse", 300), 137, 0).numpy()).curve
    dense = a.evaluate(torch.linspace(0, 1, 500, dtype=F64))
    assert float(project_points(b, dense, periodic=(True,)).distance.max()) < 1e-4


@pytest.fixture(scope="module")
def closed_shapes(tmp_path_factory):
    """`nurbskit shape` on a torus (revolution) and an elliptic tube (extrusion), no refinement."""
    root = tmp_path_factory.mktemp("closed")
    clouds = {"revolution": torus_cloud(800, 0.0, 1), "extrusion": tube_cloud(800, 0.0, 2, section="ellipse")}
    return run_shape_cli(root, clouds)


def _uv(surface, n: int = 60, seed: int = 4) -> torch.Tensor:
    t = torch.rand(n, 2, dtype=F64, generator=torch.Generator().manual_seed(seed))
    (u0, u1), (v0, v1) = surface.domain
    return torch.stack([u0 + (u1 - u0) * t[:, 0], v0 + (v1 - v0) * t[:, 1]], -1)


def _diagonal(surface) -> float:
    cp = surface.control_points.reshape(-1, 3)
    return float((cp.amax(0) - cp.amin(0)).norm())


@pytest.mark.parametrize("kind", ["revolution", "extrusion"])
def test_periodic_profile_surface_round_trips_through_json(closed_shapes, kind):
    """surface.json holds the periodic surface (the projection sees v as periodic), and the
    report's profile rebuilds it exactly."""
    from nurbskit.io.cad.analytic import swept_from_report

    folder = closed_shapes[kind]
    surface = nurbskit.load(folder / "surface.json")
    assert periodic_directions(surface)[1]
    p = surface.degrees[1]
    assert torch.equal(surface.control_points[:, :p], surface.control_points[:, -p:])
    uv = _uv(surface)
    rebuilt = swept_from_report(folder / "report.json").to_nurbs()
    assert float((rebuilt.evaluate(uv) - surface.evaluate(uv)).abs().max()) <= 1e-12 * _diagonal(surface)


@pytest.mark.parametrize("kind", ["revolution", "extrusion"])
def test_periodic_profile_surface_round_trips_through_step(tmp_path, closed_shapes, kind):
    """`nurbskit export` of the shape's report: the analytic swept surface (STEP
    SURFACE_OF_REVOLUTION / _LINEAR_EXTRUSION over the periodic profile) lies on the fitted
    surface and back (1e-9 of the diagonal); with --bspline the NURBS is written periodic in v
    and reads back to the same points at the same parameters."""
    require_extra("OCP", "cad")
    from nurbskit.cli import main
    from nurbskit.io import cad

    folder = closed_shapes[kind]
    surface = nurbskit.load(folder / "surface.json")
    diag = _diagonal(surface)
    assert main(["export", str(folder / "report.json"), str(tmp_path / "a.step")]) == 0
    back = cad.read_cad(tmp_path / "a.step").faces[0].surface
    for a, b in ((surface, back), (back, surface)):
        pts = a.evaluate(_uv(a, 150))
        proj = project_points(b, pts, starts=3)
        assert float((b.evaluate(proj.params) - pts).norm(dim=-1).max()) <= 1e-9 * diag
    assert main(["export", str(folder), str(tmp_path / "b.step"), "--bspline"]) == 0
    assert cad.is_periodic(surface, 1)
    back = cad.read_cad(tmp_path / "b.step").faces[0].surface
    uv = _uv(surface)
    assert float((back.evaluate(uv) - surface.evaluate(uv)).abs().max()) <= 1e-12 * diag
