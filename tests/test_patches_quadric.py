"""Taubin's quadric error: zero on quadrics, additive moments, the merge queue's order."""

import heapq

import numpy as np
import pytest

from _assert import assert_close
from nurbskit.patches.quadric import moments, quadric_error, taubin_error
from nurbskit.patches.queue import MergeQueue


def _sphere(n, rng, r=0.4):
    d = rng.normal(size=(n, 3))
    return r * d / np.linalg.norm(d, axis=1, keepdims=True) + [0.1, -0.05, 0.02]


def _cylinder(n, rng):
    t, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(-0.4, 0.4, n)
    return np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), z]


def _hyperbolic_paraboloid(n, rng):
    xy = rng.uniform(-0.4, 0.4, (n, 2))
    return np.c_[xy, xy[:, 0] ** 2 - xy[:, 1] ** 2]


@pytest.mark.parametrize("make", [_sphere, _cylinder, _hyperbolic_paraboloid])
def test_error_is_zero_on_points_of_a_quadric(make):
    pts = make(400, np.random.default_rng(1))
    assert quadric_error(pts) < 1e-12


def test_error_is_positive_off_quadrics_and_about_the_mean_squared_distance():
    rng = np.random.default_rng(2)
    # a cube's surface is no quadric
    p = rng.uniform(-0.5, 0.5, (3000, 3))
    axis = rng.integers(0, 3, 3000)
    p[np.arange(3000), axis] = np.sign(p[np.arange(3000), axis]) * 0.5
    assert quadric_error(p) > 1e-3
    # noise of std sigma along the normal of a sphere: error ~ sigma^2 (first order)
    sigma = 1e-3
    s = _sphere(5000, rng)
    noisy = s + sigma * rng.normal(size=(5000, 1)) * (s - [0.1, -0.05, 0.02]) / 0.4
    assert 0.5 * sigma**2 < quadric_error(noisy) < 1.5 * sigma**2


def test_moments_are_additive_under_union():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(70, 3))
    ma, na = moments(a)
    mb, nb = moments(b)
    mu, nu = moments(np.vstack([a, b]))
    assert_close(ma + mb, mu, atol=1e-10)
    assert_close(na + nb, nu, atol=1e-10)
    assert_close(taubin_error(ma + mb, na + nb), quadric_error(np.vstack([a, b])), atol=1e-10)
    # two halves of one cylinder: each zero, and their sum zero too
    c = _cylinder(400, rng)
    h1, h2 = c[c[:, 0] > 0], c[c[:, 0] <= 0]
    (m1, n1), (m2, n2) = moments(h1), moments(h2)
    assert taubin_error(m1 + m2, n1 + n2) < 1e-12


def _greedy_with_queue(weights, edges):
    """Merge everything greedily through MergeQueue; priority = sum of the two values."""
    value = dict(enumerate(weights))
    graph = {i: set() for i in value}
    for a, b in edges:
        graph[a].add(b)
        graph[b].add(a)
    q = MergeQueue()
    for a, b in edges:
        q.push(value[a] * value[b] / (value[a] + value[b]), a, b)
    order, nxt = [], len(weights)
    while (item := q.pop()) is not None:
        _, a, b = item
        order.append((a, b))
        value[nxt] = value[a] + value[b]
        nbrs = (graph.pop(a) | graph.pop(b)) - {a, b}
        graph[nxt] = nbrs
        q.retire(a)
        q.retire(b)
        for c in nbrs:
            graph[c] -= {a, b}
            graph[c].add(nxt)
            q.push(value[c] * value[nxt] / (value[c] + value[nxt]), c, nxt)
        nxt += 1
    return order


def _greedy_brute_force(weights, edges):
    """The same greedy merging by scanning every current edge at each step."""
    value = dict(enumerate(weights))
    cur = {tuple(sorted(e)) for e in edges}
    order, nxt = [], len(weights)
    while cur:
        a, b = min(cur, key=lambda e: (value[e[0]] * value[e[1]] / (value[e[0]] + value[e[1]]), e))
        order.append((a, b))
        value[nxt] = value[a] + value[b]
        new = set()
        for e in cur:
            if e == (a, b):
                continue
            e2 = tuple(sorted(nxt if x in (a, b) else x for x in e))
            if e2[0] != e2[1]:
                new.add(e2)
        cur = new
        nxt += 1
    return order


def test_heap_merge_order_equals_a_brute_force_scan():
    rng = np.random.default_rng(4)
    weights = list(rng.uniform(1, 10, 12))
    edges = [(i, i + 1) for i in range(11)] + [(0, 5), (2, 9), (3, 7), (4, 11)]
    assert _greedy_with_queue(weights, edges) == _greedy_brute_force(weights, edges)


def test_queue_skips_retired_regions_lazily():
    q = MergeQueue()
    q.push(0.3, 2, 1)
    q.push(0.1, 0, 1)
    q.push(0.2, 0, 2)
    q.retire(0)
    assert q.pop() == (0.3, 1, 2)
    assert q.stale_pops == 2
    assert q.pop() is None
    heapq.heapify([])  # the module is a plain binary heap, nothing more
