"""A PNG that puts each drawing beside the projection of the fitted solid."""

from __future__ import annotations

import os

import numpy as np

from .._fs import atomic_path
from .views import VIEWS


def write_comparison_png(path: str | os.PathLike, drawings: dict, projections: dict, scores: dict) -> None:
    """Two rows x three views: drawings (top) and the mesh's projections (bottom) with IoU.

    ``drawings[name]`` masks ``(H, W)``; ``projections[name]`` bool images; ``scores[name]`` IoU.
    Written atomically with matplotlib's object API (no pyplot state).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 6.2), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 3)
    for j, view in enumerate(VIEWS):
        d = np.asarray(drawings[view.name].detach().cpu().numpy() if hasattr(drawings[view.name], "detach") else drawings[view.name])
        axes[0, j].imshow(1 - d, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[0, j].set_title(f"{view.name} drawing")
        axes[1, j].imshow(1 - projections[view.name].astype(float), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        axes[1, j].set_title(f"{view.name} projection, IoU {scores[view.name]:.3f}")
        for ax in axes[:, j]:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
