"""Least squares, foot points, the alternation, the trainable parametrisation and matching."""

from __future__ import annotations

import itertools

import pytest
import torch
from _assert import assert_close

from nurbskit.core import NURBSSurface
from nurbskit.fit.lstsq import alternate, solve_control_points
from nurbskit.fit.matching import matching_cost, one_to_one_matching, one_to_one_matching_naive
from nurbskit.fit.params import SurfaceParameters, Topology, expand, new_surface, periodic_knots

F64 = torch.float64


def _gen(seed=0):
    return torch.Generator().manual_seed(seed)


def _random_surface(n_u=6, n_v=5, rational=False, seed=0):
    g = _gen(seed)
    cp = torch.rand(n_u, n_v, 3, generator=g, dtype=F64)
    w = 0.5 + torch.rand(n_u, n_v, generator=g, dtype=F64) if rational else None
    return NURBSSurface(cp, (3, 2), weights=w)


@pytest.mark.parametrize("rational", [False, True])
def test_least_squares_reproduces_a_surface_of_the_same_space(rational):
    s = _random_surface(rational=rational)
    uv = torch.rand(300, 2, generator=_gen(1), dtype=F64)
    P = solve_control_points(uv, s.evaluate(uv), s.knot_vectors, s.degrees, s.sizes, s.weights)
    assert_close(P, s.control_points, atol=1e-9)


def test_least_squares_keeps_a_closed_seam_and_poles():
    topo = Topology(closed_v=True, pole_start=True, pole_end=True)
    n_u, n_v, q = 6, 8, 3
    index, k = topo.index(n_u, n_v, q)
    free = torch.rand(k, 3, generator=_gen(2), dtype=F64)
    cp = expand(free, index, n_u, n_v)
    s = new_surface(cp, (3, q), closed_v=True)
    uv = torch.rand(400, 2, generator=_gen(3), dtype=F64)
    P = solve_control_points(uv, s.evaluate(uv), s.knot_vectors, s.degrees, s.sizes, None, topo)
    assert_close(P, cp, atol=1e-9)
    assert torch.equal(P[:, :q], P[:, n_v - q:])  # seam closed
    assert torch.equal(P[0], P[0, :1].expand_as(P[0]))  # pole row
    # The closed surface meets itself at v = 0 and v = 1.
    u = torch.linspace(0, 1, 7, dtype=F64)
    a = s.evaluate(torch.stack([u, torch.zeros_like(u)], -1))
    b = s.evaluate(torch.stack([u, torch.ones_like(u)], -1))
    assert_close(a, b, atol=1e-12)


def test_periodic_knots_domain_is_unit():
    k = periodic_knots(9, 3, dtype=F64)
    assert k.numel() == 13 and float(k[3]) == 0.0 and float(k[9]) == 1.0


def test_smoothness_trades_fit_for_a_smoother_net():
    s = _random_surface(8, 8)
    uv = torch.rand(200, 2, generator=_gen(4), dtype=F64)
    x = s.evaluate(uv) + 0.05 * torch.randn(200, 3, generator=_gen(5), dtype=F64)

    def rough(P):
        return float((P[2:] - 2 * P[1:-1] + P[:-2]).square().sum() + (P[:, 2:] - 2 * P[:, 1:-1] + P[:, :-2]).square().sum())

    P0 = solve_control_points(uv, x, s.knot_vectors, s.degrees, s.sizes, smoothness=0.0)
    P1 = solve_control_points(uv, x, s.knot_vectors, s.degrees, s.sizes, smoothness=1e-1)
    r0 = (s._replace(control_points=P0).evaluate(uv) - x).square().sum()
    r1 = (s._replace(control_points=P1).evaluate(uv) - x).square().sum()
    assert rough(P1) < 0.5 * rough(P0)
    assert r1 >= r0


def _gentle_surface(n=5, seed=6):
    """A gently curved patch: a plane with random heights of 0.2."""
    g = torch.linspace(0, 1, n, dtype=F64)
    u, v = torch.meshgrid(g, g, indexing="ij")
    z = 0.2 * torch.rand(n, n, generator=_gen(seed), dtype=F64)
    return NURBSSurface(torch.stack([u, v, z], -1), (3, 3))


def test_alternation_foot_points_are_the_projection():
    # The alternation has no foot-point solver of its own: its parameters are those of
    # core.project (true closest points, no worse than a dense search).
    s = _gentle_surface()
    uv = torch.rand(40, 2, generator=_gen(7), dtype=F64)
    x = s.evaluate(uv) + 0.01 * s.normals(uv)
    fitted, found, _ = alternate(s, x, rounds=1, smoothness=0.0)
    d_found = (fitted.evaluate(found) - x).norm(dim=-1)
    dense = fitted.sample((400, 400)).reshape(-1, 3)
    d_dense = torch.cdist(x, dense).min(dim=1).values
    assert torch.all(d_found <= d_dense + 1e-12)
    import nurbskit.fit.lstsq as lstsq

    assert not hasattr(lstsq, "foot_points")


def test_alternation_on_a_closed_surface_crosses_the_seam():
    # A closed-v surface (periodic knots, wrapped columns): points on both sides of the
    # seam are fitted exactly; a clamped projection would hold them on the seam column.
    n_u, q, m = 4, 3, 8
    t = torch.linspace(0, 1, n_u, dtype=F64)
    ang = torch.arange(m, dtype=F64) * 2 * torch.pi / m
    free = torch.stack([torch.cos(ang)[None].expand(n_u, m), torch.sin(ang)[None].expand(n_u, m),
                        t[:, None].expand(n_u, m)], -1)
    truth = new_surface(torch.cat([free, free[:, :q]], 1), (3, q), True)
    uv = torch.rand(800, 2, generator=_gen(21), dtype=F64)
    x = truth.evaluate(uv)
    start = truth._replace(control_points=truth.control_points * 1.05)
    fitted, params, history = alternate(start, x, rounds=20, topology=Topology(closed_v=True), smoothness=0.0,
                                        tolerance=0.0)
    assert history[-1] < 1e-6 * history[0]
    assert float((fitted.evaluate(params) - x).square().sum(-1).mean()) < 1e-12


def test_alternation_recovers_parameters_of_a_surface():
    s = _gentle_surface(5, seed=8)
    uv = torch.rand(600, 2, generator=_gen(9), dtype=F64)
    x = s.evaluate(uv)
    start = s._replace(control_points=s.control_points + 0.02 * torch.randn(5, 5, 3, generator=_gen(10), dtype=F64))
    fitted, params, history = alternate(start, x, rounds=30, smoothness=0.0, tolerance=0.0)
    # Parameter correction converges linearly (points slide along the surface), so the
    # check is a large reduction, not exactness.
    assert all(b <= a * (1 + 1e-9) for a, b in zip(history, history[1:]))
    assert history[-1] < 1e-3 * history[0]
    assert float((fitted.evaluate(params) - x).square().sum(-1).mean()) < 1e-7


def test_surface_parameters_keep_ties_and_orders_under_any_update():
    n_u, n_v, q = 6, 8, 3
    topo = Topology(closed_v=True, pole_start=True)
    index, k = topo.index(n_u, n_v, q)
    cp = expand(torch.rand(k, 3, generator=_gen(11), dtype=F64), index, n_u, n_v)
    params = SurfaceParameters(new_surface(cp, (3, q), True), topo, train_weights=True, train_knots=True)
    with torch.no_grad():
        for t in params.trainable():
            t.add_(torch.randn(t.shape, generator=_gen(12), dtype=F64))
    s = params()
    assert torch.equal(s.control_points[:, :q], s.control_points[:, n_v - q:])
    assert torch.equal(s.control_points[0], s.control_points[0, :1].expand(n_v, 3))
    assert (s.weights > 0).all()
    ku = s.knot_vectors[0].detach()
    assert (ku[1:] >= ku[:-1]).all() and float(ku[0]) == 0.0 and float(ku[-1]) == 1.0
    assert torch.equal(s.knot_vectors[1], periodic_knots(n_v, q, dtype=F64))  # closed v: uniform


def test_gradients_reach_control_points_weights_and_knots():
    s = _random_surface(5, 5, rational=True, seed=13)
    params = SurfaceParameters(s, train_weights=True, train_knots=True)
    u = torch.linspace(0, 1, 9, dtype=F64)
    target = torch.rand(9, 9, 3, generator=_gen(14), dtype=F64)

    def loss():
        return (params().evaluate_grid(u, u) - target).square().sum()

    value = loss()
    value.backward()
    eps = 1e-6
    for t in params.trainable():
        assert t.grad is not None and t.grad.abs().sum() > 0
        i = (0,) * t.ndim if t.ndim else ()
        flat = t.detach().reshape(-1)
        j = int(torch.argmax(t.grad.abs()))
        with torch.no_grad():
            flat_view = t.view(-1)
            flat_view[j] += eps
            up = loss()
            flat_view[j] -= 2 * eps
            down = loss()
            flat_view[j] += eps
        fd = (up - down) / (2 * eps)
        assert abs(float(fd) - float(t.grad.reshape(-1)[j])) < 1e-5 * max(1.0, abs(float(fd)))
        del i, flat


@pytest.mark.parametrize("seed", range(6))
def test_matching_equals_brute_force(seed):
    g = _gen(seed)
    m, n = [(3, 3), (4, 4), (3, 5), (5, 5), (2, 6), (4, 6)][seed]
    pred = torch.rand(m, 3, generator=g, dtype=F64)
    target = torch.rand(n, 3, generator=g, dtype=F64)
    fast = one_to_one_matching(pred, target)
    slow = one_to_one_matching_naive(pred, target)
    assert len(set(fast.tolist())) == m
    assert matching_cost(pred, target, fast) == pytest.approx(matching_cost(pred, target, slow), abs=1e-12)


def test_matching_of_a_permutation_finds_it():
    pred = torch.rand(30, 3, generator=_gen(20), dtype=F64)
    perm = torch.randperm(30, generator=_gen(21))
    index = one_to_one_matching(pred, pred[perm])
    assert torch.equal(perm[index], torch.arange(30))


def test_matching_refuses_fewer_inputs_than_samples():
    from nurbskit.errors import NurbskitError

    with pytest.raises(NurbskitError, match="at least as many input points"):
        one_to_one_matching(torch.rand(5, 3), torch.rand(4, 3))


def test_matching_naive_is_exhaustive():
    # The oracle itself: on 3 x 3 it must see all 6 permutations' minimum.
    pred = torch.tensor([[0.0], [1.0], [2.0]], dtype=F64)
    target = torch.tensor([[2.1], [0.1], [1.1]], dtype=F64)
    best = min(sum((float(pred[i]) - float(target[j])) ** 2 for i, j in enumerate(p)) for p in itertools.permutations(range(3)))
    idx = one_to_one_matching_naive(pred, target)
    assert matching_cost(pred, target, idx) == pytest.approx(best)


def test_equidistributed_knots_follow_the_bending():
    from nurbskit.fit.lstsq import equidistributed_knots

    t = torch.linspace(0, 1, 64, dtype=F64)
    u, v = torch.meshgrid(t, t, indexing="ij")
    # Bends only near u = 1 (exp), and not at all along v (linear).
    g = torch.stack([u, v, torch.exp(6 * u) / 400], -1)
    ku = equidistributed_knots(g, 0, 10, 3)
    kv = equidistributed_knots(g, 1, 10, 3)
    assert ku.numel() == 14 and torch.all(ku[1:] >= ku[:-1])
    assert torch.equal(ku[:4], torch.zeros(4, dtype=F64)) and torch.equal(ku[-4:], torch.ones(4, dtype=F64))
    inner_u, inner_v = ku[4:-4], kv[4:-4]
    assert float(inner_u.mean()) > 0.55  # crowded towards u = 1
    # No bending along v: the floor spreads the knots evenly.
    assert_close(inner_v, torch.linspace(0, 1, 8, dtype=F64)[1:-1], atol=0.02)


def test_a_fit_iteration_after_the_first_reads_nothing_back():
    # The objective of one iteration of the default refine stage (refresh the foot points
    # warm, point-to-surface + coverage + smoothness, backward) under the operation
    # counter: no .item(), no bool(tensor), no nonzero. (torch's L-BFGS reads its own
    # scalars in the line search; that is the optimiser's, not the objective's.)
    from nurbskit._opcount import count_fit_iterations
    from nurbskit.fit.loop import Target
    from nurbskit.fit.pipelines import get_pipeline

    stage = get_pipeline("default").stages[0]
    s = _gentle_surface(6, seed=30)
    x = s.evaluate(torch.rand(500, 2, generator=_gen(31), dtype=F64)) + 0.002 * torch.randn(500, 3, generator=_gen(32), dtype=F64)
    params = SurfaceParameters(s, Topology(), train_weights=True, train_knots=True)
    counts, parts = count_fit_iterations(params, stage, Target(points=x), (24, 24))
    assert counts[0].host_reads > 0  # the first iteration projects from the grid
    for c in counts[1:]:
        assert c.host_reads == 0, c.host_read_names()
    assert set(parts) == {"point_to_surface", "coverage", "smoothness"}


@pytest.mark.parametrize("topology", [Topology(), Topology(closed_v=True), Topology(closed_v=True, pole_start=True, pole_end=True)],
                         ids=["open", "closed", "poles"])
def test_large_nets_solve_sparse_as_the_dense_system_does(topology, monkeypatch):
    # Large systems without gradients on the CPU (lstsq.solves_sparse) are assembled and
    # solved as sparse matrices: the same solution as the dense solve.
    from nurbskit.fit import lstsq

    g = torch.Generator().manual_seed(11)
    n = (33, 32)
    s = NURBSSurface(torch.rand(*n, 3, dtype=torch.float64, generator=g), (3, 3),
                     weights=torch.rand(*n, dtype=torch.float64, generator=g) + 0.5)
    uv = torch.rand(3000, 2, dtype=torch.float64, generator=g)
    X = s.evaluate(uv) + 0.01 * torch.randn(3000, 3, dtype=torch.float64, generator=g)
    args = (uv, X, s.knot_vectors, s.degrees, s.sizes, s.weights, topology, 1e-3)
    assert lstsq.solves_sparse(3000, n[0] * n[1], "cpu") and not lstsq.solves_sparse(300, 64, "cpu")
    with torch.no_grad():
        sparse = lstsq.solve_control_points(*args)
        monkeypatch.setattr(lstsq, "solves_sparse", lambda *_: False)
        dense = lstsq.solve_control_points(*args)
    assert_close(sparse, dense, atol=1e-10 * float(dense.abs().max()))
    # with gradients wanted, the dense (differentiable) solve runs whatever the size
    monkeypatch.setattr(lstsq, "solves_sparse", lambda *_: True)
    cp = lstsq.solve_control_points(uv, X, s.knot_vectors, s.degrees, s.sizes, s.weights.requires_grad_(), topology, 1e-3)
    assert cp.requires_grad
