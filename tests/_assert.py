"""One tolerance table per dtype, and closeness checks with ``rtol=0`` unless asked.

``torch.testing.assert_close`` and ``numpy.allclose`` both default to a relative
tolerance (1e-5 for float32 / 1e-7 or 1e-5 for float64): a check written as
``allclose(a, b, atol=1e-12)`` silently passes errors of 1e-5 * |b|. Tests use these
helpers instead, so that a tolerance means what it says.

>>> import torch
>>> assert_close(torch.tensor([1.0]), torch.tensor([1.0 + 1e-9]), atol=1e-8)
>>> tolerance(torch.float64)
1e-12
"""

from __future__ import annotations

import numpy as np
import torch

# Absolute tolerances for "exact up to rounding" comparisons of O(1) quantities.
TOLERANCE = {
    torch.float64: 1e-12,
    torch.float32: 1e-5,
    torch.float16: 1e-2,
    torch.bfloat16: 5e-2,
}


def tolerance(dtype) -> float:
    """The table's absolute tolerance for ``dtype`` (torch or numpy dtype)."""
    if isinstance(dtype, torch.dtype):
        return TOLERANCE[dtype]
    return TOLERANCE[torch.from_numpy(np.zeros(0, dtype=dtype)).dtype]


def _to_numpy(x):
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().to(torch.float64).numpy() if x.is_floating_point() else x.detach().cpu().numpy()
    return np.asarray(x)


def assert_close(actual, expected, *, atol: float | None = None, rtol: float = 0.0, msg: str = "") -> None:
    """``|actual - expected| <= atol + rtol * |expected|`` elementwise; ``rtol=0`` by default.

    ``atol`` defaults to the table's value for ``actual``'s dtype. Shapes must match
    exactly (no broadcasting hides a missing axis). NaNs must coincide.
    """
    a, e = _to_numpy(actual), _to_numpy(expected)
    if a.shape != e.shape:
        raise AssertionError(f"shape {a.shape} != expected {e.shape} {msg}")
    if atol is None:
        dt = actual.dtype if isinstance(actual, torch.Tensor) else np.asarray(actual).dtype
        atol = tolerance(dt) if (isinstance(dt, torch.dtype) and dt.is_floating_point) or (
            not isinstance(dt, torch.dtype) and np.issubdtype(dt, np.floating)) else 0.0
    nan_a, nan_e = np.isnan(a.astype(np.float64)), np.isnan(e.astype(np.float64))
    if not np.array_equal(nan_a, nan_e):
        raise AssertionError(f"NaN positions differ {msg}")
    diff = np.abs(a.astype(np.float64) - e.astype(np.float64))[~nan_a]
    bound = (atol + rtol * np.abs(e.astype(np.float64)))[~nan_a]
    if diff.size and not np.all(diff <= bound):
        worst = int(np.argmax(diff - bound))
        raise AssertionError(
            f"max |actual - expected| = {diff.max():.3e} exceeds atol={atol:.1e}, rtol={rtol:.1e} "
            f"(worst excess at flat index {worst}) {msg}"
        )


def allclose(actual, expected, *, atol: float | None = None, rtol: float = 0.0) -> bool:
    """Boolean form of :func:`assert_close` (``rtol=0`` by default)."""
    try:
        assert_close(actual, expected, atol=atol, rtol=rtol)
    except AssertionError:
        return False
    return True
