"""Fitting NURBS surfaces to point clouds: the thesis's pipelines and ours.

Example:
    >>> import torch
    >>> from nurbskit.fit import fit_surface
    >>> uv = torch.rand(300, 2, dtype=torch.float64)
    >>> pts = torch.stack([uv[:, 0], uv[:, 1], 0.1 * uv[:, 0] * uv[:, 1]], -1)
    >>> fit_surface(pts, "default").surface.sizes
    (15, 15)
"""

from .api import FitResult, fit_surface, resolve_config
from .config import AlternationConfig, FitConfig, InitConfig, LossWeights, StageConfig, config_from_dict, config_to_dict
from .init import initial_surface, looks_closed
from .loop import Progress, Target, run_stage
from .lstsq import alternate, solve_control_points
from .matching import one_to_one_matching
from .outputs import fit_report, write_fit_outputs
from .params import SurfaceParameters, Topology
from .pipelines import PIPELINES, get_pipeline

__all__ = [
    "fit_surface", "FitResult", "resolve_config",
    "FitConfig", "StageConfig", "LossWeights", "InitConfig", "AlternationConfig",
    "config_to_dict", "config_from_dict",
    "initial_surface", "looks_closed", "solve_control_points", "alternate", "one_to_one_matching",
    "run_stage", "Progress", "Target", "PIPELINES", "get_pipeline",
    "fit_report", "write_fit_outputs", "SurfaceParameters", "Topology",
]
