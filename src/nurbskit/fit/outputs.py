"""The report and the files of one fit.

:func:`fit_report` gathers the numbers (:func:`nurbskit.metrics.evaluate_fit` in the
input's units and in *fit units*, the input scaled to a unit bounding-box diagonal,
plus iterations and timings); :func:`write_fit_outputs` writes everything ``nurbskit
fit`` promises into a directory:

=====================  ===========================================================
``surface.json``       the fitted surface (nurbskit JSON)
``points.off``         the surface sampled on the ``resolution`` grid
``control_points.off`` the control net, u-major
``report.json``        :func:`fit_report`
``config.json``        the resolved :class:`~nurbskit.fit.config.FitConfig`
``wireframe.png``      the output's parametric grid as a wireframe
``clouds.png``         input and output clouds with the control net
``error_map.png``      each input point coloured by its distance to the surface
``loss.png``           the loss curve
=====================  ===========================================================
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from .. import metrics
from .._fs import atomic_open
from ..core.serialize import save
from .api import FitResult
from .config import config_to_dict


def _floats(d: dict) -> dict:
    return {k: (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v) for k, v in d.items()}


def fit_report(result: FitResult, *, distances: bool = False) -> dict:
    """The numbers of a fit, JSON-ready.

    Keys: ``pipeline``, ``dtype`` and ``device`` (those of the fit, the input's),
    ``iterations``, ``seconds``, ``loop_seconds``,
    ``seconds_per_iteration``, ``initial_loss`` (of the first gradient iteration),
    ``final_loss`` and ``final_parts`` (fit units),
    ``closed_v``, ``metrics`` (input units) and ``metrics_normalized`` (the input and
    surface scaled to a unit bounding-box diagonal: the thesis's columns become
    comparable across shapes), and for supervised fits ``rms`` and
    ``rms_normalized`` of the output grid against the target grid. With
    ``distances=True`` the per-point distances (a tensor) come under ``_distances``.
    """
    cfg = result.config
    # The report is measured in float64 on the CPU, whatever the fit ran in.
    s = result.surface.to(dtype=torch.float64, device="cpu")
    pts = result.points.detach().to(dtype=torch.float64, device="cpu")
    res = tuple(cfg.resolution)
    with torch.no_grad():
        # one projection for both sets of numbers: the normalised copy is the same geometry scaled
        to_surface = metrics.point_distances(s, pts)
        m = metrics.evaluate_fit(s, pts, res, to_surface=to_surface)
        center = result.center.to(dtype=torch.float64, device="cpu")
        s_n = s._replace(control_points=(s.control_points - center) / result.scale)
        m_n = metrics.evaluate_fit(s_n, (pts - center) / result.scale, res, to_surface=to_surface / result.scale)
    last = result.history[-1] if result.history else {}
    report = {
        "pipeline": cfg.pipeline,
        "supervised": cfg.supervised,
        "points": int(pts.shape[0]),
        "dtype": str(result.surface.dtype).removeprefix("torch."),
        "device": str(result.surface.control_points.device),
        "control_points": list(s.sizes),
        "degrees": list(s.degrees),
        "topology": result.topology.as_dict(),
        "iterations": int(result.iterations),
        "alternation_rounds": len(result.alternation),
        "seconds": float(result.seconds),
        "loop_seconds": float(result.loop_seconds),
        "seconds_per_iteration": float(result.seconds_per_iteration),
        "initial_loss": float(result.history[0]["loss"]) if result.history else None,
        "final_loss": float(last.get("loss", float("nan"))) if last else None,
        "final_parts": _floats(last.get("parts", {})) if last else {},
        "metrics": _floats(m),
        "metrics_normalized": _floats(m_n),
    }
    if result.target_grid is not None:
        with torch.no_grad():
            grid = s.sample(tuple(result.target_grid.shape[:2]))
            rms = float((grid - result.target_grid.to(dtype=torch.float64, device="cpu")).square().sum(-1).mean().sqrt())
        report["rms"] = rms
        report["rms_normalized"] = rms / result.scale
    if distances:
        report["_distances"] = to_surface
    return report


def write_fit_outputs(
    result: FitResult,
    directory: str | os.PathLike,
    *,
    figures: bool = True,
    report: dict | None = None,
) -> dict:
    """Write the files listed in the module docstring into ``directory`` (which must exist).

    Returns the report (computed here unless given). Use
    :func:`nurbskit._fs.output_directory` around this call for an all-or-nothing
    output folder.
    """
    from ..io import write_points

    d = Path(directory)
    rep = report if report is not None else fit_report(result, distances=figures)
    distances = rep.pop("_distances", None)
    s = result.surface.to(dtype=torch.float64, device="cpu")
    points = result.points.detach().to(dtype=torch.float64, device="cpu")
    res = tuple(result.config.resolution)
    with torch.no_grad():
        grid = s.sample(res)
    save(s, d / "surface.json")
    write_points(d / "points.off", grid.reshape(-1, 3).numpy())
    write_points(d / "control_points.off", s.control_points.reshape(-1, 3).detach().numpy())
    with atomic_open(d / "config.json", "w") as fh:
        json.dump(config_to_dict(result.config), fh, indent=2)
    files = ["surface.json", "points.off", "control_points.off", "report.json", "config.json"]
    if figures:
        from ..viz import plots

        if distances is None:
            distances = metrics.point_distances(s, points)
        name = result.config.pipeline
        plots.plot_wireframe(grid, d / "wireframe.png", title=f"{name}: output grid {res[0]} x {res[1]}")
        plots.plot_clouds(points, grid, s.control_points, d / "clouds.png",
                          title=f"{name}: input (blue), output (green), control net (red)")
        plots.plot_error_map(points, distances, d / "error_map.png", scale=rep["metrics"]["diagonal"])
        plots.plot_loss(result.history, d / "loss.png", result.alternation, title=f"{name}: loss")
        files += ["wireframe.png", "clouds.png", "error_map.png", "loss.png"]
    rep["files"] = files
    with atomic_open(d / "report.json", "w") as fh:
        json.dump(rep, fh, indent=2)
    return rep
