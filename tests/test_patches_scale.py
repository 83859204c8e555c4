"""Large clouds: merges on a subset, every point assigned by projection; work that cannot fit is refused."""

import numpy as np
import pytest

from nurbskit.errors import OptionError
from nurbskit.patches import PatchConfig, fit_patches
from nurbskit.patches.driver import check_patch_memory, patch_memory
from nurbskit.patches.refit import point_distances

from _assert import assert_close


def test_a_subsampled_run_labels_every_input_point():
    rng = np.random.default_rng(0)
    xy = rng.random((3000, 2))
    p = np.c_[xy, 0.05 * xy[:, 0] ** 2]
    res = fit_patches(p, config=PatchConfig(max_points=500, final_iters=0))
    assert res.counts["merged_points"] == 500
    assert res.labels.shape == (3000,) and res.normals.shape == (3000, 3) and res.planar_labels.shape == (3000,)
    assert len(res) == 1
    patch = res.patches[0]
    # every point (not only the 500 merged ones) is an inlier with its true distance
    assert len(patch.inliers) > 0.99 * 3000 and np.all(patch.distance < res.eps)
    assert res.metrics["completeness"] > 99
    # the distances are true point-to-surface distances of the input points (not of their
    # nearest merged point): the same as projecting them again
    _, d = point_distances(patch.surface, p[patch.inliers])
    assert_close(patch.distance, d, atol=1e-9, rtol=0)


def test_the_same_cloud_without_subsampling_gives_the_same_patch_count():
    rng = np.random.default_rng(0)
    xy = rng.random((1200, 2))
    p = np.c_[xy, 0.05 * xy[:, 0] ** 2]
    full = fit_patches(p, config=PatchConfig(max_points=0, final_iters=0))
    sub = fit_patches(p, config=PatchConfig(max_points=400, final_iters=0))
    assert len(full) == len(sub) == 1
    assert abs(full.metrics["completeness"] - sub.metrics["completeness"]) < 1.0


def test_memory_estimate_grows_with_the_points_and_refuses_in_one_line():
    assert patch_memory(2_000_000) > patch_memory(1_000_000) > 0
    with pytest.raises(OptionError) as info:
        check_patch_memory(1_000_000, "scan.ply", budget=patch_memory(1_000_000) / 2)
    text = str(info.value)
    assert "scan.ply" in text and "1,000,000 points" in text and "GB" in text and "\n" not in text
    check_patch_memory(1_000_000, "scan.ply", budget=patch_memory(1_000_000) * 2)  # fits: no error


def test_max_points_is_validated():
    with pytest.raises(OptionError, match="max_points"):
        PatchConfig(max_points=-1).validate()
