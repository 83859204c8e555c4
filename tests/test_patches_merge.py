"""Merging: one cylinder's two halves become one (closed) patch; two perpendicular planes stay two."""

import numpy as np
import pytest

from nurbskit.patches import PatchConfig, fit_patches
from nurbskit.patches.energy import Contribution, energy
from nurbskit.patches.refit import bend_radii, fit_patch
from nurbskit.patches.config import PatchConfig as Cfg


def _cylinder(n, rng, r=0.3, h=1.0):
    t, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, h, n)
    return np.c_[r * np.cos(t), r * np.sin(t), z], t


def test_two_half_cylinders_merge_into_one_closed_patch():
    rng = np.random.default_rng(0)
    p, t = _cylinder(1500, rng)
    halves = (t < np.pi).astype(np.int64)
    res = fit_patches(p, config=PatchConfig(final_iters=0), init_labels=halves)
    assert len(res) == 1
    assert res.patches[0].closed
    assert sorted(res.patches[0].regions) == [0, 1]
    assert res.metrics["completeness"] > 99.0
    assert res.history[0]["accepted"] and res.energy[1] < res.energy[0]


def test_two_perpendicular_planes_do_not_merge():
    rng = np.random.default_rng(1)
    a = rng.random((800, 2))
    p = np.vstack([np.c_[a[:400, 0], a[:400, 1], np.zeros(400)], np.c_[np.zeros(400), a[400:, 1], a[400:, 0]]])
    labels = np.repeat([0, 1], 400)
    res = fit_patches(p, config=PatchConfig(final_iters=0), init_labels=labels)
    assert len(res) == 2
    assert res.history and not any(h["accepted"] for h in res.history)
    for patch in res.patches:  # each plane keeps its own points
        assert len(np.unique(labels[patch.inliers])) == 1


def test_bend_radius_of_a_cylinder_patch_is_its_radius():
    rng = np.random.default_rng(2)
    p, t = _cylinder(1200, rng, r=0.3)
    half = p[t < np.pi]
    pf = fit_patch(half, 0.01, Cfg(fit_points=800, fit_rounds=15))  # a converged fit (candidates use fewer rounds)
    r = bend_radii(pf.surface, pf.params[pf.distance < 0.005])
    assert abs(np.median(r) - 0.3) < 0.02


def test_energy_by_hand():
    # 3 patches of 10 initial, 80 of 100 points inliers, mean inlier distance 0.25 eps
    u, parts = energy(Contribution(80, 20.0), 3, 10, 100, (0.3, 0.4, 0.3))
    assert abs(u - (0.3 * 0.25 + 0.4 * 0.3 + 0.3 * 0.2)) < 1e-12
    assert parts == {"fidelity": 0.25, "simplicity": 0.3, "completeness": 0.8}


def test_points_across_the_seam_of_a_closed_patch_find_their_foot_point():
    import torch

    from nurbskit.fit.params import new_surface
    from nurbskit.patches.refit import point_distances

    rng = np.random.default_rng(3)
    cp = torch.as_tensor(rng.normal(size=(5, 7, 3)))
    cp = torch.cat([cp, cp[:, :3]], dim=1)  # closed in v: 10 columns, 7 distinct
    s = new_surface(cp, (3, 3), closed_v=True)
    near = s.evaluate(torch.tensor([[0.5, 0.995], [0.3, 0.004]], dtype=torch.float64)).numpy()
    _, d = point_distances(s, near, closed_v=True)
    assert d.max() < 1e-8


def _can(n, rng, noise):
    """A cylinder (radius 0.5, height 1) with both caps, area-uniform, Gaussian noise ``noise`` x diagonal."""
    r, h = 0.5, 1.0
    side = rng.random(n) < (2 * np.pi * r * h) / (2 * np.pi * r * h + 2 * np.pi * r * r)
    t, z, rr = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, h, n), r * np.sqrt(rng.random(n))
    cap = np.where(rng.random(n) < 0.5, 0.0, h)
    p = np.where(side[:, None], np.c_[r * np.cos(t), r * np.sin(t), z], np.c_[rr * np.cos(t), rr * np.sin(t), cap])
    diag = np.sqrt(2 * (2 * r) ** 2 + h * h)
    return p + rng.normal(0, noise * diag / np.sqrt(3), p.shape), diag


@pytest.mark.slow
def test_a_cylinder_with_caps_is_three_patches_and_covers_its_input():
    """The issue's clean CAD case, smaller (3,000 points, 0.1 % noise): a closed side and two flat caps."""
    rng = np.random.default_rng(0)
    p, diag = _can(3000, rng, 0.001)
    res = fit_patches(p, config=PatchConfig(final_iters=0))
    m = res.metrics
    assert m["N"] == 3  # no more patches than smooth faces: the side is one closed patch
    assert sum(patch.closed for patch in res.patches) == 1
    assert m["P_cov_i"] >= 99.9  # input within eps of the trimmed output
    assert m["input_to_output_mean"] <= 0.0012  # fraction of the diagonal
    # the crease test keeps each cap off the side: a cap's inliers span at most the cap
    # plane's eps band plus the side's rim points within eps of it (a merge would span 1)
    for patch in res.patches:
        if not patch.closed:
            assert np.ptp(p[patch.inliers, 2]) < 2 * 0.01 * diag


def test_a_fillet_cut_into_strips_merges_with_its_faces():
    """Two perpendicular faces joined by a fillet of radius 2.3 eps, given as four planar regions.

    The merged patch bends tighter than ``min_radius`` on the fillet, but it follows its
    strips' normals and the parts meet at shallow seams, so the crease test lets it merge
    (the previous rule, a tight bend alone, kept every strip apart).
    """
    rng = np.random.default_rng(3)
    r = 0.04
    a = rng.random((1500, 2)) * [1 - r, 1]
    b = rng.random((1500, 2)) * [1 - r, 1]
    t, y = rng.uniform(0, np.pi / 2, 600), rng.random(600)
    p = np.vstack([np.c_[r + a[:, 0], a[:, 1], np.zeros(1500)],
                   np.c_[np.zeros(1500), b[:, 1], r + b[:, 0]],
                   np.c_[r - r * np.sin(t), y, r - r * np.cos(t)]])
    labels = np.r_[np.zeros(1500), np.ones(1500), np.where(t < np.pi / 4, 2, 3)].astype(np.int64)
    res = fit_patches(p, config=PatchConfig(final_iters=0), init_labels=labels)
    merged = [h for h in res.history if h["accepted"]]
    assert merged and len(res) < 4
    # a strip of the fillet now shares a patch with a face
    assert any(set(patch.regions) & {2, 3} and set(patch.regions) & {0, 1} for patch in res.patches)
    assert res.metrics["P_cov_i"] > 99


def _two_faces_and_a_strip():
    """Two perpendicular unit faces (600 points each, labels 0 and 1) and a 24-point strip
    along their edge (label 2), half on each face's plane: ``(points (1224, 3), labels)``."""
    rng = np.random.default_rng(4)
    a, b, c = rng.random((600, 2)), rng.random((600, 2)), rng.random((24, 2))
    p = np.vstack([np.c_[0.01 + 0.99 * a[:, 0], a[:, 1], np.zeros(600)],
                   np.c_[np.zeros(600), b[:, 1], 0.01 + 0.99 * b[:, 0]],
                   np.where(np.arange(24)[:, None] < 12, np.c_[0.01 * c[:, 0], c[:, 1], np.zeros(24)],
                            np.c_[np.zeros(24), c[:, 1], 0.01 * c[:, 0]])])
    return p, np.r_[np.zeros(600), np.ones(600), np.full(24, 2)].astype(np.int64)


def test_a_leftover_strip_at_an_edge_is_absorbed_by_its_neighbours():
    """Two perpendicular faces and a 24-point strip along their edge, a region of its own.

    No merge is allowed (``crease_seam`` of 10 degrees: the strip's plane meets both faces
    at 45 degrees; ``leftover=0``: a small part crosses no seam), so without absorption the strip stays a third patch; its points lie
    within eps of both faces' surfaces, so dissolving it lowers the energy and keeps them
    inliers.
    """
    p, labels = _two_faces_and_a_strip()
    kept = fit_patches(p, config=PatchConfig(final_iters=0, crease_seam=10, leftover=0, absorb=0), init_labels=labels)
    res = fit_patches(p, config=PatchConfig(final_iters=0, crease_seam=10, leftover=0), init_labels=labels)
    assert len(kept) == 3 and len(res) == 2
    absorbed = [h for h in res.history if h.get("reason") == "absorb" and h["accepted"]]
    assert len(absorbed) == 1 and absorbed[0]["a"] == 2 and absorbed[0]["held"] == 24
    assert absorbed[0]["energy_after"] < absorbed[0]["energy_before"]
    assert res.metrics["completeness"] == 100.0
    for patch in res.patches:  # each face keeps its own points and gains part of the strip
        assert set(labels[patch.inliers]) in ({0, 2}, {1, 2})


def test_a_candidate_fit_reports_true_distances():
    """fit_patch's distances (its union projected warm from the fitted subset's foot points)
    match a cold projection from the grid (the core's search), point by point."""
    from nurbskit.patches.refit import point_distances

    rng = np.random.default_rng(5)
    xy = rng.random((2000, 2))
    p = np.c_[xy, 0.15 * np.sin(4 * xy[:, 0]) * xy[:, 1]]
    pf = fit_patch(p, 0.01, Cfg(fit_points=400))
    _, cold = point_distances(pf.surface, p)
    assert pf.distance.shape == (2000,)
    assert np.max(np.abs(pf.distance - cold)) < 1e-6
    assert np.mean(pf.distance < 0.01) > 0.95  # and the fit is a fit


def test_a_refused_crease_is_inherited_by_every_pair_holding_its_sides():
    """contains_refused against a brute-force reading of its rule on random region sets."""
    from nurbskit.patches.driver import contains_refused

    rng = np.random.default_rng(6)
    refused = [(frozenset({0, 1}), frozenset({2})), (frozenset({3}), frozenset({4, 5}))]
    assert contains_refused([0, 1, 7], [2, 9], refused)
    assert contains_refused([2], [0, 1], refused)  # either order
    assert not contains_refused([0], [2], refused)  # a smaller side: not the refused union
    assert not contains_refused([0, 1, 2], [9], refused)  # both sides in one part: no seam between them
    for _ in range(200):
        regions = rng.permutation(10)
        k = rng.integers(1, 9)
        a, b = list(regions[:k]), list(regions[k:])
        brute = any(all(r in a for r in s) and all(r in b for r in t) or all(r in b for r in s) and all(r in a for r in t)
                    for s, t in refused)
        assert contains_refused(a, b, refused) == brute


def test_a_small_leftover_crosses_a_steep_seam_but_two_faces_do_not():
    """The leftover strip of the absorption case (24 of 1,224 points, at 45 degrees to both
    faces) merges into a face across the 10-degree seam limit (the energy decides a
    leftover's merge); the two faces (600 points each) still never merge."""
    p, labels = _two_faces_and_a_strip()
    res = fit_patches(p, config=PatchConfig(final_iters=0, crease_seam=10, absorb=0), init_labels=labels)
    merged = [h for h in res.history if h["accepted"]]
    assert len(merged) == 1 and 2 in (merged[0]["a"], merged[0]["b"]) and merged[0]["seam_angle"] > 10
    assert len(res) == 2
    for patch in res.patches:  # no patch holds both faces
        assert not {0, 1} <= set(labels[patch.inliers])
    assert res.metrics["completeness"] > 99


def _wavy(n, seed):
    xy = np.random.default_rng(seed).random((n, 2))
    return np.c_[xy, 0.12 * np.sin(6 * xy[:, 0]) * np.cos(5 * xy[:, 1])]


def test_point_distances_equal_the_cores_default_projection():
    """point_distances stops Newton earlier (FOOT_TOL, checked every iteration) than the
    core's default (eps ** 0.75, every 4): the distances agree to rounding, cold and warm."""
    import torch

    from nurbskit.core.project import project_points
    from nurbskit.patches.refit import point_distances

    p = _wavy(1500, 7)
    pf = fit_patch(p, 0.01, Cfg(fit_points=400))
    x = torch.as_tensor(p + 0.02 * np.random.default_rng(8).standard_normal(p.shape))
    ref = project_points(pf.surface, x, periodic=(False, False)).distance.numpy()
    _, cold = point_distances(pf.surface, x.numpy())
    _, warm = point_distances(pf.surface, x.numpy(), start=pf.params)
    assert np.max(np.abs(cold - ref)) < 1e-12
    assert np.max(np.abs(warm - ref)) < 1e-9  # warm may settle in the same minimum from another side


def test_a_grown_grid_is_solved_at_the_last_grids_feet_without_a_grid_search(monkeypatch):
    """A candidate whose 4 x 4 fit is not enough grows its grid from the last grid's foot
    points: the larger fit's alternation never starts from the grid (fit.alternate warm
    first round), and it fits as well as a fit of that grid from scratch."""
    import nurbskit.fit.lstsq as lstsq
    from nurbskit.patches.refit import _fit_lsq

    p = _wavy(400, 9)
    cfg = Cfg(fit_points=400)
    calls = []
    real = lstsq.project_points

    def spy(surface, points, **kw):
        calls.append((surface.sizes, kw.get("params") is not None))
        return real(surface, points, **kw)

    monkeypatch.setattr(lstsq, "project_points", spy)
    pf = fit_patch(p, 0.01, cfg)
    assert pf.fits > 1 and pf.ctrl[0] > 4
    grown = [warm for sizes, warm in calls if sizes[0] > 4]
    assert grown and all(grown)  # every projection of a grown grid started warm
    assert not calls[0][1]  # the first grid's first projection searched the grid
    monkeypatch.undo()
    # as good as a fit of the same grid from the plane parametrisation (mean squared distance)
    _, _, _, scratch = _fit_lsq(p, pf.ctrl, False, cfg)
    first = _fit_lsq(p, (4, 4), False, cfg)
    _, _, _, warm = _fit_lsq(p, pf.ctrl, False, cfg, warm=first[2])
    assert np.mean(warm**2) <= 1.2 * np.mean(scratch**2)
    assert np.mean(warm < 0.005) > 0.95
