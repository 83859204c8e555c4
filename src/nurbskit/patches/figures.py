"""Figures of a multi-patch fit (matplotlib's object API on the Agg canvas, as :mod:`nurbskit.viz.plots`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..viz.plots import _equal_axes, _figure, _save, _subsample


def plot_labels(points: np.ndarray, labels: np.ndarray, path, title: str) -> Path:
    """Points ``(N, 3)`` coloured by ``labels (N,)`` (grey: -1), three-quarter view."""
    from .outputs import palette

    keep = _subsample(np.arange(len(points)))
    p, lab = points[keep], labels[keep]
    colours = np.full((len(p), 3), 0.75)
    ok = lab >= 0
    if ok.any():
        colours[ok] = palette(int(lab.max()) + 1)[lab[ok]] / 255.0
    fig = _figure((6, 6))
    ax = fig.add_subplot(111, projection="3d")
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=colours, s=1.5, linewidths=0)
    _equal_axes(ax, points)
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


def plot_energy(energy: list[float], path) -> Path:
    """The energy U after the planar start (merge 0) and after each accepted merge."""
    fig = _figure((6, 3.5))
    ax = fig.add_subplot(111)
    ax.plot(np.arange(len(energy)), energy, marker="o", markersize=3, color="tab:blue")
    ax.set_xlabel("accepted merges")
    ax.set_ylabel("energy U")
    ax.set_title("energy over the merges")
    ax.grid(alpha=0.3)
    return _save(fig, path)
