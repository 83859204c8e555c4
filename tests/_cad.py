"""Helpers for the CAD exchange tests: the extras policy and random splines with every
kind of knot vector (clamped, unclamped, periodic)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import _extras
from nurbskit import NURBSCurve, NURBSSurface


def require_extra(module: str, extra: str = "cad"):
    """Import ``module``; skip the test module without it, but FAIL when NURBSKIT_REQUIRE_EXTRAS=1 (CI)."""
    return _extras.require_extra(module, extra, module_level=True)


def knots(rng: np.random.Generator, n: int, p: int, kind: str) -> np.ndarray:
    """A flat knot vector for ``n`` control points: 'clamped', 'unclamped' or 'periodic'
    (periodic: ``n - p`` distinct poles, knots repeating with the period; the caller
    wraps the control points)."""
    a = float(rng.uniform(-2, 2))
    if kind == "clamped":
        inner = np.sort(rng.uniform(a, a + 3, n - p - 1))
        return np.concatenate([np.full(p + 1, a), inner, np.full(p + 1, a + 3)])
    if kind == "unclamped":
        return a + np.cumsum(rng.uniform(0.2, 1.0, n + p + 1))
    m = n - p  # periodic
    gaps = rng.uniform(0.3, 1.2, m)
    inside = a + np.concatenate([[0.0], np.cumsum(gaps)])  # t_p .. t_n (m + 1 knots)
    period = inside[-1] - inside[0]  # as OCC computes it, so that the wrapped knots agree to the bit
    return np.concatenate([inside[m - p:m] - period, inside, inside[1:p + 1] + period])


def random_surface(rng, degrees, kinds=("clamped", "clamped"), rational=True, scale=1.0) -> NURBSSurface:
    sizes = [int(p + 2 + rng.integers(0, 4)) for p in degrees]
    sizes = [max(n, 2 * p + 1) if k == "periodic" else n for n, p, k in zip(sizes, degrees, kinds)]
    kvs = [knots(rng, n, p, k) for n, p, k in zip(sizes, degrees, kinds)]
    cp = rng.normal(size=(*sizes, 3)) * scale
    w = rng.uniform(0.4, 2.0, size=sizes) if rational else np.ones(sizes)
    for axis, (k, p, n) in enumerate(zip(kinds, degrees, sizes)):
        if k == "periodic":  # the last p control points repeat the first p
            idx = [slice(None)] * 2
            idx[axis] = slice(n - p, n)
            src = [slice(None)] * 2
            src[axis] = slice(0, p)
            cp[tuple(idx)] = cp[tuple(src)]
            w[tuple(idx)] = w[tuple(src)]
    t = lambda a: torch.tensor(a, dtype=torch.float64)  # noqa: E731
    return NURBSSurface(t(cp), tuple(degrees), [t(k) for k in kvs], t(w))


def random_curve(rng, degree, kind="clamped", rational=True, scale=1.0) -> NURBSCurve:
    n = int(degree + 2 + rng.integers(0, 5))
    if kind == "periodic":
        n = max(n, 2 * degree + 1)
    kv = knots(rng, n, degree, kind)
    cp = rng.normal(size=(n, 3)) * scale
    w = rng.uniform(0.4, 2.0, size=n) if rational else np.ones(n)
    if kind == "periodic":
        cp[n - degree:] = cp[:degree]
        w[n - degree:] = w[:degree]
    t = lambda a: torch.tensor(a, dtype=torch.float64)  # noqa: E731
    return NURBSCurve(t(cp), degree, t(kv), t(w))


def grid(spline, count: int = 9) -> torch.Tensor:
    """``(count ** k, k)`` parameters on a regular grid over the spline's domain (ends included)."""
    axes = [np.linspace(lo, hi, count) for lo, hi in spline.domain]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    return torch.tensor(mesh if len(axes) > 1 else mesh[:, 0], dtype=torch.float64)


def diagonal(spline) -> float:
    cp = spline.control_points.detach().double().numpy().reshape(-1, spline.dim)
    return float(np.linalg.norm(cp.max(axis=0) - cp.min(axis=0)))
