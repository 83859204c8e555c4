"""Synthetic clouds with known shape: random vases (revolution) and extruded profiles.

Used by the tests and ``benchmarks/bench_shapes.py``. Every generator takes a ``seed`` and
its own ``torch.Generator``; global RNGs are untouched.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from ..core.construct import extrude, revolve
from ..core.curve import NURBSCurve

F64 = torch.float64

__all__ = ["SyntheticCloud", "random_axis", "vase_cloud", "extrusion_cloud", "l_profile", "torus_cloud",
           "tube_cloud", "circle_curve"]


class SyntheticCloud(NamedTuple):
    points: torch.Tensor  # (N, 3)
    surface: object  # the exact NURBSSurface
    axis_point: torch.Tensor  # (3,)
    axis_direction: torch.Tensor  # (3,) unit


def random_axis(g: torch.Generator):
    d = torch.randn(3, generator=g, dtype=F64)
    d = d / d.norm()
    o = torch.randn(3, generator=g, dtype=F64) * 0.5
    return o, d


def _frame(d):
    h = torch.tensor([1.0, 0.0, 0.0], dtype=F64) if abs(float(d[0])) < 0.9 else torch.tensor([0.0, 1.0, 0.0], dtype=F64)
    e1 = h - (h @ d) * d
    e1 = e1 / e1.norm()
    return e1, torch.linalg.cross(d, e1, dim=-1)


def _sample(surface, n, noise, g):
    uv = torch.rand(n, 2, generator=g, dtype=F64)
    p = surface.evaluate(uv)
    diag = float((p.amax(0) - p.amin(0)).norm())
    return p + noise * diag * torch.randn(n, 3, generator=g, dtype=F64)


def vase_cloud(n: int = 2000, noise: float = 0.0, seed: int = 0, angle: float = 2 * math.pi) -> SyntheticCloud:
    """A random vase: a cubic profile ``r(z)``, positive and monotone in height, revolved
    about a random axis; ``n`` points uniform in parameter, Gaussian noise of ``noise``
    times the diagonal."""
    g = torch.Generator().manual_seed(seed)
    o, d = random_axis(g)
    m = 7
    z = torch.linspace(0, 1.5, m, dtype=F64)
    r = 0.35 + 0.35 * torch.rand(m, generator=g, dtype=F64)
    e1, _ = _frame(d)
    prof = NURBSCurve(o + r[:, None] * e1 + z[:, None] * d, degree=3)
    s = revolve(prof, o, d, angle)
    return SyntheticCloud(_sample(s, n, noise, g), s, o, d)


def l_profile(width: float = 1.0, height: float = 0.6, seed: int | None = None) -> torch.Tensor:
    """Corner points ``(3, 2)`` of an L: up the vertical leg, along the horizontal one."""
    return torch.tensor([[0.0, height], [0.0, 0.0], [width, 0.0]], dtype=F64)


def extrusion_cloud(n: int = 2000, noise: float = 0.0, seed: int = 0, kind: str = "smooth",
                    length: float = 1.5) -> SyntheticCloud:
    """A random extruded profile (``kind='smooth'``: a cubic wave; ``'L'``: an L, degree 1),
    along a random direction; sampled as :func:`vase_cloud`."""
    g = torch.Generator().manual_seed(seed)
    o, d = random_axis(g)
    e1, e2 = _frame(d)
    if kind == "L":
        xy, degree = l_profile(), 1
        # the corner as a knot: arc-length parameters of the 3 corners
        kv = torch.tensor([0.0, 0.0, 0.6 / 1.6, 1.0, 1.0], dtype=F64)
    else:
        m = 7
        x = torch.linspace(0, 1.5, m, dtype=F64)
        y = 0.4 * torch.rand(m, generator=g, dtype=F64)
        xy, degree, kv = torch.stack([x, y], -1), 3, None
    prof = NURBSCurve(o + xy[:, :1] * e1 + xy[:, 1:2] * e2, degree=degree, knot_vector=kv)
    s = extrude(prof, d, length)
    return SyntheticCloud(_sample(s, n, noise, g), s, o, d)


def circle_curve(centre, e1, e2, radius: float) -> NURBSCurve:
    """The exact nine-point rational circle (weights 1 and sqrt(2)/2) of ``radius`` about
    ``centre (3,)`` in the plane of the unit vectors ``e1, e2``."""
    sq = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)]
    P = torch.stack([centre + radius * (a * e1 + b * e2) for a, b in sq])
    w = torch.tensor([1.0, math.sqrt(0.5)] * 4 + [1.0], dtype=F64)
    kv = torch.tensor([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=F64)
    return NURBSCurve(P, degree=2, knot_vector=kv, weights=w)


def torus_cloud(n: int = 2000, noise: float = 0.0, seed: int = 0, major: float = 1.0,
                minor: float = 0.35) -> SyntheticCloud:
    """A torus (a closed profile: a circle revolved) about a random axis; sampled as
    :func:`vase_cloud`."""
    g = torch.Generator().manual_seed(seed)
    o, d = random_axis(g)
    e1, _ = _frame(d)
    s = revolve(circle_curve(o + major * e1, e1, d, minor), o, d)
    return SyntheticCloud(_sample(s, n, noise, g), s, o, d)


def tube_cloud(n: int = 2000, noise: float = 0.0, seed: int = 0, side: float = 1.0, length: float = 1.5,
               section: str = "square") -> SyntheticCloud:
    """A closed section extruded along a random direction: ``'square'`` (degree 1, the
    corners as knots) or ``'ellipse'`` (a circle scaled 1 : 0.6, rational quadratic)."""
    g = torch.Generator().manual_seed(seed)
    o, d = random_axis(g)
    e1, e2 = _frame(d)
    if section == "square":
        xy = torch.tensor([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=F64) * side
        kv = torch.tensor([0, 0, 0.25, 0.5, 0.75, 1, 1], dtype=F64)
        prof = NURBSCurve(o + xy[:, :1] * e1 + xy[:, 1:2] * e2, degree=1, knot_vector=kv)
    else:
        prof = circle_curve(o, e1 * side * 0.5, e2 * side * 0.3, 1.0)
    s = extrude(prof, d, length)
    return SyntheticCloud(_sample(s, n, noise, g), s, o, d)
