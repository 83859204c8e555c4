"""The metrics against hand-computed values on tiny cases."""

import numpy as np

from nurbskit.patches.metrics import patch_metrics, segmentation_iou


def test_segmentation_iou_by_hand():
    truth = np.array([0, 0, 0, 1, 1, 2])
    pred = np.array([5, 5, 7, 7, 7, -1])
    # best matching: 5 <-> 0 (IoU 2/3), 7 <-> 1 (IoU 2/3), segment 2 unmatched (0)
    assert abs(segmentation_iou(pred, truth) - (2 / 3 + 2 / 3 + 0) / 3) < 1e-12
    assert segmentation_iou(truth, truth) == 1.0
    assert segmentation_iou(np.full(6, -1), truth) == 0.0


def test_patch_metrics_by_hand():
    # the output: the unit square z = 0, as two triangles; the input: a dense grid on its
    # left half (x <= 0.5), plus two points 0.5 above it (outliers, not covered)
    square = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    g = np.linspace(0, 1, 101)
    xs, ys = np.meshgrid(g[g <= 0.5 + 1e-12], g)
    on = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    off = np.array([[0.25, 0.5, 0.5], [0.3, 0.5, 0.5]])
    points = np.vstack([on, off])
    n = len(points)
    labels = np.r_[np.zeros(len(on), int), [-1, -1]]
    dist = np.r_[np.full(len(on), 0.002), [0.0, 0.0]]
    diag = np.linalg.norm(points.max(0) - points.min(0))  # sqrt(1 + 1 + 0.25) = 1.5
    eps = 0.01 * diag
    m = patch_metrics(points, labels, dist, [square], eps, truth=np.r_[np.zeros(len(on), int), [1, 1]])
    assert m["N"] == 1
    assert abs(m["completeness"] - 100 * len(on) / n) < 1e-9
    assert abs(m["E_fid"] - 100 * 0.002 / eps) < 1e-9
    assert abs(m["P_cov_i"] - 100 * len(on) / n) < 1e-9
    # half of the square lies within eps of the input: its left half plus a band eps wide
    expected_o = 100 * (0.5 + eps)
    assert abs(m["P_cov_o"] - expected_o) < 1.5  # sampling error of ~1e5 uniform samples
    assert abs(m["iou"] - 100 * 0.5) < 1e-9  # segment 0 matched exactly, segment 1 missed
