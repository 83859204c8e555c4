"""The fitting loop's steps replayed as CUDA graphs (nurbskit._cuda_graph).

The CUDA tests run where a GPU is present and are skipped with the reason otherwise;
the CPU ones check what the loop relies on everywhere: a step runs eagerly off the GPU,
and the loop's state keeps its tensors (a captured graph reads the tensors it saw).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nurbskit._cuda_graph import GraphedStep
from nurbskit.fit import fit_surface, get_pipeline
from nurbskit.fit.loop import _State, _store

requires_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available: GPU-only check")


def _quadratic_step(x: torch.Tensor):
    def step():
        loss = (x * x).sum() + x[0]
        loss.backward()
        return loss.detach()

    return step


def test_off_the_gpu_a_step_runs_eagerly_and_clears_the_gradients():
    x = torch.tensor([1.0, 2.0, 3.0], requires_grad=True)
    step = GraphedStep(_quadratic_step(x), [x], device="cpu", warmup=0)
    for _ in range(3):  # a captured step would accumulate nothing either: each call starts from no gradient
        loss = step()
    assert not step.captured and step.reason == "not on a CUDA device"
    assert loss.item() == 15.0
    assert x.grad.tolist() == [3.0, 4.0, 6.0]


def test_the_state_keeps_its_tensors():
    state = _State()
    first = torch.zeros(4, 2)
    _store(state, "foot", first)
    _store(state, "foot", torch.ones(4, 2))
    assert state.foot is first and first.eq(1).all()
    _store(state, "foot", torch.ones(5, 2))  # another shape: a new stage's tensor
    assert state.foot.shape == (5, 2) and state.foot is not first


@requires_cuda
def test_a_replayed_step_gives_the_eager_gradients_for_new_values():
    x = torch.tensor([1.0, 2.0, 3.0], device="cuda", dtype=torch.float64, requires_grad=True)
    step = GraphedStep(_quadratic_step(x), [x], device="cuda", warmup=1)
    step()
    for value in ([1.0, 2.0, 3.0], [-4.0, 0.5, 2.0], [0.0, 0.0, 7.0]):
        with torch.no_grad():
            x.copy_(torch.tensor(value, dtype=torch.float64))
        version = None if not step.captured else step.output._version
        loss = step()
        assert step.captured, step.reason
        if version is not None:
            assert step.output._version > version  # a replay bumps what it wrote
        v = np.array(value)
        assert loss.item() == float((v * v).sum() + v[0])
        assert x.grad.tolist() == (2 * v + np.array([1.0, 0.0, 0.0])).tolist()


@requires_cuda
def test_a_step_that_reads_back_runs_eagerly_with_the_reason():
    x = torch.tensor([1.0, 2.0], device="cuda", requires_grad=True)

    def step():
        loss = (x * x).sum()
        if loss.item() > 0:  # a host read: cannot be captured
            loss.backward()
        return loss.detach()

    graphed = GraphedStep(step, [x], device="cuda", warmup=1)
    for _ in range(3):
        loss = graphed()
    assert not graphed.captured and graphed.reason.startswith("capture failed")
    assert loss.item() == 5.0 and x.grad.tolist() == [2.0, 4.0]


@requires_cuda
@pytest.mark.parametrize("pipeline", ["default"])
def test_a_fit_with_cuda_graphs_matches_the_eager_fit(monkeypatch, pipeline):
    g = torch.Generator().manual_seed(3)
    uv = torch.rand(3000, 2, generator=g, dtype=torch.float64)
    points = torch.stack([uv[:, 0], uv[:, 1], 0.3 * torch.sin(3 * uv[:, 0]) * torch.cos(2 * uv[:, 1])], -1).cuda()
    graphed = fit_surface(points, get_pipeline(pipeline))
    monkeypatch.setenv("NURBSKIT_CUDA_GRAPHS", "0")
    eager = fit_surface(points, get_pipeline(pipeline))
    reasons = [h["cuda_graph"] for h in graphed.history if "cuda_graph" in h]
    assert reasons and all(r == "captured" for r in reasons), reasons
    assert [h.get("cuda_graph") for h in eager.history if "cuda_graph" in h][0] == "turned off (NURBSKIT_CUDA_GRAPHS=0)"
    assert graphed.iterations == eager.iterations
    assert [h["evaluations"] for h in graphed.history] == [h["evaluations"] for h in eager.history]
    a = graphed.surface.control_points.double().cpu()
    b = eager.surface.control_points.double().cpu()
    assert (a - b).abs().max().item() <= 1e-9
