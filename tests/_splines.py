"""Random splines for tests: non-uniform knots, repeated interior knots, any domain."""

from __future__ import annotations

import numpy as np
import torch

from nurbskit import NURBSCurve, NURBSSurface, NURBSVolume


def random_knots(rng: np.random.Generator, n: int, p: int, domain=(0.0, 1.0), repeat: bool = True) -> np.ndarray:
    """Clamped knot vector with random interior knots; one may repeat up to multiplicity p."""
    a, b = domain
    n_inner = n - p - 1
    inner = np.sort(rng.uniform(a, b, n_inner))
    if repeat and n_inner >= 2 and p >= 2:
        i = rng.integers(0, n_inner - 1)
        mult = int(min(p, n_inner - i))
        inner[i : i + mult] = inner[i]
        inner = np.sort(inner)
    return np.concatenate([np.full(p + 1, a), inner, np.full(p + 1, b)])


def random_domain(rng: np.random.Generator) -> tuple[float, float]:
    a = float(rng.uniform(-3, 3))
    return a, a + float(rng.uniform(0.5, 4))


def random_spline(cls, rng: np.random.Generator, degrees, sizes, dim=3, rational=True, domains=None, dtype=torch.float64):
    """A random curve/surface/volume of class ``cls`` with the given degrees and sizes."""
    domains = domains or [random_domain(rng) for _ in degrees]
    kvs = [torch.tensor(random_knots(rng, n, p, d), dtype=dtype) for n, p, d in zip(sizes, degrees, domains)]
    cp = torch.tensor(rng.normal(size=tuple(sizes) + (dim,)), dtype=dtype)
    w = torch.tensor(rng.uniform(0.3, 2.0, size=tuple(sizes)), dtype=dtype) if rational else None
    if len(degrees) == 1:
        return cls(cp, degrees[0], kvs[0], w)
    return cls(cp, degrees, kvs, w)


def random_params(rng: np.random.Generator, spline, m: int, ends: bool = True) -> torch.Tensor:
    """``(M, k)`` parameters inside the domain, with the corners of the domain included."""
    lo = np.array([d[0] for d in spline.domain])
    hi = np.array([d[1] for d in spline.domain])
    pts = rng.uniform(lo, hi, size=(m, len(lo)))
    if ends:
        corners = np.array(np.meshgrid(*[[l, h] for l, h in zip(lo, hi)], indexing="ij")).reshape(len(lo), -1).T
        pts = np.concatenate([corners, pts])
    return torch.tensor(pts, dtype=spline.dtype)


def to_geomdl_params(spline, params: torch.Tensor) -> np.ndarray:
    """geomdl normalises clamped knot vectors to [0, 1]: map our parameters onto that."""
    lo = np.array([float(kv[0]) for kv in spline.knot_vectors])
    hi = np.array([float(kv[-1]) for kv in spline.knot_vectors])
    t = (params.reshape(-1, len(lo)).numpy() - lo) / (hi - lo)
    return np.clip(t, 0.0, 1.0), hi - lo


def random_batch(cls, rng: np.random.Generator, batch, degrees, sizes, dim=3, per_element_knots=False,
                 dtype=torch.float64, domains=None):
    """A batch ``batch`` of random rational splines; knots shared or one vector per element."""
    n_el = int(np.prod(batch))
    domains = domains or [random_domain(rng) for _ in degrees]
    kvs = []
    for n, p, d in zip(sizes, degrees, domains):
        if per_element_knots:
            rows = [random_knots(rng, n, p, d) for _ in range(n_el)]
            kvs.append(torch.tensor(np.array(rows), dtype=dtype).reshape(tuple(batch) + (-1,)))
        else:
            kvs.append(torch.tensor(random_knots(rng, n, p, d), dtype=dtype))
    cp = torch.tensor(rng.normal(size=tuple(batch) + tuple(sizes) + (dim,)), dtype=dtype)
    w = torch.tensor(rng.uniform(0.3, 2.0, size=tuple(batch) + tuple(sizes)), dtype=dtype)
    if len(degrees) == 1:
        return cls(cp, degrees[0], kvs[0], w)
    return cls(cp, degrees, kvs, w)


def sphere_octant(dtype=torch.float64):
    """Unit sphere, x, y, z >= 0, as a rational biquadratic: u the longitude (0 at +x), v the
    latitude (1 at the pole, where the whole edge v = 1 collapses to (0, 0, 1))."""
    from nurbskit import NURBSSurface

    arc = torch.tensor([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=dtype)
    arc_w = torch.tensor([1.0, 2 ** -0.5, 1.0], dtype=dtype)
    cp = torch.empty(3, 3, 3, dtype=dtype)
    for i in range(3):
        for j in range(3):
            r, z = arc[j]
            cp[i, j] = torch.stack([r * arc[i, 0], r * arc[i, 1], z])
    return NURBSSurface(cp, degrees=(2, 2), weights=arc_w[:, None] * arc_w[None, :])


def small_surface(rational=True):
    """A small fixed rational surface (5 x 4, degrees 2, a non-uniform u knot vector)."""
    g = torch.Generator().manual_seed(3)
    cp = torch.rand(5, 4, 3, generator=g, dtype=torch.float64)
    w = (0.5 + torch.rand(5, 4, generator=g, dtype=torch.float64)) if rational else None
    ku = torch.tensor([0, 0, 0, 0.3, 0.6, 1, 1, 1], dtype=torch.float64)
    return NURBSSurface(cp, (2, 2), [ku, None], w)


def small_curve():
    """A rational quarter circle (exact: weights 1, sqrt(2)/2, 1)."""
    cp = torch.tensor([[1.0, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=torch.float64)
    return NURBSCurve(cp, 2, None, torch.tensor([1, 2 ** -0.5, 1], dtype=torch.float64))


def small_volume():
    """A small fixed rational volume (3 x 4 x 5, degrees 2, 2, 3)."""
    g = torch.Generator().manual_seed(4)
    return NURBSVolume(torch.rand(3, 4, 5, 3, generator=g, dtype=torch.float64), (2, 2, 3),
                       None, 0.5 + torch.rand(3, 4, 5, generator=g, dtype=torch.float64))
