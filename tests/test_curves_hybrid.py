"""The default method, ``hybrid``: the classical path with the MV network's count vote (issue 10).

The vote (``nets.predict.count_probabilities``) reads the drawing's skeleton redrawn as the
training drawings are (``nets.predict.redrawn``), and enters the classical pairing search
as evidence (``classic._fewest_curves``, ``prior``); where the classical count stays much
less likely than the vote's, the network's curves are returned (``api._hybrid``).
"""

from __future__ import annotations

import json

import numpy as np
from skimage.morphology import skeletonize

from _curves import assert_counted_right
from test_curves_classic_shared import _pixels

from nurbskit.curves.api import extract
from nurbskit.curves.classic import _chains, _fewest_curves, _fill_slivers, chamfer_points, ink_mask
from nurbskit.curves.nets.predict import TRAIN_SIZE, network_ink, redrawn
from nurbskit.curves.synthetic import SyntheticConfig, dense_samples, make_sample, render


def _skeleton(image):
    ink, _ = ink_mask(image)
    return skeletonize(_fill_slivers(ink))


def _ink_points(grey):
    rows, cols = np.nonzero(grey < 0.5)
    return np.stack([cols + 0.5, rows + 0.5], axis=1).astype(float)


def test_redrawn_drawings_look_alike_at_any_width_and_size():
    # The networks saw 2 px strokes at 128 px only. The same curves drawn 1 or 3 px wide,
    # or at 512 px, are redrawn from their skeletons into nearly the same training-frame
    # image, while the raw network inputs differ (ink amount) by about the width ratio.
    drawn = {(size, w): make_sample(300_042, SyntheticConfig(size=(size, size), curves=(2, 2), width=w))
             for size, w in ((128, 1.0), (128, 3.0), (512, 2.0))}
    reference = redrawn(_skeleton(drawn[(128, 1.0)].image))
    assert reference.shape == (TRAIN_SIZE, TRAIN_SIZE)
    for key in ((128, 3.0), (512, 2.0)):
        other = redrawn(_skeleton(drawn[key].image))
        assert other.shape == (TRAIN_SIZE, TRAIN_SIZE)
        assert chamfer_points(_ink_points(other), _ink_points(reference))["symmetric"] < 1.0, key
        assert abs(float((1 - other).sum()) / float((1 - reference).sum()) - 1.0) < 0.2, key
    raw = [float(network_ink(drawn[(128, w)].image, 64).sum()) for w in (1.0, 3.0)]
    assert raw[1] / raw[0] > 2.0


def _shared_segment_graph():
    # The graph of test_curves_classic_shared: a shallow crossing, two three-way junctions
    # joined by one segment; without evidence the search walks the segment twice (2 curves).
    j0, j1 = (50, 40), (50, 70)
    edges = [(0, 1, _pixels(j0, j1)), (2, 0, _pixels((44, 0), j0)), (3, 0, _pixels((56, 0), j0)),
             (1, 4, _pixels(j1, (44, 110))), (1, 5, _pixels(j1, (56, 110)))]
    partner = {(1, 1): (0, 0), (0, 0): (1, 1), (0, 1): (4, 0), (4, 0): (0, 1)}
    return edges, partner


def test_the_count_vote_is_evidence_in_the_pairing_search():
    counts = {}
    for name, prior in (("none", None), ("two", [0.01, 0.97, 0.01, 0.005, 0.005]),
                        ("three", [0.0, 0.0, 1.0, 0.0, 0.0])):
        edges, partner = _shared_segment_graph()
        partner, tips = _fewest_curves(edges, partner, set(), set(), 2, (0.5, 0.5), 2.0, 1.0, 120.0,
                                       None if prior is None else np.array(prior))
        counts[name] = len(_chains(edges, partner, tips, 2, (0.5, 0.5)))
    # A vote for 3 curves outweighs the shorter description of 2; a vote for 2 agrees with it.
    assert counts == {"none": 2, "two": 2, "three": 3}


def test_drawings_the_classical_path_miscounts_are_counted_right():
    # Development drawings (seeds 300000 + i, outside the benchmark's) that the classical
    # path reads as 1, 3, 2 curves instead of 2, 2, 3 and the vote, as evidence in the
    # pairing search, fixes; two where the network's curves regroup the classical ones
    # (3 and 4 classical curves instead of 2 and 3; with the twelfth session's vote, 2 + 11
    # of the earlier pair stays at the classical path's 1), and one where they cannot (a
    # network curve with no classical curve along it) and are returned themselves. A
    # regression test of the measured change.
    for n, i in ((2, 12), (2, 42), (3, 8)):
        sample = make_sample(300_000 + i, SyntheticConfig(curves=(n, n), width=(1.0, 2.0, 3.0)[i % 3]))
        assert len(extract(sample.image, method="classic")[0]) != n, (n, i)
    assert_counted_right(300_000, ((2, 12), (2, 42), (3, 8)), method="hybrid", chosen="classic")
    for n, i, classic in ((2, 49, 3), (3, 43, 4), (3, 44, 4)):
        sample = make_sample(300_000 + i, SyntheticConfig(curves=(n, n), width=(1.0, 2.0, 3.0)[i % 3]))
        assert len(extract(sample.image, method="classic")[0]) == classic, (n, i)
    assert_counted_right(300_000, ((2, 49), (3, 43)), method="hybrid", chosen="regrouped", chamfer_px=0.6)
    assert_counted_right(300_000, ((3, 44),), method="hybrid", chosen="network", chamfer_px=3.0)


def _halves(curve):
    # Two curves fitted to the two halves of ``curve``'s points: the classical path's
    # reading of a curve it split.
    from nurbskit.curves.classic import fit_stroke
    from nurbskit.curves.synthetic import dense_samples

    pts = dense_samples(curve, 1.0)
    mid = len(pts) // 2
    return [fit_stroke(pts[: mid + 1], 0.25, measure=False)[0], fit_stroke(pts[mid:], 0.25, measure=False)[0]]


def test_regrouped_joins_the_pieces_each_guide_runs_along():
    from nurbskit.core import NURBSCurve
    from nurbskit.curves.classic import regrouped
    from nurbskit.curves.synthetic import dense_samples

    truth = make_sample(300_007, SyntheticConfig(curves=(2, 2), width=2.0)).curves()
    a0, a1 = _halves(truth[0])
    b0, b1 = _halves(truth[1])
    # Guides a few pixels off (as the network's curves are), in the other direction for
    # the second; the pieces shuffled, one of them reversed.
    guides = [NURBSCurve(truth[0].control_points + 2.0, degree=3),
              NURBSCurve(truth[1].control_points.flip(0) - 1.5, degree=3)]
    b1 = NURBSCurve(b1.control_points.flip(0), degree=3)
    joined = regrouped([b1, a0, b0, a1], guides, tolerance=0.5)
    assert joined is not None and len(joined) == 2
    for got, want in zip(joined, truth):
        pts = dense_samples(got)
        assert chamfer_points(pts, dense_samples(want))["symmetric"] < 0.25
        assert pts[0, 0] <= pts[-1, 0]  # the canonical orientation
    # A guide with no piece along it: no regrouping.
    assert regrouped([a0, a1], guides, tolerance=0.5) is None
    # One piece per guide: the pieces themselves.
    one = regrouped([a0, b1], guides, tolerance=0.5)
    assert one[0] is a0 and one[1] is b1


def test_a_large_drawing_split_by_the_classical_path_is_regrouped():
    # 512 px: the classical path reads 4 curves for 3; the vote (3, surely), the search
    # rerun with it (still 4), then the network's curves regroup the pieces. The curves
    # keep the classical path's precision (the network's own lie pixels off at this size).
    sample = make_sample(300_056, SyntheticConfig(size=(512, 512), curves=(3, 3), width=1.0))
    assert len(extract(sample.image, method="classic")[0]) == 4
    curves, found = extract(sample.image)
    assert found.chosen == "regrouped" and len(curves) == 3
    got = np.concatenate([dense_samples(c) for c in curves])
    truth = np.concatenate([dense_samples(c) for c in sample.curves()])
    assert chamfer_points(got, truth)["symmetric"] < 0.5


def test_a_large_drawing_reruns_the_search_with_the_vote():
    # 512 px: the search does not run by default; the vote disagrees with the classical
    # count (4 curves for 3), and the search run with it as evidence finds 3.
    sample = make_sample(300_003, SyntheticConfig(size=(512, 512), curves=(3, 3), width=1.0))
    assert len(extract(sample.image, method="classic")[0]) == 4
    assert_counted_right(300_000, ((3, 3),), size=512, method="hybrid", chosen="classic")


def test_a_sketch_of_many_strokes_keeps_the_classical_count():
    # One long stroke crossed by five others: six curves, more than the networks know (1-3).
    lines = [np.array([[8.0, 64.0], [120.0, 64.0]])]
    lines += [np.array([[x, 20.0], [x + 6.0, 108.0]]) for x in (20.0, 40.0, 60.0, 80.0, 100.0)]
    dense = [np.stack([np.linspace(a[0], b[0], 400), np.linspace(a[1], b[1], 400)], axis=1) for a, b in lines]
    image = 1.0 - render(dense, (128, 128), 2.0)
    classic, _ = extract(image, method="classic")
    hybrid, found = extract(image)
    assert len(classic) == len(hybrid) == 6 and found.chosen == "classic"


def test_the_cli_default_is_the_hybrid_method(tmp_path):
    from PIL import Image

    from nurbskit.cli import main

    s = make_sample(300_012, SyntheticConfig(curves=(2, 2), width=1.0))
    src = tmp_path / "two.png"
    Image.fromarray((s.image * 255).astype(np.uint8)).save(src)
    assert main(["curves", str(src), "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["method"] == "hybrid" and report["curves"] == 2


def test_without_the_shipped_weights_the_default_is_the_classical_path(monkeypatch):
    from nurbskit.curves.nets import predict
    from nurbskit.errors import InputError

    def missing(mode, input="image"):
        raise InputError("no shipped weights called 'curves_mv_redrawn'")

    s = make_sample(300_012, SyntheticConfig(curves=(2, 2), width=1.0))
    classic, _ = extract(s.image, method="classic")
    monkeypatch.setattr(predict, "load_model", missing)
    curves, found = extract(s.image)
    assert found.chosen == "classic" and len(curves) == len(classic) == 1


def test_strokes_thicker_than_the_networks_know_get_the_classical_reading(monkeypatch):
    # Strokes 14 px wide in a 128 px drawing (the networks trained on 1 to 3 px): over
    # HYBRID_MAX_WIDTH of the ink's extent, so the hybrid returns the classical path's
    # curves, and the vote is not even read (the width is known before it). On these two
    # drawings the vote would change the count (checked with the guard lifted), so the
    # test fails if the guard goes.
    from nurbskit.curves import api
    from nurbskit.curves.nets import predict

    votes = []
    read = predict.count_probabilities
    monkeypatch.setattr(predict, "count_probabilities", lambda *a, **k: votes.append(1) or read(*a, **k))
    for i in (2, 25):
        sample = make_sample(400_000 + i, SyntheticConfig(curves=(1, 1), width=14.0))
        classic, _ = extract(sample.image, method="classic")
        hybrid, found = extract(sample.image, method="hybrid")
        assert not api.thin_enough(found.strokes.width, found.strokes.ink)
        assert not votes
        assert found.chosen == "classic" and len(hybrid) == len(classic)
        for a, b in zip(hybrid, classic):
            np.testing.assert_allclose(a.control_points.numpy(), b.control_points.numpy(), rtol=0, atol=0)
