"""nearest_neighbors against the brute-force loop oracle."""

from __future__ import annotations

import pytest
import torch
from _property import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbskit.errors import NurbskitError
from nurbskit.core import neighbors
from nurbskit.core.neighbors import k_nearest, nearest_neighbors, nearest_neighbors_naive


def _clouds(n, m, d, seed, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, d, generator=g, dtype=dtype), torch.rand(m, d, generator=g, dtype=dtype)


@pytest.mark.parametrize("n,m,d", [(1, 1, 3), (5, 9, 3), (40, 17, 3), (23, 31, 2), (12, 6, 1), (30, 30, 5)])
def test_matches_naive(n, m, d):
    q, r = _clouds(n, m, d, seed=n * 100 + m)
    sq, idx = nearest_neighbors(q, r)
    sq0, idx0 = nearest_neighbors_naive(q, r)
    assert idx.dtype == torch.int64 and idx.shape == (n,) and sq.shape == (n,)
    assert torch.equal(idx, idx0)
    torch.testing.assert_close(sq, sq0, rtol=0, atol=1e-15)


def test_sq_dist_is_the_gathered_distance_and_dtype_follows():
    q, r = _clouds(50, 60, 3, seed=1, dtype=torch.float32)
    sq, idx = nearest_neighbors(q, r)
    assert sq.dtype == torch.float32
    torch.testing.assert_close(sq, ((q - r[idx]) ** 2).sum(-1), rtol=0, atol=0)


def test_no_gradient_flows():
    q, r = _clouds(10, 12, 3, seed=2)
    q.requires_grad_(True)
    r.requires_grad_(True)
    sq, idx = nearest_neighbors(q, r)
    assert not sq.requires_grad and not idx.requires_grad


def test_batched_equals_one_by_one():
    g = torch.Generator().manual_seed(3)
    q = torch.rand(2, 3, 15, 3, generator=g, dtype=torch.float64)
    r = torch.rand(2, 3, 11, 3, generator=g, dtype=torch.float64)
    sq, idx = nearest_neighbors(q, r)
    assert sq.shape == (2, 3, 15) and idx.shape == (2, 3, 15)
    for a in range(2):
        for b in range(3):
            sq0, idx0 = nearest_neighbors_naive(q[a, b], r[a, b])
            assert torch.equal(idx[a, b], idx0)
            torch.testing.assert_close(sq[a, b], sq0)


def test_empty_query():
    sq, idx = nearest_neighbors(torch.zeros(0, 3), torch.rand(4, 3))
    assert sq.shape == (0,) and idx.shape == (0,) and idx.dtype == torch.int64


def test_cpu_path_never_builds_the_full_matrix(monkeypatch):
    def forbidden(*args, **kwargs):
        raise AssertionError("torch.cdist must not be used on CPU")

    monkeypatch.setattr(torch, "cdist", forbidden)
    q, r = _clouds(3000, 2000, 3, seed=4, dtype=torch.float32)
    sq, idx = nearest_neighbors(q, r)
    assert sq.shape == (3000,)
    # spot-check against a direct computation on a few rows
    rows = torch.arange(0, 3000, 397)
    full = ((q[rows, None, :] - r[None]) ** 2).sum(-1)
    torch.testing.assert_close(sq[rows], full.min(-1).values)


@pytest.mark.parametrize("chunk_bytes", [1, 8 * 17, 10**9])
def test_chunked_cdist_kernel_matches_naive(chunk_bytes):
    # The CUDA kernel is device-agnostic code: run it on CPU with tiny chunks (1 row,
    # a few rows, everything at once) so the chunk bookkeeping is tested without a GPU.
    q, r = _clouds(37, 29, 3, seed=5)
    idx = neighbors._index_cdist(q, r, chunk_bytes)
    assert torch.equal(idx, nearest_neighbors_naive(q, r)[1])


@pytest.mark.parametrize("chunk_bytes", [1, 8 * 29 * 3, 8 * 37 * 29 * 2, 10**9])
def test_chunked_cdist_kernel_on_a_batch_matches_naive(chunk_bytes):
    # A batch of clouds in the same tiles: row tiles of one element, one element per tile,
    # two elements per tile, the whole batch at once; each element against its own reference.
    q = torch.stack([_clouds(37, 29, 3, seed=s)[0] for s in range(5)])
    r = torch.stack([_clouds(37, 29, 3, seed=10 + s)[1] for s in range(5)])
    idx = neighbors._index_cdist(q, r, chunk_bytes)
    top = neighbors._index_cdist(q, r, chunk_bytes, count=3)
    assert idx.shape == (5, 37) and top.shape == (5, 37, 3)
    for e in range(5):
        assert torch.equal(idx[e], nearest_neighbors_naive(q[e], r[e])[1])
        full = ((q[e][:, None] - r[e][None]) ** 2).sum(-1)
        assert torch.equal(top[e], full.topk(3, dim=-1, largest=False).indices)
    # k_nearest takes the batch too (a KD-tree per element on the CPU): the same answer
    assert torch.equal(k_nearest(q, r, 3), top)
    assert neighbors._index_cdist(q[:, :0], r, chunk_bytes).shape == (5, 0)  # no query points


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_batch_matches_cpu():
    q = torch.stack([_clouds(500, 300, 3, seed=s)[0] for s in range(4)])
    r = torch.stack([_clouds(500, 300, 3, seed=20 + s)[1] for s in range(4)])
    assert torch.equal(k_nearest(q.cuda(), r.cuda(), 2).cpu(), k_nearest(q, r, 2))
    assert torch.equal(nearest_neighbors(q.cuda(), r.cuda())[1].cpu(), nearest_neighbors(q, r)[1])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu():
    q, r = _clouds(2000, 1500, 3, seed=6)
    sq_c, idx_c = nearest_neighbors(q.cuda(), r.cuda(), chunk_bytes=2**16)
    sq, idx = nearest_neighbors(q, r)
    assert sq_c.device.type == "cuda"
    assert torch.equal(idx_c.cpu(), idx)
    torch.testing.assert_close(sq_c.cpu(), sq)


@settings(max_examples=examples(25), deadline=None)
@given(
    n=st.integers(1, 12),
    m=st.integers(1, 12),
    d=st.integers(1, 4),
    seed=st.integers(0, 2**31 - 1),
)
def test_property_distance_equals_brute_force_minimum(n, m, d, seed):
    # Ties may pick different indices; the distance itself must match.
    g = torch.Generator().manual_seed(seed)
    q = torch.randint(-3, 4, (n, d), generator=g).double()
    r = torch.randint(-3, 4, (m, d), generator=g).double()
    sq, idx = nearest_neighbors(q, r)
    sq0, _ = nearest_neighbors_naive(q, r)
    torch.testing.assert_close(sq, sq0, rtol=0, atol=0)
    torch.testing.assert_close(((q - r[idx]) ** 2).sum(-1), sq0, rtol=0, atol=0)


@pytest.mark.parametrize(
    "q,r,match",
    [
        (torch.rand(4, 3), torch.rand(5, 2), "same point dimension"),
        (torch.rand(4, 3), torch.rand(0, 3), "empty"),
        (torch.rand(3), torch.rand(5, 3), r"\(\.\.\., N, D\)"),
        (torch.rand(2, 4, 3), torch.rand(3, 5, 3), "batch shape"),
        (torch.tensor([[0.0, float("nan")]]), torch.rand(5, 2), "NaN"),
        (torch.ones(2, 2, dtype=torch.int64), torch.rand(5, 2), "floating-point"),
    ],
)
def test_errors_name_the_problem(q, r, match):
    with pytest.raises(NurbskitError, match=match):
        nearest_neighbors(q, r)


def test_docstring_examples_run():
    import doctest

    assert doctest.testmod(neighbors, raise_on_error=False).failed == 0
