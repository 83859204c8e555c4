"""The classical curve path: strokes rejoined through junctions by good continuation (issue 10)."""

from __future__ import annotations

import numpy as np

from nurbskit.curves.classic import _fill_slivers, chamfer_points, fit_image
from nurbskit.curves.synthetic import curve_of, dense_samples, render


def _polyline_image(polylines, size=(128, 128), width=2.0):
    return 1.0 - render(polylines, size, width)


def _curve(cp):
    return dense_samples(curve_of(np.asarray(cp, dtype=float)), 0.25)


def _symmetric(curves, truth):
    got = np.concatenate([dense_samples(c) for c in curves])
    return chamfer_points(got, np.concatenate(truth))["symmetric"]


def test_an_x_of_two_curves_gives_two_curves_each_straight_through():
    a = _curve([[10, 20], [50, 50], [80, 80], [118, 110]])
    b = _curve([[10, 110], [50, 80], [80, 50], [118, 20]])
    for width in (1.0, 2.0, 3.0):
        curves, _ = fit_image(_polyline_image([a, b], width=width))
        assert len(curves) == 2, width
        assert _symmetric(curves, [a, b]) < 1.0
        for c in curves:  # each runs from one side to the other (no turn at the crossing)
            ends = c.control_points[[0, -1]].numpy()
            assert abs(ends[0, 0] - ends[1, 0]) > 90


def test_a_figure_eight_is_one_closed_curve():
    t = np.linspace(0, 2 * np.pi, 2000)
    eight = np.stack([64 + 45 * np.sin(t), 64 + 40 * np.sin(t) * np.cos(t)], axis=1)
    curves, _ = fit_image(_polyline_image([eight], width=2.0))
    assert len(curves) == 1
    assert _symmetric(curves, [eight]) < 1.0


def test_an_open_curve_crossing_itself_is_one_curve():
    # A curl: the curve loops once and crosses its own path (a cubic with a loop).
    curl = _curve([[10, 100], [110, 20], [20, 20], [118, 100]])
    curves, _ = fit_image(_polyline_image([curl], width=2.0))
    assert len(curves) == 1
    assert _symmetric(curves, [curl]) < 1.0


def test_a_t_junction_gives_two_curves():
    bar = _curve([[10, 30], [40, 30], [80, 30], [118, 30]])
    stem = _curve([[64, 30], [64, 60], [64, 90], [64, 118]])
    curves, _ = fit_image(_polyline_image([bar, stem], width=2.0))
    assert len(curves) == 2
    lengths = sorted(np.linalg.norm(np.diff(dense_samples(c), axis=0), axis=1).sum() for c in curves)
    assert lengths[1] > 100  # the bar is one curve, not split at the stem


def test_a_hairpin_is_one_curve():
    # The curve turns back sharply: near the tip its two sides merge into one skeleton line
    # (a three-way junction with a dead end); the tip is joined, not split off.
    pin = np.concatenate([
        np.stack([np.linspace(10, 110, 400), 60 - np.linspace(10, 0.5, 400) ** 1.0], axis=1),
        np.stack([np.linspace(110, 10, 400), 60 + np.linspace(0.5, 10, 400) ** 1.0], axis=1),
    ])
    curves, _ = fit_image(_polyline_image([pin], width=2.0))
    assert len(curves) == 1
    tip = max(float(dense_samples(c)[:, 0].max()) for c in curves)
    assert tip > 106  # the tip is kept


def test_two_curves_touching_near_tangentially_give_two_curves():
    x = np.linspace(8, 120, 600)
    upper = np.stack([x, 64 - 0.004 * (x - 64) ** 2], axis=1)
    lower = np.stack([x, 64 + 0.004 * (x - 64) ** 2], axis=1)
    curves, _ = fit_image(_polyline_image([upper, lower], width=2.0))
    assert len(curves) == 2
    assert _symmetric(curves, [upper, lower]) < 1.0


def test_thin_holes_are_filled_and_loops_kept():
    ink = np.zeros((40, 60), bool)
    ink[10:13, 5:55] = ink[14:17, 5:55] = True  # two bars one pixel apart...
    ink[10:17, 5:8] = ink[10:17, 52:55] = True  # ...closed at both ends: a one-pixel sliver
    ink[25:36, 20:31] = True
    ink[28:33, 23:28] = False  # a 5 x 5 hole: a real loop
    filled = _fill_slivers(ink)
    assert filled[13, 8:52].all()
    assert not filled[28:33, 23:28].any()
    assert (filled & ~ink).sum() == 44


def test_tracing_an_empty_mask_gives_no_strokes():
    from nurbskit.curves.classic import trace_strokes

    strokes, width = trace_strokes(np.zeros((16, 16), bool))
    assert strokes == [] and width == 1.0


def test_strokes_keep_image_coordinates_after_cropping():
    # Ink far from the origin: the tracer works on the ink's bounding box, and the
    # strokes must come back in the image's pixel coordinates.
    ink = np.zeros((200, 300), bool)
    ink[150:153, 120:280] = True  # a bar whose centre line is y = 151.5
    from nurbskit.curves.classic import trace_strokes

    [stroke], _ = trace_strokes(ink)
    assert abs(float(np.median(stroke[:, 1])) - 151.5) < 0.51
    assert stroke[:, 0].min() < 125 and stroke[:, 0].max() > 275
