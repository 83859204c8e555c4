"""One fit of each kind on every available device, in float32 and float64 (issue 8).

Convention under test: dtype and device follow the inputs (no configuration field, no
round trip through numpy); `--device`/`--dtype` on the command line only move the
inputs. CPU always; CUDA when torch sees it.
"""

from __future__ import annotations

import dataclasses

import pytest
import torch

from nurbskit.fit import FitConfig, fit_surface, get_pipeline
from nurbskit.volume import VolumeFitConfig, fit_silhouettes
from nurbskit.volume.shapes import solid_drawings, sphere_and_box

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
DTYPES = [torch.float32, torch.float64]


def test_the_fit_configuration_holds_no_device_or_dtype():
    names = {f.name for f in dataclasses.fields(FitConfig)}
    assert "device" not in names and "dtype" not in names
    names = {f.name for f in dataclasses.fields(VolumeFitConfig)}
    assert "device" not in names and "dtype" not in names


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", DTYPES)
def test_fit_surface_runs_on_the_inputs_device_and_dtype(device, dtype):
    g = torch.Generator().manual_seed(3)
    uv = torch.rand(300, 2, generator=g, dtype=torch.float64)
    pts = torch.stack([uv[:, 0], uv[:, 1], 0.2 * torch.sin(3 * uv[:, 0])], -1).to(device=device, dtype=dtype)
    cfg = get_pipeline("default").with_iters(5)
    cfg.ctrl = (6, 6)
    result = fit_surface(pts, cfg)
    s = result.surface
    assert s.dtype == dtype and s.control_points.device.type == device
    assert s.weights.dtype == dtype and all(k.dtype == dtype for k in s.knot_vectors)
    assert result.points.dtype == dtype and result.points.device.type == device
    losses = [h["loss"] for h in result.history]
    assert losses[-1] < losses[0]
    # the fit is good in either precision: within 1% of the diagonal everywhere sampled
    from nurbskit.fit.outputs import fit_report

    assert fit_report(result)["metrics_normalized"]["to_surface_mean"] < 1e-2


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", DTYPES)
def test_supervised_fit_follows_the_target_surface(device, dtype):
    from nurbskit.core import NURBSSurface

    g = torch.Generator().manual_seed(0)
    target = NURBSSurface(torch.rand(5, 5, 3, generator=g, dtype=torch.float64), (3, 3)).to(dtype=dtype, device=device)
    cfg = get_pipeline("SC")
    cfg.resolution = (12, 12)
    result = fit_surface(config=cfg, target_surface=target)
    assert result.surface.dtype == dtype and result.surface.control_points.device.type == device


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", DTYPES)
def test_volume_fit_runs_on_the_drawings_device_and_dtype(device, dtype):
    d = {k: v.to(device=device, dtype=dtype) for k, v in solid_drawings(sphere_and_box, 48).items()}
    result = fit_silhouettes(d, VolumeFitConfig(control_size=8, grid=12, iterations=5, iou_resolution=64))
    assert result.volume.dtype == dtype and result.volume.control_points.device.type == device
    assert result.costs["total"] < result.costs["initial_total"]
