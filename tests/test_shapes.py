"""Shape fitting: axis and direction estimators, round trips, auto choice, bad input.

Oracles: synthetic clouds sampled from exact surfaces built by the core constructors,
with known axis / direction (:mod:`nurbskit.shapes.synthetic`).
"""

from __future__ import annotations

import math

import pytest
import torch

from _assert import assert_close

from nurbskit.errors import InputError, OptionError
from nurbskit.metrics import surface_distances
from nurbskit.shapes import (
    axis_angle_degrees, estimate_normals, extrusion_direction, fit_shape, order_points, revolution_axis,
)
from nurbskit.shapes.synthetic import extrusion_cloud, vase_cloud

F64 = torch.float64


def test_normals_of_a_sphere_are_radial():
    g = torch.Generator().manual_seed(0)
    p = torch.randn(1500, 3, generator=g, dtype=F64)
    p = p / p.norm(dim=-1, keepdim=True)
    n = estimate_normals(p, 12)
    cos = (n * p).sum(-1).abs()
    assert float(cos.mean()) > 0.999 and float(cos.min()) > 0.99


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_revolution_axis_clean(seed):
    c = vase_cloud(2000, 0.0, seed)
    ax = revolution_axis(c.points, estimate_normals(c.points, 24))
    assert axis_angle_degrees(ax.direction, c.axis_direction) < 0.5
    # the axis point lies on the true axis (distance over the diagonal)
    rel = ax.point - c.axis_point
    off = (rel - (rel @ c.axis_direction) * c.axis_direction).norm()
    assert float(off) < 5e-3


def test_revolution_axis_exact_normals_is_exact():
    c = vase_cloud(500, 0.0, 4)
    uv = torch.rand(500, 2, generator=torch.Generator().manual_seed(1), dtype=F64)
    p = c.surface.evaluate(uv)
    n = c.surface.normals(uv)
    ax = revolution_axis(p, n)
    assert axis_angle_degrees(ax.direction, c.axis_direction) < 1e-6


def test_revolution_axis_ignores_outlier_lines():
    c = vase_cloud(1000, 0.0, 5)
    uv = torch.rand(1000, 2, generator=torch.Generator().manual_seed(2), dtype=F64)
    p, n = c.surface.evaluate(uv), c.surface.normals(uv)
    g = torch.Generator().manual_seed(3)
    n[:150] = torch.randn(150, 3, generator=g, dtype=F64)  # 15 % random normal lines
    ax = revolution_axis(p, n)
    assert axis_angle_degrees(ax.direction, c.axis_direction) < 0.05


@pytest.mark.parametrize("kind", ["L", "smooth"])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_extrusion_direction_geometric(kind, noise):
    """The geometric estimate alone (no refinement), on the 64-neighbour normals the fitter uses."""
    from nurbskit.shapes.fit import DIRECTION_NEIGHBOURS

    c = extrusion_cloud(2000, noise, 0, kind)
    d, spread = extrusion_direction(estimate_normals(c.points, DIRECTION_NEIGHBOURS))
    assert axis_angle_degrees(d, c.axis_direction) < 0.5
    assert spread < (0.05 if noise == 0 else 0.25)  # noisy normals leave the section's plane


@pytest.mark.parametrize("kind", ["L", "smooth"])
def test_extrusion_direction_clean(kind):
    c = extrusion_cloud(2000, 0.0, 0, kind)
    d, spread = extrusion_direction(estimate_normals(c.points, 24))
    assert axis_angle_degrees(d, c.axis_direction) < 0.5
    assert spread < 0.05


@pytest.mark.parametrize("kind,seed", [
    ("revolution", 0), ("revolution", 1),
    # was ~1 degree off (noisy 24-neighbour normals; a 34-control-point profile zig-zagging
    # through the noise; the refinement on an 800-point subset): now 64-neighbour normals
    # for the direction, a profile whose knot spans exceed the noise band, all points
    ("extrusion", 0), ("extrusion", 1),
])
@pytest.mark.slow
def test_axis_after_refinement_with_one_percent_noise(kind, seed):
    c = vase_cloud(2000, 0.01, seed) if kind == "revolution" else extrusion_cloud(2000, 0.01, seed, "L")
    fit = fit_shape(c.points, kind)
    assert axis_angle_degrees(fit.axis["direction"], c.axis_direction) < 0.5


def test_order_points_follows_the_curve():
    t = torch.rand(600, generator=torch.Generator().manual_seed(0), dtype=F64)
    xy = torch.stack([torch.cos(3 * t), torch.sin(3 * t) + t], -1)  # a spiral-like open curve
    u = torch.as_tensor(order_points(xy.numpy()))
    # monotone (either direction) in the true parameter
    order = torch.argsort(t)
    du = torch.diff(u[order])
    frac = max(float((du >= -1e-3).float().mean()), float((du <= 1e-3).float().mean()))
    assert frac > 0.99


def test_vase_round_trip():
    c = vase_cloud(1500, 0.0, 7)
    fit = fit_shape(c.points, "revolution")
    assert fit.kind == "revolution"
    assert fit.distance_mean < 1e-3
    # against the metrics module: the same number
    m = surface_distances(fit.surface, c.points)
    assert abs(m["to_surface_mean"] - fit.distance_mean) < 1e-6
    # the true surface is covered too: its samples are near the fit
    truth = c.surface.sample((30, 30)).reshape(-1, 3)
    assert surface_distances(fit.surface, truth)["to_surface_mean"] < 1e-3
    assert fit.surface.weights.min() > 0 and fit.angle == pytest.approx(2 * math.pi)
    assert fit.surface.degrees[0] == 2 and fit.surface.sizes[0] == 9


def test_extruded_l_round_trip():
    c = extrusion_cloud(1500, 0.0, 3, "L")
    fit = fit_shape(c.points, "extrusion")
    assert fit.kind == "extrusion" and fit.surface.degrees[0] == 1
    assert fit.distance_mean < 1e-3
    truth = c.surface.sample((10, 40)).reshape(-1, 3)
    assert surface_distances(fit.surface, truth)["to_surface_mean"] < 1e-3


def test_partial_revolution_angle():
    c = vase_cloud(1500, 0.0, 2, angle=math.pi)
    fit = fit_shape(c.points, "revolution", iterations=10)
    assert abs(fit.angle - math.pi) < math.radians(5)
    assert fit.distance_mean < 1e-3


@pytest.mark.slow
def test_auto_chooses_by_residual():
    fit = fit_shape(vase_cloud(1200, 0.0, 8).points, "auto", iterations=10)
    assert fit.kind == "revolution", fit.reason
    assert "revolution" in fit.reason and fit.candidates["extrusion"] > fit.candidates["revolution"]
    fit = fit_shape(extrusion_cloud(1200, 0.0, 8, "smooth").points, "auto", iterations=10)
    assert fit.kind == "extrusion", fit.reason


def test_plane_is_refused():
    g = torch.Generator().manual_seed(0)
    xy = torch.rand(500, 2, generator=g, dtype=F64)
    plane = torch.cat([xy, torch.zeros(500, 1, dtype=F64)], 1) @ torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=F64))[0]
    for kind in ("revolution", "extrusion"):
        with pytest.raises(InputError, match="single plane"):
            fit_shape(plane, kind)
    with pytest.raises(InputError, match="plane"):
        fit_shape(plane, "auto", freeform=False)


def test_bad_kind_and_too_few_points():
    with pytest.raises(OptionError, match="kind"):
        fit_shape(torch.rand(100, 3), "cone")
    with pytest.raises(InputError, match="at least 30"):
        fit_shape(torch.rand(10, 3), "revolution")


def test_docstring_examples():
    import doctest

    from nurbskit.shapes import axis, fit, image, init, normals

    for module in (axis, normals, fit, init, image):
        assert doctest.testmod(module, raise_on_error=False).failed == 0, module.__name__


def test_real_cylinder_mesh(shared_data):
    """classic_meshes/cylinder.obj (a capped cylinder along y, radius 1): auto finds the revolution."""
    from nurbskit.geometry.sampling import sample_mesh
    from nurbskit.io import read_mesh

    mesh = read_mesh(shared_data / "classic_meshes" / "cylinder.obj")
    pts = torch.as_tensor(sample_mesh(mesh.vertices, mesh.faces, 2000, "uniform", seed=0), dtype=F64)
    fit = fit_shape(pts, "auto", iterations=10, freeform=False)
    assert fit.kind == "revolution", fit.reason
    assert axis_angle_degrees(fit.axis["direction"], [0.0, 1.0, 0.0]) < 0.5
    assert fit.distance_mean < 2e-3  # the caps' sharp rims are rounded by the cubic profile


def _assert_smooth_seam(fit, rtol: float = 1e-9):
    """The fitted closed profile is periodic: its last ``p`` control points and weights are its
    first ``p``, its knots unclamped, and the surface's points and first derivatives (along
    the profile and along the sweep) agree on both sides of the seam (v at the domain's two
    ends), to rounding: no corner where the ordering started."""
    prof, p = fit.profile, fit.profile.degree
    P, w, k = prof.control_points, prof.weights, prof.knot_vector
    assert torch.equal(P[:p], P[-p:]) and torch.equal(w[:p], w[-p:])
    assert not torch.equal(k[: p + 1], k[:1].expand(p + 1)), "clamped knots: the seam would be C0"
    (u0, u1), (v0, v1) = fit.surface.domain
    u = torch.linspace(u0, u1, 7, dtype=F64)
    below = fit.surface.derivatives(torch.stack([u, torch.full_like(u, v1)], -1), 1)
    above = fit.surface.derivatives(torch.stack([u, torch.full_like(u, v0)], -1), 1)
    scale = float(below[:, 0, 1].norm(dim=-1).max())
    for i, j in ((0, 0), (0, 1), (1, 0)):  # the point, d/dv (the profile's tangent), d/du
        assert_close(below[:, i, j], above[:, i, j], atol=rtol * scale, rtol=0)


@pytest.mark.parametrize("shape", ["torus", "ellipse", "square"])
def test_closed_profiles_round_trip(shape):
    """A torus (a revolved circle) and closed extruded sections: the profile is detected
    as closed, fitted as a periodic curve (smooth across its seam), and the surface
    matches the truth."""
    from nurbskit.shapes.synthetic import torus_cloud, tube_cloud

    if shape == "torus":
        c, kind = torus_cloud(800, 0.0, 1), "revolution"
    else:
        c, kind = tube_cloud(800, 0.0, 2, section=shape), "extrusion"
    fit = fit_shape(c.points, kind, iterations=10)
    assert fit.closed
    _assert_smooth_seam(fit)
    assert axis_angle_degrees(fit.axis["direction"], c.axis_direction) < 0.1
    truth = c.surface.sample((30, 30)).reshape(-1, 3)
    # the square's corners are rounded by the cubic: a looser bound
    bound = 1e-3 if shape != "square" else 3e-3
    assert fit.distance_mean < bound and surface_distances(fit.surface, truth)["to_surface_mean"] < bound


def test_open_profiles_are_not_closed():
    from nurbskit.shapes.profile import is_closed, order_points

    t = torch.linspace(0, 1.8 * math.pi, 400, dtype=F64)  # a C: 90 % of a circle
    xy = torch.stack([t.cos(), t.sin()], -1).numpy()
    assert not is_closed(xy, order_points(xy))
    t = torch.linspace(0, 2 * math.pi, 400, dtype=F64)[:-1]
    xy = torch.stack([t.cos(), 0.5 * t.sin()], -1).numpy()
    assert is_closed(xy, order_points(xy))


def _rounded_rectangle(count: int, width: float = 2.0, height: float = 1.0, radius: float = 0.3,
                       offset: float = 0.0):
    """``count`` points ``(count, 2)`` evenly spaced by arc length on a rounded rectangle
    centred at the origin (straight sides and quarter circles), starting ``offset`` of a
    spacing along."""
    a, b = width / 2 - radius, height / 2 - radius
    pieces = [("line", (a, -b - radius), (-1, 0), 2 * a), ("arc", (-a, -b), -math.pi / 2, -1),
              ("line", (-a - radius, -b), (0, 1), 2 * b), ("arc", (-a, b), math.pi, -1),
              ("line", (-a, b + radius), (1, 0), 2 * a), ("arc", (a, b), math.pi / 2, -1),
              ("line", (a + radius, b), (0, -1), 2 * b), ("arc", (a, -b), 0.0, -1)]
    lengths = [p[3] if p[0] == "line" else math.pi / 2 * radius for p in pieces]
    total = sum(lengths)
    out = []
    for i in range(count):
        s = (i + offset) * total / count
        for piece, length in zip(pieces, lengths):
            if s <= length:
                break
            s -= length
        if piece[0] == "line":
            (x, y), (dx, dy) = piece[1], piece[2]
            out.append((x + s * dx, y + s * dy))
        else:
            (cx, cy), start = piece[1], piece[2]
            t = start - s / radius  # clockwise, as the lines run
            out.append((cx + radius * math.cos(t), cy + radius * math.sin(t)))
    return torch.tensor(out, dtype=F64)


def _extrude_rings(ring, heights):
    """Rings ``(K, 2)`` stacked at ``heights``, in the plane orthogonal to z: ``(len(heights) K, 3)``."""
    return torch.cat([torch.cat([ring, torch.full((ring.shape[0], 1), float(h), dtype=F64)], 1) for h in heights])


def test_sparse_evenly_spaced_rings_close():
    """The closing test follows the sampling: a ring of a few evenly spaced points (gap
    between the ordering's ends = one spacing) closes; the same points on an arc do not."""
    from nurbskit.shapes.profile import is_closed

    for count in (8, 12, 24):
        t = torch.arange(count, dtype=F64) * 2 * math.pi / count
        assert is_closed(torch.stack([t.cos(), t.sin()], -1).numpy())
        assert is_closed(_rounded_rectangle(count).numpy())
        arc = torch.linspace(0, math.pi, count, dtype=F64)  # a half circle: its ends a diameter apart
        assert not is_closed(torch.stack([arc.cos(), arc.sin()], -1).numpy())


@pytest.mark.parametrize("section", ["circle", "rounded_rectangle"])
def test_sparse_closed_extrusion_round_trip(section):
    """An extruded circle (12 points per ring) and rounded rectangle (20 per ring), 6 rings
    (the gap between the ordering's ends is one spacing, 0.52 and 0.27 of the extent):
    the profile closes (periodic, smooth across the seam) and the surface follows the true
    section between the samples (dense points of the truth to the fit)."""
    heights = torch.linspace(0, 1.5, 6, dtype=F64)
    if section == "circle":
        t = torch.arange(12, dtype=F64) * 2 * math.pi / 12
        ring = torch.stack([t.cos(), t.sin()], -1)
        s = torch.linspace(0, 2 * math.pi, 400, dtype=F64)
        dense = torch.stack([s.cos(), s.sin()], -1)
    else:
        ring, dense = _rounded_rectangle(20), _rounded_rectangle(400, offset=0.5)
    fit = fit_shape(_extrude_rings(ring, heights), "extrusion", iterations=10)
    assert fit.closed, "the profile was left open"
    _assert_smooth_seam(fit)
    assert axis_angle_degrees(fit.axis["direction"], [0.0, 0.0, 1.0]) < 0.2
    # few points per ring: the periodic cubic has at most half as many free control points
    # as the ring has points, and is an approximation between them
    assert fit.distance_mean < 5e-3
    truth = _extrude_rings(dense, [0.3, 1.1])
    d = surface_distances(fit.surface, truth)
    # the periodic seam: the C0 clamped fit of the last session was up to 1.2e-2 off (a corner)
    assert d["to_surface_mean"] < 5e-3 and d["to_surface_max"] < 7.5e-3, d


def test_real_cylinder_vertices_close(shared_data):
    """cylinder.obj's raw vertices (11 rings of 20, radius 1 along y): as an extrusion the
    circle closes; auto calls the near-exact tie a revolution."""
    from nurbskit.io import read_mesh

    v = torch.as_tensor(read_mesh(shared_data / "classic_meshes" / "cylinder.obj").vertices, dtype=F64)
    fit = fit_shape(v, "extrusion", iterations=10)
    assert fit.closed, "the circle was left open"
    assert axis_angle_degrees(fit.axis["direction"], [0.0, 1.0, 0.0]) < 0.2
    s = torch.linspace(0, 2 * math.pi, 300, dtype=F64)
    truth = torch.stack([s.cos(), torch.zeros_like(s), s.sin()], -1)
    assert surface_distances(fit.surface, truth)["to_surface_max"] < 5e-3
    auto = fit_shape(v, "auto", iterations=5, freeform=False)
    assert auto.kind == "revolution", auto.reason


def test_fit_shape_reports_its_stages():
    calls = []
    fit = fit_shape(vase_cloud(400, seed=2).points, "auto", iterations=3, progress=lambda *a: calls.append(a))
    stages = list(dict.fromkeys(stage for stage, _, _ in calls))
    assert stages[:2] == ["revolution", "extrusion"] and fit.kind == "revolution"
    assert ("revolution", 1, 1) in calls and ("extrusion", 1, 1) in calls
