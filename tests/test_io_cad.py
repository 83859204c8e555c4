"""CAD exchange through OpenCASCADE: B-spline conversion exact both ways, STEP and BREP
round trips exact, IGES to its text precision, trimmed faces keep their holes, patch sets
sew into valid shells, meshes become solids, real STEP files read onto their STL.

Oracles: OpenCASCADE's own evaluator (``Geom_BSplineSurface::Value``) and checker
(``BRepCheck_Analyzer``), its area and volume integrals (``BRepGProp``), the ABC model's
own STL, shoelace areas in closed form.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from _assert import assert_close
from _cad import diagonal, grid, random_curve, random_surface, require_extra
from _property import examples
from conftest import shared_file

import nurbskit
from nurbskit.core.trim import TrimLoop, TrimmedSurface
from nurbskit.errors import NurbskitError, OptionError

OCP = require_extra("OCP")

from nurbskit.io import cad  # noqa: E402
from nurbskit.io.cad import occ, shapes  # noqa: E402

KINDS = ("clamped", "unclamped", "periodic")


def _occ_points(geom, params: np.ndarray) -> np.ndarray:
    if params.ndim == 1:
        pts = [geom.Value(float(t)) for t in params]
    else:
        pts = [geom.Value(float(u), float(v)) for u, v in params]
    return np.array([[p.X(), p.Y(), p.Z()] for p in pts])


def _same_spline(a, b, atol=0.0):
    assert a.kind == b.kind and a.degrees == b.degrees and a.sizes == b.sizes
    for x, y in zip(a.knot_vectors, b.knot_vectors):
        assert_close(x, y, atol=atol)
    assert_close(a.control_points, b.control_points, atol=max(atol, 1e-14) * max(1.0, diagonal(a)))
    assert_close(a.weights, b.weights, atol=max(atol, 1e-14))


# ---- geometry conversion: exact both ways ------------------------------------------------

@settings(max_examples=examples(30))
@given(p=st.integers(1, 5), q=st.integers(1, 5), ku=st.sampled_from(KINDS), kv=st.sampled_from(KINDS),
       rational=st.booleans(), seed=st.integers(0, 2 ** 31))
def test_surface_to_occ_and_back_is_exact(p, q, ku, kv, rational, seed):
    rng = np.random.default_rng(seed)
    s = random_surface(rng, (p, q), (ku, kv), rational)
    geom = occ.surface_to_occ(s)
    assert geom.UDegree() == p and geom.VDegree() == q
    assert geom.IsUPeriodic() == (ku == "periodic") and geom.IsVPeriodic() == (kv == "periodic")
    assert (geom.IsURational() or geom.IsVRational()) == s.is_rational
    uv = grid(s, 7)
    # OCC's evaluator agrees with ours at the same (u, v): the parameter domain is kept
    assert_close(_occ_points(geom, uv.numpy()), s.evaluate(uv), atol=1e-12 * max(1.0, diagonal(s)))
    _same_spline(occ.surface_from_occ(geom), s)


@settings(max_examples=examples(30))
@given(p=st.integers(1, 5), kind=st.sampled_from(KINDS), rational=st.booleans(), seed=st.integers(0, 2 ** 31))
def test_curve_to_occ_and_back_is_exact(p, kind, rational, seed):
    rng = np.random.default_rng(seed)
    c = random_curve(rng, p, kind, rational)
    geom = occ.curve_to_occ(c)
    assert geom.Degree() == p and geom.IsPeriodic() == (kind == "periodic")
    t = grid(c, 15)
    assert_close(_occ_points(geom, t.numpy()), c.evaluate(t), atol=1e-12 * max(1.0, diagonal(c)))
    _same_spline(occ.curve_from_occ(geom), c)


def test_periodic_detection_and_forcing():
    rng = np.random.default_rng(5)
    s = random_surface(rng, (3, 2), ("periodic", "clamped"))
    assert occ.is_periodic(s, 0) and not occ.is_periodic(s, 1)
    assert not occ.surface_to_occ(s, periodic=False).IsUPeriodic()
    with pytest.raises(OptionError, match="not periodic"):
        occ.surface_to_occ(random_surface(rng, (2, 2)), periodic=True)
    # one control point off: no longer periodic, written as the plain unclamped spline
    cp = s.control_points.clone()
    cp[-1, 0, 0] += 1e-3
    moved = nurbskit.NURBSSurface(cp, s.degrees, s.knot_vectors, s.weights)
    assert not occ.is_periodic(moved, 0)
    _same_spline(occ.surface_from_occ(occ.surface_to_occ(moved)), moved)


# ---- files: STEP and BREP exact, IGES to its precision ------------------------------------

def _random_set(seed: int, scale: float = 1.0):
    rng = np.random.default_rng(seed)
    surfaces, curves = [], []
    for i, (p, q) in enumerate([(1, 1), (2, 3), (3, 3), (4, 2), (5, 5), (5, 1), (3, 4), (2, 2), (1, 5)]):
        kinds = (KINDS[i % 3], KINDS[(i // 3) % 3])
        surfaces.append(random_surface(rng, (p, q), kinds, rational=i % 4 != 0, scale=scale))
    for i, p in enumerate([1, 2, 3, 4, 5, 3]):
        curves.append(random_curve(rng, p, KINDS[i % 3], rational=i % 2 == 0, scale=scale))
    return surfaces, curves


@pytest.mark.parametrize("ext", [".step", ".brep"])
def test_step_and_brep_round_trip_exactly(tmp_path, ext):
    surfaces, curves = _random_set(11)
    path = tmp_path / f"set{ext}"
    report = cad.write_cad(surfaces + curves, path, sew_tolerance=None)
    assert report["valid"] and report["faces"] == len(surfaces) == report["faces_written"]
    model = cad.read_cad(path)
    assert len(model.faces) == len(surfaces) and len(model.curves) == len(curves)
    for back, s in zip(model.faces, surfaces):
        assert back.loops == []  # the natural boundary is no trim
        assert back.surface.domain == s.domain
        _same_spline(back.surface, s)  # bit for bit: 17 significant digits in STEP
        uv = grid(s, 11)
        assert_close(back.surface.evaluate(uv), s.evaluate(uv), atol=1e-12)
    for back, c in zip(model.curves, curves):
        t = grid(c, 21)
        assert back.domain == c.domain
        assert_close(back.evaluate(t), c.evaluate(t), atol=1e-12)


def test_a_closed_fit_with_two_poles_exports_to_step(tmp_path):
    # tests/data/pole_seam_fit.json: make demo's default fit of the thesis duck (periodic in
    # v, both u ends collapsed to poles, rational). STEP holds no degenerate edge, so its
    # face is written as a loop of the seam edges alone; the check's reader must add the
    # edges at the poles, as any reader does (it refused the file as invalid before).
    s = nurbskit.load(Path(__file__).parent / "data" / "pole_seam_fit.json")
    for ext in (".step", ".iges", ".brep"):
        report = cad.write_cad(s, tmp_path / f"fit{ext}")
        assert report["valid"] and report["faces"] == 1
        back = cad.read_cad(tmp_path / f"fit{ext}").faces[0].surface
        uv = grid(s, 11)
        assert_close(back.evaluate(uv), s.evaluate(uv), atol=1e-12 * diagonal(s))
        # closed along v: one seam edge, used twice by the face, and the two poles; not a
        # band slit open along v (two coincident boundary edges, 4 edges in all)
        assert _seam_and_degenerate_edges(cad.read_shape(tmp_path / f"fit{ext}")) == (1, 2), ext


def _seam_and_degenerate_edges(shape) -> tuple[int, int]:
    from OCP.BRep import BRep_Tool

    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as ShapeMap
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp
    from OCP.TopoDS import TopoDS

    face = next(shapes._faces(shape))
    found = ShapeMap()  # each edge once, however often the face's wire uses it
    TopExp.MapShapes_s(face, TopAbs_EDGE, found)
    edges = [TopoDS.Edge(found.FindKey(i)) for i in range(1, found.Extent() + 1)]
    return sum(BRep_Tool.IsClosed_s(e, face) for e in edges), sum(BRep_Tool.Degenerated_s(e) for e in edges)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_the_fits_periodic_knots_are_written_periodic(dtype):
    # the core's periodic knots (every closed fit's) wrap as OCC wraps them: bit for bit in
    # float64, to float32's rounding in float32; (i - p) / s alone missed by an ulp, and a
    # closed fit was written as an open band with two coincident edges
    from nurbskit.fit.params import periodic_knots

    k = periodic_knots(15, 3, dtype=dtype)
    t = k.double().numpy()
    exact = np.array_equal(t[:3], t[12:15] - 1.0) and np.array_equal(t[16:], t[4:7] + 1.0)  # as OCC, in float64
    assert exact == (dtype == torch.float64)
    assert (k[3], k[15]) == (0.0, 1.0) and torch.all(torch.diff(k) > 0)
    cp = torch.as_tensor(np.random.default_rng(3).normal(size=(5, 12, 3)), dtype=dtype)
    s = nurbskit.NURBSSurface(torch.cat([cp, cp[:, :3]], 1), (2, 3), [None, k])
    assert occ.is_periodic(s, 1) and occ.surface_to_occ(s).IsVPeriodic()
    back = occ.surface_from_occ(occ.surface_to_occ(s))
    # OCC's wrapped knots replace a float32 spline's: a change within float32's rounding
    tol = 1e-12 if dtype == torch.float64 else 8 * torch.finfo(dtype).eps
    s = s.to(torch.float64)
    uv = grid(s, 11)
    assert_close(back.evaluate(uv), s.evaluate(uv), atol=tol * diagonal(s))


def test_step_keeps_large_coordinates_to_the_last_bit(tmp_path):
    # OCC's default STEP output keeps 12 decimals (an error of 1e-10 at this scale); ours all 17 digits
    surfaces, _ = _random_set(12, scale=250.0)
    cad.write_cad(surfaces[:3], tmp_path / "big.step", sew_tolerance=None)
    for back, s in zip(cad.read_cad(tmp_path / "big.step").faces, surfaces):
        _same_spline(back.surface, s)


def test_iges_round_trip_exactly_and_occ_default_precision(tmp_path):
    surfaces, curves = _random_set(13, scale=10.0)
    curves = [c for c in curves if c.degrees[0] > 1]  # IGES readers split polylines into lines
    cad.write_cad(surfaces + curves, tmp_path / "set.iges", sew_tolerance=None)
    model = cad.read_cad(tmp_path / "set.iges")
    assert len(model.faces) == len(surfaces) and len(model.curves) == len(curves)
    for back, s in zip(model.faces, surfaces):
        assert back.surface.degrees == s.degrees
        uv = grid(s, 11)
        assert_close(back.surface.evaluate(uv), s.evaluate(uv), atol=1e-12 * diagonal(s))
    for back, c in zip(model.curves, curves):
        t = grid(c, 21)
        assert_close(back.evaluate(t), c.evaluate(t), atol=1e-12 * diagonal(c))
    # OCC's own IGES output (9 significant digits) as the comparison: measured 1e-8 of the diagonal
    from OCP.IGESControl import IGESControl_Writer

    writer = IGESControl_Writer("MM", 0)
    writer.AddShape(shapes.to_shape(surfaces, sew_tolerance=None, solids=False))  # the faces, as write_cad's IGES
    writer.ComputeModel()
    assert writer.Write(str(tmp_path / "occ.iges"))
    worst = 0.0
    # (its 9 digits move the domain ends too: evaluate past them by up to 1e-9)
    for back, s in zip(cad.read_cad(tmp_path / "occ.iges").faces, surfaces):
        uv = grid(s, 11)
        worst = max(worst, (back.surface.evaluate(uv, extrapolate=True) - s.evaluate(uv)).norm(dim=-1).max().item() / diagonal(s))
    assert 1e-12 < worst <= 1e-7


# ---- trimmed faces -----------------------------------------------------------------------

def _disk_with_hole(n: int = 96):
    """A planar patch [-1, 1]^2 (bilinear, domain [0, 1]^2) trimmed to an annulus in (u, v)."""
    xy = np.stack(np.meshgrid([-1.0, 1.0], [-1.0, 1.0], indexing="ij"), axis=-1)
    cp = torch.tensor(np.concatenate([xy, np.zeros((2, 2, 1))], axis=-1))
    plane = nurbskit.NURBSSurface(cp, (1, 1))
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    outer = TrimLoop.from_uv(np.stack([0.5 + 0.45 * np.cos(th), 0.5 + 0.45 * np.sin(th)], axis=1))
    hole = TrimLoop(np.stack([0.55 + 0.2 * np.cos(th), 0.5 + 0.2 * np.sin(th)], axis=1), "hole")
    return TrimmedSurface(plane, [outer, hole])


def _face_area(shape) -> float:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(shape, props)
    return props.Mass()


@pytest.mark.parametrize("ext", [".step", ".iges", ".brep"])
def test_disk_with_a_hole_round_trips_with_its_hole(tmp_path, ext):
    disk = _disk_with_hole()
    expected = 4.0 * (disk.outer.area - disk.holes[0].area)  # (u, v) area times the plane's Jacobian (2 x 2)
    path = tmp_path / f"disk{ext}"
    report = cad.write_cad(disk, path)
    assert report["valid"] and report["faces"] == 1
    shape = cad.read_shape(path)
    assert abs(_face_area(shape) - expected) <= 0.005 * expected
    back = cad.read_cad(path).faces[0]
    assert [lp.kind for lp in back.loops] == ["outer", "hole"]
    assert abs(back.outer.area - disk.outer.area) <= 0.005 * disk.outer.area
    assert abs(back.holes[0].area - disk.holes[0].area) <= 0.005 * disk.holes[0].area
    # the hole is where it was: its centre in (u, v)
    assert_close(back.holes[0].uv.mean(axis=0), disk.holes[0].uv.mean(axis=0), atol=1e-6)


def test_trimming_curves_are_exact_on_the_surface():
    rng = np.random.default_rng(21)
    s = random_surface(rng, (3, 2), rational=True)
    (u0, u1), (v0, v1) = s.domain
    th = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    uv = np.stack([(u0 + u1) / 2 + 0.4 * (u1 - u0) * np.cos(th), (v0 + v1) / 2 + 0.4 * (v1 - v0) * np.sin(th)], 1)
    closed = np.vstack([uv, uv[:1]])
    params = shapes._chord_parameters(closed)
    poles, weights, flat, degree = shapes.loop_curve_3d(s, closed, params)
    curve = nurbskit.NURBSCurve(torch.tensor(poles), degree, torch.tensor(flat), torch.tensor(weights))
    # at arbitrary parameters the 3-D curve is the surface at the polyline's (u, v)
    t = np.sort(rng.uniform(params[0], params[-1], 200))
    seg = np.clip(np.searchsorted(params, t, side="right") - 1, 0, len(params) - 2)
    frac = (t - params[seg]) / (params[seg + 1] - params[seg])
    at = closed[seg] + frac[:, None] * (closed[seg + 1] - closed[seg])
    assert_close(curve.evaluate(torch.tensor(t)), s.evaluate(torch.tensor(at)), atol=1e-11 * diagonal(s))


def _dense_deviation(surface, closed: np.ndarray, params: np.ndarray, curve_3d, count: int = 4001) -> float:
    """Largest |C(t) - S(uv(t))| at ``count`` parameters (the polyline's points included),
    C evaluated by OpenCASCADE, S by nurbskit."""
    poles, weights, flat, degree = curve_3d
    geom = shapes._bspline_curve_3d(poles, weights, flat, degree)
    t = np.unique(np.concatenate([np.linspace(params[0], params[-1], count), params]))
    seg = np.clip(np.searchsorted(params, t, side="right") - 1, 0, len(params) - 2)
    frac = (t - params[seg]) / (params[seg + 1] - params[seg])
    at = closed[seg] + frac[:, None] * (closed[seg + 1] - closed[seg])
    return float(np.abs(_occ_points(geom, t) - surface.evaluate(torch.tensor(at)).numpy()).max())


@pytest.mark.parametrize("degrees,rational,scale", [((3, 3), True, 1.0), ((3, 3), True, 30.0), ((2, 3), True, 30.0),
                                                    ((1, 1), True, 10.0), ((3, 3), False, 30.0),
                                                    ((1, 2), False, 10.0), ((5, 4), True, 30.0)])
def test_approximated_trimming_curves_stay_within_their_tolerance(degrees, rational, scale):
    """The 3-D curves written for trimming loops (polynomial, degree APPROX_DEGREE) lie
    within the edge's tolerance of the exact image of the pcurve, measured densely (4001
    parameters, far more than the 4 + 5 points per piece the approximation looked at)."""
    rng = np.random.default_rng(sum(degrees) + 10 * rational)
    s = random_surface(rng, degrees, rational=rational, scale=scale)
    (u0, u1), (v0, v1) = s.domain
    th = np.linspace(0, 2 * np.pi, 37, endpoint=False)
    r = 0.4 + 0.05 * np.sin(3 * th)
    uv = np.stack([(u0 + u1) / 2 + r * (u1 - u0) * np.cos(th), (v0 + v1) / 2 + r * (v1 - v0) * np.sin(th)], 1)
    closed = np.vstack([uv, uv[:1]])
    params = shapes._chord_parameters(closed)
    tolerance = shapes.CURVE_TOLERANCE * diagonal(s)
    curve = shapes.approximate_loop_curves_3d(s, [(closed, params)], tolerance)[0]
    exact = shapes.loop_curve_3d(s, closed, params)
    if curve[3] == shapes.APPROX_DEGREE and (rational or sum(degrees) > shapes.APPROX_DEGREE):
        assert curve[1] is None  # polynomial
        assert _dense_deviation(s, closed, params, curve) <= tolerance
        assert len(curve[0]) <= len(exact[0])  # else the exact curve is written
    else:  # the exact curve: fewer poles, or already polynomial of low degree
        assert curve[3] == sum(degrees)
        assert_close(curve[0], exact[0], atol=0)
        assert _dense_deviation(s, closed, params, curve) <= 1e-11 * diagonal(s)
    # the curve passes exactly through the surface at the loop's points (the edges' vertices)
    geom = shapes._bspline_curve_3d(*curve)
    assert_close(_occ_points(geom, params), s.evaluate(torch.tensor(closed)).numpy(), atol=1e-12 * diagonal(s))


def _circle_loop(s, count=37, radius=0.4, centre=(0.5, 0.5)):
    """A wavy closed (u, v) polyline in ``s``'s domain, closed (first point again), and its chord parameters."""
    (u0, u1), (v0, v1) = s.domain
    th = np.linspace(0, 2 * np.pi, count, endpoint=False)
    r = radius + 0.05 * np.sin(3 * th)
    uv = np.stack([u0 + (centre[0] + r * np.cos(th)) * (u1 - u0), v0 + (centre[1] + r * np.sin(th)) * (v1 - v0)], 1)
    closed = np.vstack([uv, uv[:1]])
    return closed, shapes._chord_parameters(closed)


def test_trimming_curves_of_many_surfaces_in_one_batch_are_each_surfaces_own():
    """``approximate_trim_curves`` evaluates every surface of the same degrees and grid
    size in one batch: the curves must be those of each surface approximated alone
    (bit for bit), whatever the knot vectors (clamped, unclamped), sizes and degrees."""
    rng = np.random.default_rng(21)
    surfaces = []
    for degrees, kinds in [((3, 3), ("clamped", "clamped"))] * 3 + [((3, 3), ("unclamped", "clamped")),
                                                                    ((2, 3), ("clamped", "unclamped"))]:
        while True:  # three of the same grid size, with different knots
            s = random_surface(rng, degrees, kinds, scale=20.0)
            if len(surfaces) >= 3 or s.sizes == (surfaces[0].sizes if surfaces else s.sizes):
                break
        surfaces.append(s)
    assert surfaces[0].sizes == surfaces[1].sizes == surfaces[2].sizes
    jobs = []
    for k, s in enumerate(surfaces):
        loops = [_circle_loop(s, 29 + k), _circle_loop(s, 13, radius=0.12, centre=(0.45, 0.5))]
        jobs.append((s, loops, shapes.CURVE_TOLERANCE * diagonal(s)))
    together = shapes.approximate_trim_curves(jobs)
    for job, curves in zip(jobs, together):
        alone = shapes.approximate_loop_curves_3d(*job)
        assert len(curves) == len(alone) == 2
        for a, b in zip(curves, alone):
            assert a[3] == b[3]
            assert_close(a[0], b[0], atol=0)
            assert_close(a[2], b[2], atol=0)
        for (closed, params), curve in zip(job[1], curves):
            assert _dense_deviation(job[0], closed, params, curve) <= job[2]


def test_trimming_curve_across_a_crease_keeps_a_corner_there():
    """A bicubic surface with a triple knot (C0: a crease) in u: the polyline's segments
    are cut where they cross it, so the polynomial curve follows the crease within the
    tolerance instead of falling back to the exact curve."""
    x, y = np.meshgrid(np.linspace(0, 30, 7), np.linspace(0, 30, 5), indexing="ij")
    z = np.abs(x - 15.0) * 0.8  # a ridge along the crease line u = 0.5
    cp = np.stack([x, y, z], axis=-1)
    ku = torch.tensor([0, 0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1, 1], dtype=torch.float64)
    kv = torch.tensor([0, 0, 0, 0, 0.5, 1, 1, 1, 1], dtype=torch.float64)
    s = nurbskit.NURBSSurface(torch.tensor(cp), (3, 3), [ku, kv], torch.tensor(np.ones((7, 5)) + 0.1 * (y > 10)))
    assert [len(k) for k in shapes._crease_knots(s)] == [1, 0]
    closed, params = _circle_loop(s, 23)
    tolerance = shapes.CURVE_TOLERANCE * diagonal(s)
    curve = shapes.approximate_loop_curves_3d(s, [(closed, params)], tolerance)[0]
    assert curve[3] == shapes.APPROX_DEGREE and curve[1] is None  # approximated, not the exact fallback
    assert _dense_deviation(s, closed, params, curve) <= tolerance


def test_written_trimming_edges_carry_the_approximation_tolerance(tmp_path, monkeypatch):
    """Each trimming edge's tolerance is the one its 3-D curve was fitted to, the written
    file passes the check with it, and the exact curves (``EXACT_CURVES``) are still
    written on request."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    rng = np.random.default_rng(4)  # a wavy rational bicubic height field, 9 x 9 control points over 40 mm
    xy = np.stack(np.meshgrid(np.linspace(0, 40, 9), np.linspace(0, 40, 9), indexing="ij"), axis=-1)
    cp = np.concatenate([xy, 3 * np.sin(xy[..., :1] / 7) + rng.normal(0, 0.5, (9, 9, 1))], axis=-1)
    s = nurbskit.NURBSSurface(torch.tensor(cp), (3, 3), None, torch.tensor(rng.uniform(0.8, 1.25, (9, 9))))
    th = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    (u0, u1), (v0, v1) = s.domain
    centre, size = np.array([(u0 + u1) / 2, (v0 + v1) / 2]), np.array([u1 - u0, v1 - v0])
    circle = np.stack([np.cos(th), np.sin(th)], 1)
    outer = TrimLoop.from_uv(centre + 0.45 * size * circle)
    hole = TrimLoop(centre + 0.2 * size * circle, "hole")
    patch = TrimmedSurface(s, [outer, hole])
    expected = max(shapes.TOLERANCE, shapes.CURVE_TOLERANCE * max(diagonal(s), 1.0))
    assert expected == shapes.edge_tolerance(s) < shapes.CURVE_TOLERANCE_MAX

    def edges(face):
        exp, found = TopExp_Explorer(face, TopAbs_EDGE), []
        while exp.More():
            edge = TopoDS.Edge(exp.Current())
            found.append((BRep_Tool.Tolerance_s(edge), BRep_Tool.Curve_s(edge, 0.0, 1.0).Degree()))
            exp.Next()
        return np.array(found)

    approximated = edges(shapes.face_of(patch))
    assert_close(approximated[:, 0], np.full(len(approximated), expected), rtol=1e-12)
    assert set(approximated[:, 1]) == {shapes.APPROX_DEGREE}
    assert cad.write_cad(patch, tmp_path / "approximated.step")["valid"]
    monkeypatch.setattr(shapes, "EXACT_CURVES", True)
    assert set(edges(shapes.face_of(patch))[:, 1]) == {6}
    assert cad.write_cad(patch, tmp_path / "exact.step")["valid"]


def test_edge_tolerance_is_relative_within_its_bounds():
    """The trimming edges' tolerance is CURVE_TOLERANCE of the surface's diagonal, never
    coarser than CURVE_TOLERANCE_MAX (0.001 mm) nor finer than TOLERANCE; a 20 m surface
    gets the cap and its curves stay within it."""
    rng = np.random.default_rng(8)
    for scale in (1e-4, 1.0, 30.0, 2e4):
        s = random_surface(rng, (3, 3), scale=scale)
        relative = shapes.CURVE_TOLERANCE * max(diagonal(s), 1.0)
        expected = min(max(relative, shapes.TOLERANCE), shapes.CURVE_TOLERANCE_MAX)
        assert shapes.edge_tolerance(s) == expected
    assert shapes.edge_tolerance(s) == shapes.CURVE_TOLERANCE_MAX  # the 20 m one
    closed, params = _circle_loop(s, 31)
    curve = shapes.approximate_loop_curves_3d(s, [(closed, params)], shapes.edge_tolerance(s))[0]
    assert _dense_deviation(s, closed, params, curve) <= shapes.CURVE_TOLERANCE_MAX


def test_a_loop_outside_the_domain_is_refused():
    s = nurbskit.NURBSSurface(torch.rand(4, 4, 3, dtype=torch.float64), (3, 3))
    loop = TrimLoop.from_uv([[0.2, 0.2], [1.4, 0.2], [0.5, 0.8]])
    with pytest.raises(OptionError, match="leaves the surface's domain"):
        shapes.face_of(TrimmedSurface(s, [loop]))


# ---- patch sets, meshes ------------------------------------------------------------------

def _patch_set():
    """A rational bicubic surface split into 2 x 2 patches (shared edges), one with a hole."""
    rng = np.random.default_rng(8)
    xy = np.stack(np.meshgrid(np.linspace(0, 30, 6), np.linspace(0, 20, 5), indexing="ij"), axis=-1)
    cp = np.concatenate([xy, rng.normal(0, 1.5, (6, 5, 1))], axis=-1)
    whole = nurbskit.NURBSSurface(torch.tensor(cp), (3, 3), None, torch.tensor(rng.uniform(0.8, 1.2, (6, 5))))
    left, right = nurbskit.split(whole, 0.5, axis=0)
    patches = [*nurbskit.split(left, 0.5, axis=1), *nurbskit.split(right, 0.5, axis=1)]
    (u0, u1), (v0, v1) = patches[0].domain
    th = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    hole = TrimLoop(np.stack([(u0 + u1) / 2 + 0.2 * (u1 - u0) * np.cos(th),
                              (v0 + v1) / 2 + 0.2 * (v1 - v0) * np.sin(th)], 1), "hole")
    return [TrimmedSurface(patches[0], [hole])] + patches[1:]


def test_patch_set_is_sewn_into_one_valid_shell(tmp_path):
    patches = _patch_set()
    report = cad.write_cad(patches, tmp_path / "patches.step")
    assert report["valid"] and report["faces"] == 4 and report["shells"] == 1
    # 4 patches sharing edges: 12 distinct edges (the outer 8, the inner 4) plus the hole's
    # 48 segments in edges of shapes.EDGE_SEGMENTS segments
    assert report["edges"] == 12 + (48 // shapes.EDGE_SEGMENTS if shapes.EDGE_SEGMENTS else 1)
    model = cad.read_cad(tmp_path / "patches.step")
    assert sorted(len(f.holes) for f in model.faces) == [0, 0, 0, 1]


def test_patches_json_exports_to_step_and_reads_back_valid(tmp_path):
    from nurbskit.cli import main

    patches = _patch_set()
    src = tmp_path / "patches.json"
    src.write_text(json.dumps({"patches": [p.to_dict() if isinstance(p, TrimmedSurface) else
                                           nurbskit.core.serialize.to_dict(p) for p in patches]}))
    assert main(["export", str(src), str(tmp_path / "out.step")]) == 0
    info = cad.cad_info(tmp_path / "out.step")
    assert info["valid"] and info["num_faces"] == 4
    assert [f["sizes"] for f in info["faces"]] == [list(p.surface.sizes if isinstance(p, TrimmedSurface) else p.sizes)
                                                   for p in patches]
    # and back to nurbskit JSON: {"surfaces": [...]}, the trimmed one with its trim
    assert main(["export", str(tmp_path / "out.step"), str(tmp_path / "back.json")]) == 0
    data = json.loads((tmp_path / "back.json").read_text())
    assert len(data["surfaces"]) == 4 and sum("trim" in s for s in data["surfaces"]) == 1


def test_the_index_that_nurbskit_patches_writes_exports_its_faces(tmp_path):
    # `nurbskit patches` writes patches.json as an index: per patch its summary and the
    # files of its faces (patches/NNN.json); export follows the index, inside the folder only.
    from nurbskit.cli import main

    patches = _patch_set()
    (tmp_path / "patches").mkdir()
    index = []
    for i, p in enumerate(patches):
        name = f"patches/{i:03d}.json"
        data = p.to_dict() if isinstance(p, TrimmedSurface) else nurbskit.core.serialize.to_dict(p)
        (tmp_path / name).write_text(json.dumps(data))
        index.append({"index": i, "files": [name], "inliers": 10})
    (tmp_path / "patches.json").write_text(json.dumps({"patches": index, "history": []}))
    for src in (tmp_path / "patches.json", tmp_path):  # the file or its folder
        out = tmp_path / "out.step"
        out.unlink(missing_ok=True)
        assert main(["export", str(src), str(out)]) == 0
        assert cad.cad_info(out)["num_faces"] == len(patches)
    (tmp_path / "patches.json").write_text(json.dumps({"patches": [{"files": ["../outside.json"]}]}))
    with pytest.raises(NurbskitError, match="lies outside"):
        cad.read_objects(tmp_path / "patches.json")
    (tmp_path / "patches.json").write_text(json.dumps({"patches": [{"files": ["patches.json"]}]}))
    with pytest.raises(NurbskitError, match="expected a nurbskit JSON object"):  # not followed again
        cad.read_objects(tmp_path / "patches.json")


def test_a_batch_exports_one_face_per_element(tmp_path):
    # A nurbskit JSON batch (3, 2) of surfaces: export writes each element as one face (it
    # crashed in OpenCASCADE's point constructor); the library's converter refuses a batch.
    from nurbskit.cli import main

    g = torch.Generator().manual_seed(3)
    batch = nurbskit.NURBSSurface(torch.rand(3, 2, 4, 5, 3, generator=g, dtype=torch.float64), (3, 2))
    nurbskit.save(batch, tmp_path / "b.json")
    assert main(["export", str(tmp_path / "b.json"), str(tmp_path / "b.step")]) == 0
    faces = cad.read_cad(tmp_path / "b.step").faces
    assert len(faces) == 6
    uv = grid(batch[0, 0], 5)
    for face, (i, j) in zip(faces, [(i, j) for i in range(3) for j in range(2)]):
        assert_close(face.surface.evaluate(uv), batch[i, j].evaluate(uv), atol=1e-12)
    with pytest.raises(NurbskitError, match="select an element first"):
        cad.write_cad(batch, tmp_path / "direct.step")


def test_convert_refuses_a_cad_file_of_several_faces(tmp_path, capsys):
    # convert writes one NURBS object; it wrote a STEP file's first face alone, untrimmed,
    # without a word. A file of one untrimmed face still converts.
    from _cli import refused, run

    surfaces, _ = _random_set(12)
    cad.write_cad(surfaces[:2], tmp_path / "two.step", sew_tolerance=None)
    refused(capsys, ["convert", tmp_path / "two.step", tmp_path / "two.json"], "holds 2 faces", "nurbskit export")
    assert not (tmp_path / "two.json").exists()
    cad.write_cad(surfaces[2], tmp_path / "one.step")
    assert run(["convert", str(tmp_path / "one.step"), str(tmp_path / "one.json")]) == 0
    uv = grid(surfaces[2], 7)
    assert_close(nurbskit.load(tmp_path / "one.json").evaluate(uv), surfaces[2].evaluate(uv), atol=1e-12)


def test_a_truncated_step_file_is_refused_not_read_in_part(tmp_path):
    # Cut in the middle, a STEP file of 9 faces still loaded some of them with OCC's
    # unresolved-reference failures, and passed for the whole model.
    surfaces, _ = _random_set(11)
    cad.write_cad(surfaces, tmp_path / "set.step", sew_tolerance=None)
    lines = (tmp_path / "set.step").read_text().splitlines(keepends=True)
    cut = max(i for i in range(len(lines) // 2) if lines[i].rstrip().endswith(";")) + 1  # after a whole entity
    (tmp_path / "half.step").write_text("".join(lines[:cut] + lines[-3:]))  # and ENDSEC, END-ISO
    with pytest.raises(NurbskitError, match="load failures"):
        cad.read_cad(tmp_path / "half.step")
    assert len(cad.read_cad(tmp_path / "set.step").faces) == len(surfaces)


@pytest.mark.parametrize("ext", [".step", ".iges", ".brep"])
def test_trims_of_a_large_patch_read_back_as_written(tmp_path, ext):
    # The loops' 3-D curves approximate the trims within each edge's tolerance; STEP holds
    # one uncertainty per file, and at OCC's default (the average tolerance) its reader
    # re-derived the pcurves of the looser edges from the 3-D curves: a patch of 874 mm
    # read back with loops of 92 and 79 points for 64 and 32, moved by 0.14 mm.
    rng = np.random.default_rng(5)
    for _ in range(5):
        random_surface(rng, (3, 3), ("clamped", "clamped"), rational=True, scale=1.0)
    s = random_surface(rng, (3, 3), ("clamped", "clamped"), rational=True, scale=100.0)
    (u0, u1), (v0, v1) = s.domain
    c, r = np.array([(u0 + u1) / 2, (v0 + v1) / 2]), np.array([(u1 - u0) / 2, (v1 - v0) / 2])
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    loops = [TrimLoop.from_uv(c + 0.9 * r * np.c_[np.cos(th), np.sin(th)]),
             TrimLoop(c + 0.3 * r * np.c_[np.cos(th[::2]), np.sin(th[::2])], "hole")]
    cad.write_cad(TrimmedSurface(s, loops), tmp_path / f"patch{ext}")
    back = cad.read_cad(tmp_path / f"patch{ext}").faces[0]
    for written in loops:
        (read,) = [loop for loop in back.loops if loop.kind == written.kind]
        assert len(read.uv) == len(written.uv)
        # the same points, possibly from another start
        start = int(np.argmin(np.linalg.norm(read.uv - written.uv[0], axis=1)))
        assert_close(torch.tensor(np.roll(read.uv, -start, 0)), torch.tensor(written.uv), atol=1e-9 * (u1 - u0))


def test_closed_mesh_becomes_a_valid_solid_of_the_same_volume(tmp_path):
    import trimesh
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    mesh = trimesh.creation.icosphere(subdivisions=1, radius=7.0)
    report = cad.write_cad((np.asarray(mesh.vertices), np.asarray(mesh.faces)), tmp_path / "ball.step")
    assert report["valid"] and report["solids"] == 1 and report["faces"] == len(mesh.faces)
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(cad.read_shape(tmp_path / "ball.step"), props)
    assert abs(props.Mass() - mesh.volume) <= 1e-9 * mesh.volume


def test_a_mesh_of_two_pieces_becomes_two_solids(tmp_path):
    # One shell holding two disconnected boxes failed the check ("not written"); each
    # connected piece is now its own solid.
    import trimesh
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    a = trimesh.creation.box((1.0, 2.0, 3.0))
    b = trimesh.creation.box((2.0, 2.0, 2.0))
    b.apply_translation((10.0, 0.0, 0.0))
    both = trimesh.util.concatenate([a, b])
    for ext in (".step", ".brep"):
        report = cad.write_cad((np.asarray(both.vertices), np.asarray(both.faces)), tmp_path / f"two{ext}")
        assert report["valid"] and report["solids"] == 2 and report["faces"] == 24
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(cad.read_shape(tmp_path / f"two{ext}"), props)
        assert abs(props.Mass() - (a.volume + b.volume)) <= 1e-9 * (a.volume + b.volume)


# ---- the check is built in ----------------------------------------------------------------

def test_a_failing_check_is_an_error_and_leaves_no_file(tmp_path, monkeypatch):
    from nurbskit.io.cad import exchange

    monkeypatch.setattr(exchange, "check_shape", lambda shape: {"valid": False, "faces": 1, "solids": 0,
                                                                "shells": 0, "edges": 4})
    target = tmp_path / "bad.step"
    with pytest.raises(NurbskitError, match="fails OpenCASCADE's check"):
        cad.write_cad(nurbskit.NURBSSurface(torch.rand(4, 4, 3, dtype=torch.float64), (3, 3)), target)
    assert list(tmp_path.iterdir()) == []


def test_missing_ocp_names_the_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "OCP", None)  # import OCP now raises ImportError
    with pytest.raises(NurbskitError, match=r"nurbskit\[cad\]"):
        occ.ocp()


# ---- real data: the ABC model's STEP lies on its STL ------------------------------------

def _inside(loops, uv: np.ndarray) -> np.ndarray:
    from matplotlib.path import Path as MplPath

    keep = np.ones(len(uv), dtype=bool)
    for loop in loops:
        inside = MplPath(loop.uv).contains_points(uv)
        keep &= inside if loop.kind == "outer" else ~inside
    return keep


def _segment_distance(p, e0, e1):
    e = e1 - e0
    t = np.clip(((p - e0) * e).sum(-1) / np.maximum((e * e).sum(-1), 1e-300), 0, 1)
    return np.linalg.norm(p - (e0 + t[..., None] * e), axis=-1)


def _distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, chunk: int = 64) -> np.ndarray:
    """Point-to-triangle distance against every triangle (brute force, the naive oracle):
    the plane where the foot lies inside the triangle, else the nearest edge."""
    a, b, c = (vertices[faces][None, :, i, :] for i in range(3))
    n = np.cross(b - a, c - a)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    out = np.empty(len(points))
    for start in range(0, len(points), chunk):
        p = points[start:start + chunk, None, :]
        height = ((p - a) * n).sum(-1)
        foot = p - height[..., None] * n
        inside = np.ones(height.shape, dtype=bool)
        for e0, e1 in ((a, b), (b, c), (c, a)):
            inside &= (np.cross(e1 - e0, foot - e0) * n).sum(-1) >= 0
        edge = np.min([_segment_distance(p, e0, e1) for e0, e1 in ((a, b), (b, c), (c, a))], axis=0)
        out[start:start + chunk] = np.where(inside, np.abs(height), edge).min(axis=1)
    return out


def test_abc_step_faces_lie_on_the_abc_stl(shared_data, tmp_path):
    from nurbskit.io import read_mesh

    step = shared_file(shared_data, "abc/00000050_80d90bfdd2e74e709956122a_step_000.step")
    stl = read_mesh(shared_file(shared_data, "abc/00000050_80d90bfdd2e74e709956122a_trimesh_000.stl"))
    model = cad.read_cad(step)
    assert len(model.faces) == 43  # the feature file: 20 planes, 23 cylinders
    assert sorted(set(model.face_types)) == ["CylindricalSurface", "Plane"]
    diag = float(np.linalg.norm(stl.vertices.max(axis=0) - stl.vertices.min(axis=0)))
    samples = []
    rng = np.random.default_rng(0)
    for face in model.faces:
        (u0, u1), (v0, v1) = face.surface.domain
        if face.outer is not None:
            (u0, v0), (u1, v1) = face.outer.uv.min(axis=0), face.outer.uv.max(axis=0)
        uv = np.column_stack([rng.uniform(u0, u1, 400), rng.uniform(v0, v1, 400)])
        uv = uv[_inside(face.loops, uv)][:10]
        assert len(uv) > 0
        samples.append(face.surface.evaluate(torch.tensor(uv)).numpy())
    # the STEP file declares metres; OCC's reader gives millimetres (nurbskit's unit); the STL is in metres
    samples = np.vstack(samples) / 1000.0
    dist = _distance_to_mesh(samples, stl.vertices, stl.faces)
    assert dist.max() <= 1e-3 * diag
    # written back (full cylinders re-seated on one period, curved trims as polylines): valid, same area
    report = cad.write_cad(model.faces, tmp_path / "abc.step")
    assert report["valid"] and report["faces"] == 43
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    areas = []
    for shape in (cad.read_shape(step), cad.read_shape(tmp_path / "abc.step")):
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(shape, props, 1e-4)  # adaptive (the fixed rule misses rational patches by 0.1 %)
        areas.append(props.Mass())
    assert abs(areas[1] - areas[0]) <= 1e-3 * areas[0]  # measured 1.4e-4: circular holes as polylines


def _face_with_crossing_hole():
    """A face whose hole crosses its outer loop: invalid (BRepCheck_IntersectingWires)."""
    from OCP.BRepCheck import BRepCheck_Analyzer

    g = np.linspace(0.0, 10.0, 4)
    cp = np.stack([*np.meshgrid(g, g, indexing="ij"), np.zeros((4, 4))], -1)
    surface = nurbskit.NURBSSurface(torch.tensor(cp), (3, 3))
    th = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    outer = TrimLoop.from_uv(np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]]))
    hole = TrimLoop(np.stack([0.8 + 0.15 * np.cos(th), 0.5 + 0.15 * np.sin(th)], 1)[::-1], "hole")
    face = shapes.face_of(TrimmedSurface(surface, [outer, hole]))
    assert not BRepCheck_Analyzer(face).IsValid()
    return face


@pytest.mark.parametrize("fmt", ["step", "iges", "brep"])
def test_an_invalid_shape_is_caught_by_the_check_without_healing(tmp_path, fmt):
    from nurbskit.io.cad.exchange import read_shape, write_shape

    face = _face_with_crossing_hole()
    with pytest.raises(NurbskitError, match="fails OpenCASCADE's check"):
        write_shape(face, tmp_path / f"bad.{fmt}")
    assert list(tmp_path.iterdir()) == []
    # the check reads the file as written: OCC's healing (read_shape's default) would have
    # cut the face into two valid ones, and a check of that would have passed
    write_shape(face, tmp_path / f"bad.{fmt}", check=False)
    unhealed = shapes.check_shape(read_shape(tmp_path / f"bad.{fmt}", heal=False))
    assert not unhealed["valid"] and unhealed["faces"] == 1
    if fmt != "brep":  # BREP has no healing on reading
        healed = shapes.check_shape(read_shape(tmp_path / f"bad.{fmt}"))
        assert healed["valid"] and healed["faces"] == 2


def test_a_cad_file_exported_to_cad_keeps_its_solids_and_shared_edges(shared_data, tmp_path, capsys):
    # CAD to CAD goes through OCC's shape as read: through nurbskit's faces (B-splines with
    # polyline trims, sewn again) the ABC model came back as 3 open shells of 502 edges
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    from nurbskit.cli import main

    step = shared_file(shared_data, "abc/00000050_80d90bfdd2e74e709956122a_step_000.step")
    original = cad.read_shape(step)
    assert shapes.count_shapes(original) == {"solids": 3, "shells": 3, "faces": 43, "edges": 106}

    def volume(shape):
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(shape, props)
        return props.Mass()

    for ext in (".step", ".brep"):
        assert main(["export", str(step), str(tmp_path / f"abc{ext}")]) == 0
        back = cad.read_shape(tmp_path / f"abc{ext}")
        assert shapes.check_shape(back) == {"valid": True, **shapes.count_shapes(original)}
        assert abs(volume(back) - volume(original)) <= 1e-9 * abs(volume(original))
    capsys.readouterr()
    assert main(["export", str(step), str(tmp_path / "abc.iges")]) == 0
    assert "cannot store solids and shells" in capsys.readouterr().err
    assert shapes.count_shapes(cad.read_shape(tmp_path / "abc.iges"))["faces"] == 43


def _enclosed_volume(s, per_span: int = 8) -> float:
    """|(1/3) integral of S . (S_u x S_v) du dv| over the domain (the divergence theorem on
    a closed surface): Gauss-Legendre with ``per_span`` nodes in every knot span."""
    nodes, weights = np.polynomial.legendre.leggauss(per_span)
    axes, ws = [], []
    for kv, p, n in zip(s.knot_vectors, s.degrees, s.sizes):
        k = np.unique(kv.numpy()[p : n + 1])
        a, b = k[:-1, None], k[1:, None]
        axes.append(((a + b) / 2 + (b - a) / 2 * nodes).reshape(-1))
        ws.append(((b - a) / 2 * weights).reshape(-1))
    d = s.evaluate_grid(torch.tensor(axes[0]), torch.tensor(axes[1]), order=1).numpy()
    triple = np.einsum("ijk,ijk->ij", d[..., 0, 0, :], np.cross(d[..., 1, 0, :], d[..., 0, 1, :]))
    return abs(float(np.einsum("i,j,ij->", ws[0], ws[1], triple)) / 3.0)


def test_a_closed_fit_is_written_as_a_solid(tmp_path):
    # periodic in v with a pole at each end of u: one face whose seam and poles close it, so
    # it bounds a solid (it was written as an open face, and as a band slit along the seam)
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    s = nurbskit.load(Path(__file__).parent / "data" / "pole_seam_fit.json")
    expected = _enclosed_volume(s)
    for ext in (".step", ".brep"):
        report = cad.write_cad(s, tmp_path / f"fit{ext}")
        assert (report["solids"], report["shells"], report["faces"], report["valid"]) == (1, 1, 1, True)
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(cad.read_shape(tmp_path / f"fit{ext}"), props, 1e-10)
        assert props.Mass() > 0  # oriented outward
        assert abs(props.Mass() - expected) <= 1e-6 * expected
    report = cad.write_cad(s, tmp_path / "fit.iges")  # IGES trimmed surfaces: the face alone
    assert (report["faces"], report["solids"], "left_out" in report) == (1, 0, False)
    # an open surface stays a face
    open_patch = random_surface(np.random.default_rng(2), (3, 3))
    assert (cad.write_cad(open_patch, tmp_path / "open.step")["solids"]) == 0
