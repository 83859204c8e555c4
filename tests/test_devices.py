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


# Absolute tolerance of each dtype against a float64 CPU reference of O(1) values.
AGAINST_F64 = {torch.float32: 2e-5, torch.float64: 1e-12}


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", DTYPES)
def test_core_losses_and_projection_on_every_device_and_dtype(device, dtype):
    """Evaluation, derivatives, sampling, Chamfer and projection agree with float64 on the CPU."""
    from _assert import assert_close

    from nurbskit import NURBSSurface
    from nurbskit.core.project import project_points
    from nurbskit.losses import chamfer_distance

    g = torch.Generator().manual_seed(5)
    cp = torch.rand(7, 6, 3, generator=g, dtype=torch.float64)
    w = 0.5 + torch.rand(7, 6, generator=g, dtype=torch.float64)
    ref = NURBSSurface(cp, (3, 2), weights=w)
    here = NURBSSurface(cp.to(device, dtype), (3, 2), weights=w.to(device, dtype))
    uv = torch.rand(200, 2, generator=g, dtype=torch.float64)
    tol = AGAINST_F64[dtype]
    out = here.evaluate(uv.to(device, dtype))
    assert out.dtype == dtype and out.device.type == device
    assert_close(out.cpu(), ref.evaluate(uv).to(dtype), atol=tol)
    assert_close(here.derivatives(uv.to(device, dtype), order=1).cpu(), ref.derivatives(uv, order=1).to(dtype),
                 atol=50 * tol)
    assert_close(here.sample((16, 12)).cpu(), ref.sample((16, 12)).to(dtype), atol=tol)
    x = ref.evaluate(uv) + 0.01 * torch.randn(200, 3, generator=g, dtype=torch.float64)
    y = ref.sample((20, 20)).reshape(-1, 3)
    c = chamfer_distance(x.to(device, dtype), y.to(device, dtype))
    assert c.device.type == device and c.dtype == dtype
    assert_close(c.cpu(), chamfer_distance(x, y).to(dtype), atol=tol)
    proj = project_points(here, x.to(device, dtype))
    assert proj.distance.device.type == device and proj.distance.dtype == dtype
    assert_close(proj.distance.cpu(), project_points(ref, x).distance.to(dtype), atol=10 * tol)


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
