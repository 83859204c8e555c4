"""Count aten operations and host reads: what a GPU pays for, measured on any device.

Every aten operation dispatched inside :class:`OperationCounter` is counted; those that
read a value back to the host (``.item()``, ``bool(tensor)``, ``torch.equal``) or make a
data-dependent shape (``nonzero``, boolean-mask indexing, ``unique``) are also counted as
*host reads*. On a GPU each operation is a kernel launch and each host read a stream
synchronisation, so these counts are the device-independent evidence of overhead. View
operations (``view``, ``expand``, ``slice``, ``unbind``, ...: the schema says the output
aliases the input) launch nothing; they are counted apart as ``views``, and
``kernels = operations - views`` is the closer count of launches.

>>> import torch
>>> x = torch.arange(4.0)
>>> with OperationCounter() as count:
...     y = (x * 2).sum()
...     _ = y.item()
>>> count.host_reads
1
>>> count.operations >= 3
True
>>> with OperationCounter() as count:
...     _ = x.view(2, 2).t()
>>> count.views, count.kernels
(2, 0)
"""

from __future__ import annotations

from collections import Counter

import torch
from torch.utils._python_dispatch import TorchDispatchMode

# Operations whose result lives on the host or whose output shape depends on data.
HOST_READ_OPS = frozenset(
    {
        "aten._local_scalar_dense",  # .item(), bool(t), int(t), float(t)
        "aten.is_nonzero",
        "aten.equal",
        "aten.nonzero",
        "aten.nonzero_static",
        "aten.masked_select",
        "aten.unique",
        "aten._unique",
        "aten._unique2",
        "aten.unique_dim",
        "aten.unique_consecutive",
        "aten.allclose",
        "aten.repeat_interleave",  # without output_size, the total length is read back
    }
)


# Indexing with a boolean mask is a nonzero() inside the kernel: a data-dependent shape.
_MASK_INDEX_OPS = frozenset({"aten.index", "aten.index_put", "aten.index_put_", "aten._index_put_impl_"})


def _has_bool_index(args) -> bool:
    indices = args[1] if len(args) > 1 else ()
    return any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in (indices or ()))


def _name(func) -> str:
    # "aten::add.Tensor" -> "aten.add"
    packet = getattr(func, "overloadpacket", func)
    return str(packet).replace("::", ".")


class OperationCounter(TorchDispatchMode):
    """A dispatch mode that tallies aten operations and host reads by name.

    Attributes:
        operations: number of aten operations dispatched.
        views: how many of them were views (``OpOverload.is_view``: no kernel, no memory).
        host_reads: how many of them read back to the host or had a data-dependent shape.
        by_name: ``collections.Counter`` of operation names (``"aten.mm"``, ...).
        host_reads_by_name: the same for host reads (boolean-mask indexing is named
            ``"aten.index (boolean mask)"``).
    """

    def __init__(self):
        super().__init__()
        self.by_name: Counter = Counter()
        self.host_reads_by_name: Counter = Counter()
        self.operations = 0
        self.views = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        name = _name(func)
        self.by_name[name] += 1
        self.operations += 1
        self.views += bool(getattr(func, "is_view", False))
        if name in HOST_READ_OPS:
            self.host_reads_by_name[name] += 1
        elif name in _MASK_INDEX_OPS and _has_bool_index(args):
            self.host_reads_by_name[name + " (boolean mask)"] += 1
        return func(*args, **(kwargs or {}))

    @property
    def kernels(self) -> int:
        """Operations that are not views: about the launches a GPU would make."""
        return self.operations - self.views

    @property
    def host_reads(self) -> int:
        """Operations that read back to the host or made a data-dependent shape."""
        return sum(self.host_reads_by_name.values())

    def host_read_names(self) -> dict[str, int]:
        """The host-reading operations seen, with their counts."""
        return dict(self.host_reads_by_name)

    def summary(self) -> dict:
        """JSON-ready counts: operations, host reads, and the ten most frequent names."""
        return {
            "operations": self.operations,
            "kernels": self.kernels,
            "host_reads": self.host_reads,
            "host_read_ops": self.host_read_names(),
            "top": dict(self.by_name.most_common(10)),
        }


def count_operations(fn, *args, **kwargs) -> tuple[object, OperationCounter]:
    """Run ``fn(*args, **kwargs)`` under an :class:`OperationCounter`; return (result, counter)."""
    with OperationCounter() as counter:
        result = fn(*args, **kwargs)
    return result, counter


def count_fit_iterations(params, stage, target, grid: tuple[int, int], iterations: int = 3,
                         step: float = 1e-3) -> tuple[list[OperationCounter], dict]:
    """Count ``iterations`` iterations of the fitting loop's objective, one counter each.

    Each iteration is what :func:`nurbskit.fit.loop.run_stage` does per step before its
    optimiser: the foot-point refresh (:func:`~nurbskit.fit.loop.refresh_state`), the loss
    (:func:`~nurbskit.fit.loop.stage_loss`) and its backward pass; a plain gradient step
    of size ``step`` then moves the parameters (outside the count), so every iteration
    after the first refreshes from moved ones. Returns the counters and the last loss's
    parts.
    """
    from .fit.loop import _State, refresh_state, stage_loss

    state, counts, parts = _State(), [], {}
    for it in range(iterations):
        with OperationCounter() as count:
            refresh_state(params, stage, target, grid, state, it)
            loss, parts = stage_loss(params, stage, target, grid, state, it)
            loss.backward()
        counts.append(count)
        with torch.no_grad():
            for p in params.trainable():
                p.sub_(step * p.grad)
                p.grad = None
    return counts, parts
