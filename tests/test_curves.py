"""Synthetic curve drawings and the classical curve path (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest

import nurbskit
from nurbskit.curves.classic import chamfer_points, chamfer_to_ink, fit_image, fit_stroke, ink_mask, to_grey
from nurbskit.curves.synthetic import SyntheticConfig, curve_of, dense_samples, make_sample, photograph, render
from nurbskit.errors import InputError, OptionError

from _assert import assert_close

# A smooth, non-self-intersecting cubic in a 128 x 128 image.
KNOWN = np.array([[14.0, 100.0], [40.0, 20.0], [80.0, 30.0], [112.0, 96.0]])


def _draw(polygons, size=(128, 128), width=2.0):
    return 1.0 - render([dense_samples(curve_of(p)) for p in polygons], size, width)


def _symmetric(curves, truths):
    got = np.concatenate([dense_samples(c) for c in curves])
    want = np.concatenate([dense_samples(curve_of(p)) for p in truths])
    return chamfer_points(got, want)["symmetric"]


def test_synthetic_is_deterministic_and_follows_the_recipe():
    config = SyntheticConfig()
    a, b = make_sample(11, config), make_sample(11, config)
    assert np.array_equal(a.image, b.image)
    assert all(np.array_equal(p, q) for p, q in zip(a.control_points, b.control_points))
    assert not np.array_equal(a.image, make_sample(12, config).image)
    counts = set()
    for seed in range(30):
        s = make_sample(seed, config)
        assert s.image.shape == (128, 128) and 0.0 <= s.image.min() and s.image.max() <= 1.0
        assert 1 <= s.n_curves <= 3 and list(s.counts) == [len(p) for p in s.control_points]
        for p in s.control_points:
            assert 4 <= len(p) <= 6
            assert p[0, 0] <= p[-1, 0]  # canonical orientation
            assert (p >= 4).all() and (p[:, 0] <= 124).all() and (p[:, 1] <= 124).all()
        counts.add(s.n_curves)
    assert counts == {1, 2, 3}


def test_synthetic_curves_render_where_their_control_points_say():
    config = SyntheticConfig(size=(96, 64), width=2.0)
    s = make_sample(3, config)
    assert s.image.shape == (96, 64)
    curve_pts = np.concatenate([dense_samples(c) for c in s.curves()])
    cols = np.clip(curve_pts[:, 0].astype(int), 0, 63)
    rows = np.clip(curve_pts[:, 1].astype(int), 0, 95)
    # Every pixel the curve passes through lies within 0.71 px of it: ink >= 1 - 0.21.
    assert s.image[rows, cols].max() <= 0.25
    # Pixels farther than width/2 + 1/2 from every curve point are untouched background.
    from scipy.spatial import cKDTree

    ys, xs = np.mgrid[0:96, 0:64]
    d = cKDTree(curve_pts).query(np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], 1))[0].reshape(96, 64)
    assert (s.image[d > 1.5 + 0.01] == 1.0).all()
    assert (s.image[d < 0.5] == 0.0).all()


def test_synthetic_config_rejects_bad_values():
    with pytest.raises(OptionError, match="ctrl"):
        SyntheticConfig(ctrl=(2, 3))
    with pytest.raises(OptionError, match="width"):
        SyntheticConfig(width=0)


def test_fit_stroke_recovers_an_exact_cubic():
    truth = curve_of(KNOWN)
    pts = dense_samples(truth, spacing=1.0)
    curve, err = fit_stroke(pts, tolerance=0.01)
    assert err <= 0.01
    import torch

    from nurbskit.core.project import project_points_curve

    back = project_points_curve(curve, torch.as_tensor(dense_samples(truth, spacing=0.1))).distance
    assert float(back.max()) < 0.02  # the whole true curve lies on the fit, not only the samples


@pytest.mark.parametrize("degree", [1, 2, 3])
@pytest.mark.parametrize("smooth", [0.0, 1e-2, 0.5])
def test_banded_least_squares_equals_the_dense_solution(degree, smooth):
    import torch

    from nurbskit.core.basis import basis_matrix
    from nurbskit.curves.classic import _banded_least_squares, _local_basis

    rng = np.random.default_rng(degree)
    n_ctrl = 23
    u = np.sort(rng.uniform(0, 1, 200))
    u[0], u[-1] = 0.0, 1.0
    points = rng.normal(size=(200, 2)) * 10
    # uneven interior knots (as fit_stroke places them), one of them doubled
    interior = np.sort(rng.uniform(0.05, 0.95, n_ctrl - degree - 2))
    interior = np.sort(np.append(interior, interior[3]))
    knots = np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
    values, first = _local_basis(knots, degree, torch.from_numpy(u), 0)
    got = _banded_least_squares(values[:, 0], first, points, n_ctrl, smooth)
    # Oracle: the dense system [B; smooth D] c = [points; 0] by numpy's least squares.
    B = basis_matrix(torch.from_numpy(knots), degree, n_ctrl, torch.from_numpy(u))
    D = np.diff(np.eye(n_ctrl), n=2, axis=0) * smooth
    want = np.linalg.lstsq(np.vstack([B.numpy(), D]), np.vstack([points, np.zeros((n_ctrl - 2, 2))]), rcond=None)[0]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_fit_stroke_follows_a_long_wavy_stroke():
    # 3,000 points, about 80 control points: the banded normal equations at the size of
    # a large scan's strokes.
    t = np.linspace(0.0, 1.0, 3000)
    pts = np.stack([2000.0 * t, 40.0 * np.sin(60.0 * t)], axis=1)
    curve, err = fit_stroke(pts, tolerance=0.5)
    assert err <= 0.5
    assert 40 <= curve.control_points.shape[0] <= 200


def test_fit_stroke_puts_its_knots_where_the_stroke_bends():
    # 1,000 px straight, then 100 px of tight waves: the waves need knots, the line none.
    x = np.arange(0.0, 1100.0, 0.5)
    y = np.where(x < 1000.0, 0.0, 8.0 * np.sin((x - 1000.0) / 100.0 * 6.0 * np.pi))
    pts = np.stack([x, y], axis=1)
    curve, err = fit_stroke(pts, tolerance=0.5)
    assert err <= 0.5
    knots = curve.knot_vector.numpy()[4:-4]
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    u_wave = chord[x == 1000.0][0] / chord[-1]  # where the waves begin (about 0.885)
    assert (knots > u_wave - 0.02).sum() >= 15  # the waves hold the knots ...
    assert (knots < 0.7).sum() <= 3  # ... the first 700 px of line next to none
    # uniform knots spread their spans over the line too: several times the control points
    from nurbskit.curves.classic import _control_points_needed

    assert 4 * curve.control_points.shape[0] < _control_points_needed(pts, 0.5)[0]

def test_classic_recovers_a_drawn_spline():
    image = _draw([KNOWN])
    curves = nurbskit.curves_from_image(image)
    assert len(curves) == 1
    assert _symmetric(curves, [KNOWN]) < 1.0
    assert curves[0].control_points[0, 0] < curves[0].control_points[-1, 0]  # canonical orientation


def test_classic_splits_an_x_into_two_strokes():
    a = np.array([[10.0, 10.0], [40.0, 40.0], [80.0, 80.0], [110.0, 110.0]])
    b = np.array([[10.0, 110.0], [40.0, 80.0], [80.0, 40.0], [110.0, 10.0]])
    curves = nurbskit.curves_from_image(_draw([a, b], width=3.0))
    assert len(curves) == 2
    assert _symmetric(curves, [a, b]) < 1.0
    for c in curves:  # each stroke runs corner to corner, not around the crossing
        ends = c.control_points[[0, -1]].numpy()
        assert np.linalg.norm(ends[0] - ends[1]) > 120


def test_classic_light_on_dark_matches_dark_on_light():
    image = _draw([KNOWN])
    mask, inverted = ink_mask(1.0 - image)
    assert inverted
    other = ink_mask(image)[0]
    assert (mask != other).sum() <= 0.02 * other.sum()  # only pixels at the threshold itself may differ
    curves = nurbskit.curves_from_image((255 * (1.0 - image)).astype(np.uint8))
    assert len(curves) == 1 and _symmetric(curves, [KNOWN]) < 1.0


def test_blank_images_are_a_one_line_error():
    for blank in (np.ones((32, 32)), np.zeros((32, 32), np.uint8)):
        with pytest.raises(InputError, match="blank") as info:
            nurbskit.curves_from_image(blank)
        assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="empty"):
        to_grey(np.zeros((0, 5)))
    with pytest.raises(OptionError, match="method"):
        nurbskit.curves_from_image(_draw([KNOWN]), method="nope")


def test_refinement_does_not_move_away_from_the_ink():
    image = _draw([KNOWN], width=3.0)
    before, strokes = fit_image(image, tolerance=3.0)
    after, _ = fit_image(image, tolerance=3.0, refine_iterations=10)
    sq = lambda cs: chamfer_to_ink(cs, strokes.ink)["symmetric"]  # noqa: E731
    assert sq(after) <= sq(before) + 1e-9
    assert _symmetric(after, [KNOWN]) < 1.0


def test_to_grey_scales_integer_and_colour_images():
    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[0, 0] = 255
    assert_close(to_grey(rgb), np.array([[1.0, 0.0], [0.0, 0.0]]), atol=1e-12)
    rgba = np.zeros((1, 2, 4), np.uint8)
    rgba[0, 1, 3] = 255  # opaque black beside a transparent pixel (white)
    assert_close(to_grey(rgba), np.array([[1.0, 0.0]]), atol=1e-12)


def test_curves_doctests():
    import doctest

    from nurbskit.curves import api, classic, synthetic

    for module in (api, classic, synthetic):
        assert doctest.testmod(module, raise_on_error=False).failed == 0


def test_a_t_junction_gives_a_bar_and_a_stem():
    bar = np.array([[10.0, 30.0], [40.0, 30.0], [80.0, 30.0], [118.0, 30.0]])
    stem = np.array([[64.0, 30.0], [64.0, 60.0], [64.0, 90.0], [64.0, 118.0]])
    curves = nurbskit.curves_from_image(_draw([bar, stem], width=3.0))
    assert len(curves) == 2
    lengths = sorted(np.linalg.norm(np.diff(dense_samples(c), axis=0), axis=1).sum() for c in curves)
    assert lengths[1] > 100  # the bar is one stroke, not split at the stem
    assert _symmetric(curves, [bar, stem]) < 1.0


def _iou(a, b):
    return (a & b).sum() / (a | b).sum()


def test_even_background_leaves_clean_and_small_images_alone():
    from nurbskit.curves.classic import even_background

    clean = _draw([KNOWN * 2], size=(256, 256), width=3.0)
    assert even_background(clean) is clean
    small = photograph(_draw([KNOWN / 4], size=(32, 32)), "lamp")  # under 64 px: no lighting model
    assert even_background(small) is small
    with pytest.raises(OptionError, match="light"):
        photograph(clean, "sun")


@pytest.mark.parametrize("light", ["lamp", "vignette", "board"])
def test_a_photographed_drawing_reads_as_the_clean_one(light):
    """Uneven light (and noise) defeats one global threshold; with the background evened,
    the ink is the clean drawing's and the classical path finds its one curve."""
    from skimage.filters import threshold_otsu

    from nurbskit.curves.classic import even_background

    clean = _draw([KNOWN * 2], size=(256, 256), width=3.0)
    photo = photograph(clean, light, noise=0.03, seed=5)
    want, _ = ink_mask(clean)
    plain = photo <= threshold_otsu(photo)
    assert _iou(plain if light != "board" else ~plain, want) < 0.5  # Otsu alone fails here
    got, inverted = ink_mask(even_background(photo))
    assert inverted == (light == "board")
    assert _iou(got, want) > 0.8
    curves = nurbskit.curves_from_image(photo, method="classic")
    assert len(curves) == 1 and _symmetric(curves, [KNOWN * 2]) < 1.0


def test_ink_mask_keeps_clear_of_background_noise():
    """A short stroke on evenly lit, noisy paper: Otsu alone splits the paper's noise."""
    from skimage.filters import threshold_otsu

    clean = _draw([np.array([[100.0, 120.0], [120.0, 110.0], [140.0, 125.0], [160.0, 118.0]])], (256, 256), 3.0)
    photo = np.clip(0.8 * (0.25 + 0.75 * clean) + np.random.default_rng(3).normal(0, 0.04, clean.shape), 0, 1)
    want, _ = ink_mask(clean)
    assert (photo <= threshold_otsu(photo)).sum() > 5 * want.sum()
    got, inverted = ink_mask(photo)
    assert not inverted and _iou(got, want) > 0.8


def test_guides_refined_on_the_reduced_ink_land_on_the_full_size_strokes():
    # The hybrid's guides on large drawings are refined on the ink reduced 3x (768 px ->
    # 256 px) and scaled back: they must end near the true curves in full-size pixels.
    import torch

    from nurbskit.core import NURBSCurve
    from nurbskit.curves.api import _coarse_refined

    s = make_sample(7, SyntheticConfig(size=(768, 768), curves=(2, 2), width=6.0))
    ink = ink_mask(s.image)[0]
    truth = s.curves()
    shifted = [NURBSCurve(c.control_points + torch.tensor([9.0, -7.0], dtype=torch.float64), degree=3)
               for c in truth]
    guides = _coarse_refined(shifted, ink, 20)
    truth_pts = np.concatenate([dense_samples(c) for c in truth])
    before = chamfer_points(np.concatenate([dense_samples(c) for c in shifted]), truth_pts)["symmetric"]
    after = chamfer_points(np.concatenate([dense_samples(c) for c in guides]), truth_pts)["symmetric"]
    assert before > 6.0 and after < 1.0, (before, after)  # 0.21 px (0.11 px refined at full size)


def test_the_refinements_sample_matrix_evaluates_every_curve():
    # S @ cat(P) must be each curve's points at uniform parameters, curve after curve:
    # the core's evaluation is the oracle (uneven knots, degrees 1 to 3, a domain [2, 5]).
    import torch

    from nurbskit.core import NURBSCurve
    from nurbskit.curves.classic import _sample_matrix

    rng = np.random.default_rng(3)
    curves = []
    for degree, n, (lo, hi) in ((3, 9, (0, 1)), (1, 4, (0, 1)), (2, 6, (2, 5)), (3, 4, (0, 1))):
        interior = np.sort(rng.uniform(0.1, 0.9, n - degree - 1))
        knots = lo + (hi - lo) * np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
        curves.append(NURBSCurve(torch.from_numpy(rng.uniform(0, 100, (n, 2))), degree=degree,
                                 knot_vector=torch.from_numpy(knots)))
    S = _sample_matrix(curves, 0.5)
    got = torch.sparse.mm(S, torch.cat([c.control_points for c in curves]))
    want = []
    for c in curves:
        m = int(np.clip(np.linalg.norm(np.diff(c.control_points.numpy(), axis=0), axis=1).sum() / 0.5, 16, 4096))
        lo, hi = c.domain[0]
        want.append(c.evaluate(torch.linspace(lo, hi, m, dtype=torch.float64)))
    want = torch.cat(want)
    assert got.shape == want.shape and S.shape[1] == sum(len(c.control_points) for c in curves)
    assert float((got - want).abs().max()) < 1e-11


def test_noise_is_not_mistaken_for_ink_and_says_so():
    noise = (np.random.default_rng(0).random((200, 200)) < 0.5).astype(float)
    with pytest.raises(InputError, match=r"noise.png: no strokes found: 50 % of the pixels are dark"):
        ink_mask(noise, "noise.png")
