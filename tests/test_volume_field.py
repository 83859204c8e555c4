"""GridField (mode products with basis matrices) against the core and a naive triple loop."""

import pytest
import torch

from nurbskit import NURBSVolume
from nurbskit.core.basis import basis_functions
from nurbskit.core.knots import find_spans
from nurbskit.errors import OptionError
from nurbskit.volume.field import GridField

from _assert import assert_close

SIZES = (5, 6, 4)
DEGREES = (2, 3, 1)


def make(seed=0, sizes=SIZES, degrees=DEGREES):
    gen = torch.Generator().manual_seed(seed)
    values = torch.rand(sizes, generator=gen, dtype=torch.float64)
    weights = 0.5 + torch.rand(sizes, generator=gen, dtype=torch.float64)
    volume = NURBSVolume(values.unsqueeze(-1), degrees, weights=weights)
    axes = [torch.rand(r, generator=gen, dtype=torch.float64) for r in (4, 3, 5)]
    axes = [torch.cat([a, a.new_tensor([0.0, 1.0])]) for a in axes]  # include both domain ends
    return volume, values, weights, axes


def naive_field(volume, values, weights, u, v, w):
    """Triple loop over control values with the core's per-span basis (A2.2)."""
    out = torch.zeros(len(u), len(v), len(w), dtype=torch.float64)
    basis = []
    for kv, p, n, t in zip(volume.knot_vectors, volume.degrees, volume.sizes, (u, v, w)):
        spans = find_spans(kv, p, n, t)
        local = basis_functions(kv, p, spans, t)
        full = torch.zeros(len(t), n, dtype=torch.float64)
        for m in range(len(t)):
            for j in range(p + 1):
                full[m, spans[m] - p + j] = local[m, j]
        basis.append(full)
    Bu, Bv, Bw = basis
    for a in range(len(u)):
        for b in range(len(v)):
            for c in range(len(w)):
                num = den = 0.0
                for i in range(values.shape[0]):
                    for j in range(values.shape[1]):
                        for k in range(values.shape[2]):
                            bw = Bu[a, i] * Bv[b, j] * Bw[c, k] * weights[i, j, k]
                            num += bw * values[i, j, k]
                            den += bw
                out[a, b, c] = num / den
    return out


def test_field_matches_a_naive_triple_loop():
    volume, values, weights, axes = make()
    grid = GridField(volume.knot_vectors, volume.degrees, volume.sizes, axes, second_derivatives=False)
    got = grid.evaluate(values, weights)
    assert_close(got, naive_field(volume, values, weights, *axes), atol=1e-12)


def test_field_matches_the_core_scattered_evaluation():
    volume, values, weights, axes = make(1)
    grid = GridField(volume.knot_vectors, volume.degrees, volume.sizes, axes)
    u, v, w = torch.meshgrid(*axes, indexing="ij")
    params = torch.stack([u, v, w], dim=-1).reshape(-1, 3)
    ref = volume.evaluate(params).reshape(u.shape)
    assert_close(grid.evaluate(values, weights), ref, atol=1e-12)
    f, _ = grid.evaluate_with_laplacian(values, weights)
    assert_close(f, ref, atol=1e-12)


def test_laplacian_matches_the_core_rational_derivatives():
    volume, values, weights, axes = make(2, degrees=(2, 3, 2))
    grid = GridField(volume.knot_vectors, volume.degrees, volume.sizes, axes)
    u, v, w = torch.meshgrid(*axes, indexing="ij")
    params = torch.stack([u, v, w], dim=-1).reshape(-1, 3)
    d = volume.derivatives(params, order=2)[..., 0]  # (M, 3, 3, 3)
    lap_ref = (d[:, 2, 0, 0] + d[:, 0, 2, 0] + d[:, 0, 0, 2]).reshape(u.shape)
    _, lap = grid.evaluate_with_laplacian(values, weights)
    assert_close(lap, lap_ref, rtol=1e-10, atol=1e-9)
    # and with a unit per direction, each term scales by unit^2
    _, scaled = grid.evaluate_with_laplacian(values, weights, scale=(0.5, 2.0, 1.0))
    ref = (0.25 * d[:, 2, 0, 0] + 4.0 * d[:, 0, 2, 0] + d[:, 0, 0, 2]).reshape(u.shape)
    assert_close(scaled, ref, rtol=1e-10, atol=1e-9)


def test_laplacian_of_a_quadratic_is_constant():
    # A quadratic is reproduced exactly by its blossom values as control values (x^2:
    # c_i = t_{i+1} t_{i+2}); f = x^2 + 2 y^2 - z^2 has Laplacian 2 + 4 - 2 = 4 everywhere.
    n, p = 6, 2
    volume = NURBSVolume(torch.zeros(n, n, n, 1, dtype=torch.float64), (p, p, p))
    kv = volume.knot_vectors[0]
    # a quadratic's B-spline coefficients: blossom values c_i = t1 * t2 for x^2
    sq = torch.stack([kv[i + 1] * kv[i + 2] for i in range(n)])
    X, Y, Z = torch.meshgrid(sq, sq, sq, indexing="ij")
    values = X + 2 * Y - Z
    axes = [torch.linspace(0, 1, 7, dtype=torch.float64)] * 3
    grid = GridField(volume.knot_vectors, (p, p, p), (n, n, n), axes)
    f, lap = grid.evaluate_with_laplacian(values, torch.ones(n, n, n, dtype=torch.float64))
    g = axes[0]
    x, y, z = torch.meshgrid(g, g, g, indexing="ij")
    assert_close(f, x**2 + 2 * y**2 - z**2, atol=1e-12)
    assert_close(lap, torch.full_like(lap, 4.0), atol=1e-10)


def test_gradients_reach_values_and_weights():
    volume, values, weights, axes = make(3, sizes=(3, 4, 3), degrees=(2, 2, 1))
    grid = GridField(volume.knot_vectors, volume.degrees, volume.sizes, axes)
    v = values.clone().requires_grad_(True)
    w = weights.clone().requires_grad_(True)

    def cost(v, w):
        f, lap = grid.evaluate_with_laplacian(v, w, scale=(0.1, 0.1, 0.1))
        return (f**2).mean() + (lap**2).mean()

    assert torch.autograd.gradcheck(cost, (v, w))


def test_shape_mismatch_is_an_option_error():
    volume, values, weights, axes = make()
    grid = GridField(volume.knot_vectors, volume.degrees, volume.sizes, axes, second_derivatives=False)
    with pytest.raises(OptionError, match=r"must have shape \(5, 6, 4\)"):
        grid.evaluate(values[:-1], weights[:-1])
    with pytest.raises(OptionError, match="without second derivatives"):
        grid.evaluate_with_laplacian(values, weights)
