"""Shared checks of the classical curve path on synthetic drawings."""

from __future__ import annotations

import numpy as np

from nurbskit.curves.classic import chamfer_points, fit_image
from nurbskit.curves.synthetic import SyntheticConfig, dense_samples, make_sample


def assert_counted_right(seed_base: int, cases, size: int = 128, chamfer_px: float = 1.5) -> None:
    """Each ``(n, i)`` drawing (seed ``seed_base + i``, stroke width 1, 2 or 3 px by ``i mod 3``,
    ``n`` curves) is read as ``n`` curves within ``chamfer_px`` (symmetric Chamfer to the truth)."""
    for n, i in cases:
        width = (1.0, 2.0, 3.0)[i % 3]
        sample = make_sample(seed_base + i, SyntheticConfig(size=(size, size), curves=(n, n), width=width))
        curves, _ = fit_image(sample.image)
        assert len(curves) == n, (n, i)
        got = np.concatenate([dense_samples(c) for c in curves])
        truth = np.concatenate([dense_samples(c) for c in sample.curves()])
        assert chamfer_points(got, truth)["symmetric"] < chamfer_px, (n, i)
