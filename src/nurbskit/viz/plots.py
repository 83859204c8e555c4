"""Figures of a surface fit (matplotlib, Agg backend, loaded on first use).

* :func:`plot_wireframe`: the output as a wireframe of its parametric grid (the
  thesis's way of showing point order, section 5.1.1);
* :func:`plot_clouds`: input and output clouds with the control net;
* :func:`plot_error_map`: every input point coloured by its distance to the surface;
* :func:`plot_loss`: the loss curve of the fitting loop, stage by stage.

Every function takes plain arrays (numpy or torch), writes one PNG atomically and
returns its path. Nothing is shown on screen.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from .._fs import atomic_path
from .._optional import require

MAX_SCATTER = 20000


def _figure(figsize):
    """A pyplot-free Figure rendered by Agg: no global backend or state is touched."""
    require("matplotlib", "dev", "figures")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _np(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().double().numpy()
    return np.asarray(x, dtype=np.float64)


def _subsample(x: np.ndarray, n: int = MAX_SCATTER) -> np.ndarray:
    if len(x) <= n:
        return x
    idx = np.linspace(0, len(x) - 1, n).astype(int)
    return x[idx]


def _equal_axes(ax, pts: np.ndarray) -> None:
    lo, hi = pts.min(0), pts.max(0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")


def _save(fig, path) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    return path


def plot_wireframe(grid, path: str | os.PathLike, title: str = "output grid") -> Path:
    """The ``(R, S, 3)`` grid as a wireframe: lines follow u and v (point order)."""
    g = _np(grid)
    fig = _figure((6, 6))
    ax = fig.add_subplot(111, projection="3d")
    ax.plot_wireframe(g[..., 0], g[..., 1], g[..., 2], color="tab:green", linewidth=0.5)
    _equal_axes(ax, g.reshape(-1, 3))
    ax.set_title(title)
    return _save(fig, path)


def plot_clouds(points, output, control_points, path: str | os.PathLike, title: str = "input, output and control net") -> Path:
    """Input ``(N, 3)`` in blue, output samples ``(M, 3)`` in green, control net ``(n_u, n_v, 3)`` in red."""
    x, y, c = _subsample(_np(points)), _subsample(_np(output).reshape(-1, 3)), _np(control_points)
    fig = _figure((12, 6))
    for k, (elev, azim) in enumerate(((25, -60), (25, 30))):
        # drawn in call order (not sorted by depth), the input on top: a dense control net
        # hid the input points and most of the output before
        ax = fig.add_subplot(1, 2, k + 1, projection="3d", computed_zorder=False)
        ax.plot_wireframe(c[..., 0], c[..., 1], c[..., 2], color="tab:red", linewidth=0.4, alpha=0.35, zorder=1)
        ax.scatter(c[..., 0].ravel(), c[..., 1].ravel(), c[..., 2].ravel(), s=3, c="tab:red", alpha=0.5,
                   label="control net", zorder=1)
        ax.scatter(y[:, 0], y[:, 1], y[:, 2], s=1, c="tab:green", alpha=0.4, label="output", zorder=2)
        ax.scatter(x[:, 0], x[:, 1], x[:, 2], s=1.5, c="tab:blue", alpha=0.6, label="input", zorder=3)
        _equal_axes(ax, np.vstack([x, c.reshape(-1, 3)]))
        ax.view_init(elev=elev, azim=azim)
        if k == 0:
            handles, labels = ax.get_legend_handles_labels()
            ax.legend(handles[::-1], labels[::-1], loc="upper left", markerscale=4)  # as the title lists them
    fig.suptitle(title)
    return _save(fig, path)


def plot_error_map(points, distances, path: str | os.PathLike, scale: float = 1.0,
                   title: str = "distance of each input point to the surface") -> Path:
    """Input points coloured by ``distances (N,)`` divided by ``scale`` (e.g. the bbox diagonal)."""
    x = _np(points)
    d = _np(distances) / scale
    idx = np.arange(len(x)) if len(x) <= MAX_SCATTER else np.linspace(0, len(x) - 1, MAX_SCATTER).astype(int)
    x, d = x[idx], d[idx]
    fig = _figure((7, 6))
    ax = fig.add_subplot(111, projection="3d")
    sc = ax.scatter(x[:, 0], x[:, 1], x[:, 2], s=3, c=d, cmap="viridis", vmin=0, vmax=max(np.percentile(d, 99), 1e-12))
    fig.colorbar(sc, ax=ax, shrink=0.7, label="distance / bounding-box diagonal" if scale != 1.0 else "distance")
    _equal_axes(ax, x)
    ax.set_title(title)
    return _save(fig, path)


def plot_loss(history: Sequence[dict], path: str | os.PathLike, alternation: Sequence[float] = (),
              title: str = "loss") -> Path:
    """The loss per iteration (log scale); stages in different colours.

    ``history`` records carry ``stage`` and ``loss`` (see :func:`nurbskit.fit.run_stage`);
    ``alternation`` (mean squared distances of the projection + least-squares rounds)
    is drawn first when given, on its own axis (left): the stages' losses (right) are
    other quantities, and on one axis the curve seemed to jump up at the stage change.
    A dashed line marks where each stage starts.
    """
    fig = _figure((7, 4))
    ax = fig.subplots()
    offset = 0
    lines = []
    if len(alternation):
        lines += ax.semilogy(np.arange(len(alternation)), alternation, "k.-", label="alternation (mean sq. distance)")
        ax.set_ylabel("alternation: mean squared distance")
        offset = len(alternation)
    stages: dict[str, list] = {}
    for k, rec in enumerate(history):
        stages.setdefault(rec["stage"], []).append((offset + k, rec["loss"]))
    axs = ax.twinx() if len(alternation) and stages else ax
    for name, xy in stages.items():
        a = np.asarray(xy, dtype=float)
        color = f"C{len(lines) % 10}"
        if (a[:, 1] > 0).all():
            lines += axs.semilogy(a[:, 0], a[:, 1], color=color, label=f"{name} (its loss)")
        else:
            lines += axs.plot(a[:, 0], a[:, 1], color=color, label=f"{name} (its loss)")
        ax.axvline(a[0, 0] - 0.5, color="0.5", linestyle="--", linewidth=0.8)
    ax.set_xlabel("iteration")
    if stages:
        axs.set_ylabel("stage loss (fit units: unit bounding-box diagonal)")
    ax.set_title(title)
    if lines:
        ax.legend(lines, [line.get_label() for line in lines], loc="upper right")
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def plot_training(history: Sequence[dict], path: str | os.PathLike, title: str = "training") -> Path:
    """Training curves: one line per numeric key of ``history`` records, against ``step`` (log scale).

    ``history`` records are ``{"step": int, "seconds": float, <name>: float, ...}`` (see
    :func:`nurbskit.learn.train`); keys starting with ``val_`` are drawn dashed.
    """
    fig = _figure((7, 4))
    ax = fig.subplots()
    keys = [k for k in (history[0] if history else {}) if k not in ("step", "seconds", "lr")]
    steps = np.asarray([rec["step"] for rec in history], dtype=float)
    for key in keys:
        values = np.asarray([rec.get(key, np.nan) for rec in history], dtype=float)
        style = "--" if key.startswith("val_") else "-"
        if np.all(values[np.isfinite(values)] > 0):
            ax.semilogy(steps, values, style, label=key)
        else:
            ax.plot(steps, values, style, label=key)
    ax.set_xlabel("step")
    ax.set_title(title)
    if keys:
        ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def plot_fit_panels(points, panels: Sequence[tuple[str, object]], path: str | os.PathLike,
                    title: str = "", columns: int = 4) -> Path:
    """One panel per fit: the input ``(N, 3)`` in blue and each output grid ``(R, S, 3)`` as a wireframe.

    ``panels`` is a sequence of ``(label, grid)``; used by the benchmarks to put the
    thesis's pipelines side by side (its figures 6.3 and 6.4).
    """
    x = _subsample(_np(points), 4000)
    n = max(len(panels), 1)
    rows = (n + columns - 1) // columns
    fig = _figure((4 * columns, 4 * rows))
    for k, (label, grid) in enumerate(panels):
        g = _np(grid)
        ax = fig.add_subplot(rows, columns, k + 1, projection="3d")
        ax.scatter(x[:, 0], x[:, 1], x[:, 2], s=0.5, c="tab:blue", alpha=0.4)
        ax.plot_wireframe(g[..., 0], g[..., 1], g[..., 2], color="tab:green", linewidth=0.3)
        _equal_axes(ax, x)
        ax.set_title(label, fontsize=9)
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    return _save(fig, path)
