"""The operation counter counts what it says (it is the evidence for GPU overhead)."""

import torch

from nurbskit._opcount import OperationCounter, count_operations


def test_item_and_bool_are_host_reads():
    x = torch.arange(4.0)
    with OperationCounter() as c:
        _ = (x.sum() > 1).item()
        _ = bool(x[0] == 0)
    assert c.host_reads == 2


def test_boolean_mask_indexing_is_a_host_read_and_integer_indexing_is_not():
    x = torch.rand(10, dtype=torch.float64)
    _, masked = count_operations(lambda: x[x > 0.5])
    _, gathered = count_operations(lambda: x[torch.tensor([1, 2])])
    assert masked.host_reads == 1
    assert gathered.host_reads == 0


def test_pure_arithmetic_reads_nothing():
    x = torch.rand(3, 3)
    _, c = count_operations(lambda: (x @ x + 1).sin())
    assert c.host_reads == 0
    assert c.operations == 3
