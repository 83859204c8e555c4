"""Synthetic drawings of B-spline curves, deterministic by seed (DeepSpline, section 4).

The recipe of the DeepSpline paper (seed 002, section 4): cubic B-splines with a clamped
uniform knot vector and 4 to 6 control points drawn uniformly in the image, 1 to 3
curves per image, 128 x 128, each curve oriented so that its first control point lies
left of its last (the "canonical orientation" that removes the reversal ambiguity of a
curve's control polygon). Nothing is read from or written to disk.

Convention: pixel coordinates, x to the right, y down, the origin at the top-left corner
of the top-left pixel; the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``.
Images are ``(H, W)`` float64 in [0, 1], dark strokes (0) on a light background (1).

Example:
    >>> from nurbskit.curves.synthetic import SyntheticConfig, make_sample
    >>> s = make_sample(7, SyntheticConfig(size=(64, 64)))
    >>> s.image.shape, len(s.control_points) == s.n_curves
    ((64, 64), True)
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..errors import OptionError


@dataclasses.dataclass(frozen=True)
class SyntheticConfig:
    """What a synthetic drawing holds.

    Attributes:
        size: image ``(H, W)`` in pixels.
        curves: inclusive range of the number of curves per image.
        ctrl: inclusive range of the number of control points per curve.
        degree: the curves' degree (cubic in the paper).
        width: stroke width in pixels (the full width of the anti-aliased line).
        margin: control points are drawn uniformly in the image shrunk by this many pixels.
    """

    size: tuple[int, int] = (128, 128)
    curves: tuple[int, int] = (1, 3)
    ctrl: tuple[int, int] = (4, 6)
    degree: int = 3
    width: float = 2.0
    margin: float = 4.0

    def __post_init__(self):
        h, w = self.size
        if min(h, w) < 8:
            raise OptionError(f"size: expected at least 8 x 8 pixels, got {h} x {w}")
        if not 1 <= self.curves[0] <= self.curves[1]:
            raise OptionError(f"curves: expected 1 <= low <= high, got {self.curves}")
        if not self.degree + 1 <= self.ctrl[0] <= self.ctrl[1]:
            raise OptionError(f"ctrl: expected {self.degree + 1} <= low <= high, got {self.ctrl}")
        if not 0 < self.width <= min(h, w) / 4:
            raise OptionError(f"width: expected a stroke width in (0, {min(h, w) / 4:g}] pixels, got {self.width}")
        if not 0 <= self.margin < min(h, w) / 2:
            raise OptionError(f"margin: expected [0, {min(h, w) / 2:g}) pixels, got {self.margin}")


@dataclasses.dataclass
class Sample:
    """One drawing and its targets.

    Attributes:
        image: ``(H, W)`` float64 in [0, 1], dark strokes on white.
        control_points: one ``(n_i, 2)`` array per curve, pixel coordinates (x, y).
        counts: ``(n_curves,)`` number of control points of each curve.
    """

    image: np.ndarray
    control_points: list[np.ndarray]
    counts: np.ndarray

    @property
    def n_curves(self) -> int:
        return len(self.control_points)

    def curves(self):
        """The targets as :class:`~nurbskit.NURBSCurve` objects (float64, clamped uniform)."""
        return [curve_of(p) for p in self.control_points]


def curve_of(control_points: np.ndarray, degree: int = 3):
    """A clamped-uniform B-spline of ``control_points (n, 2)`` (float64)."""
    import torch

    from ..core import NURBSCurve

    return NURBSCurve(torch.as_tensor(np.asarray(control_points, dtype=np.float64)), degree=degree)


def dense_samples(curve, spacing: float = 0.25) -> np.ndarray:
    """Points ``(M, 2)`` along ``curve`` at most about ``spacing`` pixels apart.

    The count comes from the control polygon's length, which bounds the curve's length
    (the variation-diminishing property of B-splines).
    """
    import torch

    cp = curve.control_points.detach().cpu().numpy()
    polygon = float(np.linalg.norm(np.diff(cp, axis=0), axis=1).sum())
    m = int(np.clip(np.ceil(polygon / spacing), 16, 1 << 20)) + 1
    u0, u1 = curve.domain[0]
    with torch.no_grad():
        pts = curve.evaluate(torch.linspace(float(u0), float(u1), m, dtype=curve.dtype))
    return pts.cpu().numpy().astype(np.float64)


def render(polylines: list[np.ndarray], size: tuple[int, int], width: float) -> np.ndarray:
    """Anti-aliased strokes of ``width`` pixels along dense ``polylines [(M_i, 2)]`` -> ``(H, W)`` ink in [0, 1].

    A distance-field render: a pixel's ink is ``clip(width / 2 + 1/2 - d, 0, 1)`` with ``d``
    the distance from its centre to the nearest curve sample, a one-pixel linear ramp
    across the stroke's edge (the box-filter coverage of a straight edge). The samples
    must be dense (:func:`dense_samples`), so that the nearest sample is the nearest point.
    """
    h, w = size
    ink = np.zeros((h, w))
    if not polylines:
        return ink
    tree = cKDTree(np.concatenate(polylines))
    reach = width / 2 + 1.0
    ys, xs = np.mgrid[0:h, 0:w]
    centres = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)
    d, _ = tree.query(centres, distance_upper_bound=reach)
    ink.ravel()[:] = np.clip(width / 2 + 0.5 - d, 0.0, 1.0)  # inf (beyond reach) -> 0
    return ink


def make_sample(seed: int, config: SyntheticConfig = SyntheticConfig()) -> Sample:
    """The drawing number ``seed``: the same seed gives the same drawing on every machine.

    Uses its own ``numpy.random.Generator(PCG64(seed))``; the global RNGs are untouched.
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    h, w = config.size
    n_curves = int(rng.integers(config.curves[0], config.curves[1] + 1))
    points, polylines = [], []
    for _ in range(n_curves):
        n = int(rng.integers(config.ctrl[0], config.ctrl[1] + 1))
        cp = np.stack([rng.uniform(config.margin, w - config.margin, n),
                       rng.uniform(config.margin, h - config.margin, n)], axis=1)
        if cp[0, 0] > cp[-1, 0]:  # canonical orientation: first point left of the last
            cp = cp[::-1].copy()
        points.append(cp)
        polylines.append(dense_samples(curve_of(cp, config.degree)))
    image = 1.0 - render(polylines, config.size, config.width)
    return Sample(image=image, control_points=points, counts=np.array([len(p) for p in points]))


def make_batch(seeds, config: SyntheticConfig = SyntheticConfig()) -> list[Sample]:
    """:func:`make_sample` for each seed."""
    return [make_sample(int(s), config) for s in seeds]
