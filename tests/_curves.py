"""Shared checks of the classical curve path on synthetic drawings."""

from __future__ import annotations

import numpy as np

from nurbskit.curves.api import extract
from nurbskit.curves.classic import chamfer_points
from nurbskit.curves.synthetic import SyntheticConfig, dense_samples, make_sample


def assert_counted_right(seed_base: int, cases, size: int = 128, chamfer_px: float = 1.5,
                         method: str = "classic", chosen: str | None = None) -> None:
    """Each ``(n, i)`` drawing (seed ``seed_base + i``, stroke width 1, 2 or 3 px by ``i mod 3``,
    ``n`` curves) is read by ``method`` as ``n`` curves within ``chamfer_px`` (symmetric
    Chamfer to the truth), and from the ``chosen`` source when given ("classic", "network" or "regrouped")."""
    for n, i in cases:
        width = (1.0, 2.0, 3.0)[i % 3]
        sample = make_sample(seed_base + i, SyntheticConfig(size=(size, size), curves=(n, n), width=width))
        curves, found = extract(sample.image, method=method)
        assert len(curves) == n, (n, i)
        assert chosen is None or found.chosen == chosen, (n, i, found.chosen)
        got = np.concatenate([dense_samples(c) for c in curves])
        truth = np.concatenate([dense_samples(c) for c in sample.curves()])
        assert chamfer_points(got, truth)["symmetric"] < chamfer_px, (n, i)
