"""Replaying a step of fixed shapes as one CUDA graph.

On a GPU the fitting loop is bound by launches, not arithmetic: an evaluation of the
default fit's objective is about a thousand small kernels, each launched from Python.
A step that reads nothing back to the host and keeps its shapes (the loop's objective
and its warm foot-point refresh are written so) can be captured once with
``torch.cuda.graph`` and replayed as one launch, PyTorch's whole-step capture.

:class:`GraphedStep` wraps such a step: the first ``warmup`` calls run eagerly (they
build what is cached: the basis, the grid axes, the neighbour index), the next one
captures, and every later call replays into the same output tensors. Gradients of
``leaves`` (tensors that the step's backward writes) are allocated by the capture and
rewritten in place by every replay, so a caller reads ``leaf.grad`` after each call and
must not set it to None. A replay writes its outputs without Python seeing it, so it
bumps their version counters itself (what keys the basis cache stays true), and the basis
cache is off while capturing: a cached basis would be baked into the graph as a constant,
though its key tensors (the foot points) change in place between replays.

Where a capture fails (an operation that reads back to the host, a copy from host
memory) the step runs eagerly from then on and ``reason`` says why; nothing else
changes. Off the GPU, and with ``NURBSKIT_CUDA_GRAPHS=0`` in the
environment, it always runs eagerly.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Sequence

import torch

Tensor = torch.Tensor


def graphs_enabled() -> bool:
    """False where ``NURBSKIT_CUDA_GRAPHS`` is ``0`` (every step then runs eagerly)."""
    return os.environ.get("NURBSKIT_CUDA_GRAPHS", "1") != "0"


def _bump_versions(value: Any) -> None:
    from .core.tensor import _tensors_in

    bump = getattr(torch.autograd.graph, "increment_version", None)
    for t in _tensors_in(value):
        if bump is not None:
            bump(t)
        else:  # torch < 2.2
            torch._C._increment_version([t])


class GraphedStep:
    """``step()`` run eagerly ``warmup`` times, then captured and replayed (CUDA only).

    Args:
        step: a function of no arguments whose tensors all live on one CUDA device
            when captured; its result (tensors, or tuples / dicts of them) is returned
            by every call and, once captured, is the same objects each time.
        leaves: tensors whose ``.grad`` the step's backward writes (cleared before the
            capture so that the graph owns them).
        device: where the step runs; anything but CUDA runs eagerly.
        warmup: eager calls before the capture.
    """

    def __init__(self, step: Callable[[], Any], leaves: Sequence[Tensor] = (), *, device: torch.device | str,
                 warmup: int = 1):
        self.step = step
        self.leaves = list(leaves)
        self.warmup = warmup
        self.calls = 0
        self.graph: torch.cuda.CUDAGraph | None = None
        self.output: Any = None
        device = torch.device(device)
        self.reason: str | None = None
        if device.type != "cuda":
            self.reason = "not on a CUDA device"
        elif not graphs_enabled():
            self.reason = "turned off (NURBSKIT_CUDA_GRAPHS=0)"

    @property
    def captured(self) -> bool:
        return self.graph is not None

    def __call__(self) -> Any:
        if self.graph is not None:
            self.graph.replay()
            _bump_versions(self.output)
            return self.output
        if self.reason is not None or self.calls < self.warmup:
            self.calls += 1
            for leaf in self.leaves:
                leaf.grad = None
            return self.step()
        return self._capture()

    def _capture(self) -> Any:
        for leaf in self.leaves:
            leaf.grad = None
        from .core.tensor import basis_cache

        graph = torch.cuda.CUDAGraph()
        cached, basis_cache.enabled = basis_cache.enabled, False
        try:
            with torch.cuda.graph(graph):
                output = self.step()
        except Exception as error:  # an operation that cannot be captured: eager from now on
            message = str(error).strip().splitlines()
            self.reason = f"capture failed: {type(error).__name__}: {message[0] if message else ''}"
            torch.cuda.synchronize()
            return self()
        finally:
            basis_cache.enabled = cached
        self.graph, self.output = graph, output
        graph.replay()
        _bump_versions(output)
        return output

    def release(self) -> None:
        """Free the graph and its memory (the outputs and gradients it owns)."""
        self.graph = self.output = None
