"""Fit a NURBS surface to a point cloud with the default pipeline and with a thesis pipeline.

Run from the repository root:

    python examples/fit_point_cloud.py [points.ply] [--out fits/example]

Without an argument it uses ../shared/data/thesis_nurbsdiff/meshes/horse_2500.off when
present, else a generated wavy sheet.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from nurbskit._fs import output_directory
from nurbskit.fit import fit_surface, get_pipeline
from nurbskit.fit.outputs import fit_report, write_fit_outputs

HORSE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "thesis_nurbsdiff" / "meshes" / "horse_2500.off"


def load(path: str | None) -> torch.Tensor:
    from nurbskit.io import read_points

    if path:
        return torch.as_tensor(read_points(path).points)
    if HORSE.exists():
        return torch.as_tensor(read_points(HORSE).points)
    g = torch.Generator().manual_seed(0)
    uv = torch.rand(3000, 2, generator=g, dtype=torch.float64)
    return torch.stack([uv[:, 0], uv[:, 1], 0.15 * torch.sin(6 * uv[:, 0]) * torch.cos(4 * uv[:, 1])], -1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("points", nargs="?", help="a point or mesh file")
    parser.add_argument("--out", default="fits/example", help="output folder (replaced)")
    args = parser.parse_args()
    points = load(args.points)

    # 1. Our default pipeline; the callback receives a Progress after every iteration.
    losses = []
    result = fit_surface(points, "default", callback=lambda p: losses.append(p.loss))
    with output_directory(args.out, overwrite=True) as tmp:
        report = write_fit_outputs(result, tmp)
    m = report["metrics_normalized"]
    print(f"default: input-to-surface mean {m['to_surface_mean']:.4f} of the diagonal, "
          f"CD + HD + 0.1 LD {m['combined']:.4f}, {len(losses)} refinement steps; files in {args.out}/")

    # 2. A thesis pipeline as a configuration you can edit.
    cfg = get_pipeline("UCDL").with_iters(200)
    cfg.ctrl = (20, 20)
    cfg.stages[0].loss.laplacian_on = "control"
    ucdl = fit_report(fit_surface(points, cfg))["metrics_normalized"]
    print(f"UCDL (200 iterations, Laplacian on the control net): mean {ucdl['to_surface_mean']:.4f}, "
          f"CD + HD + 0.1 LD {ucdl['combined']:.4f}")


if __name__ == "__main__":
    main()
