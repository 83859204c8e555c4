"""Memory budgets: refuse work that cannot fit before it starts.

Every size that comes from a user (control net, sampling grid, volume grid, image
pixels) is turned into an estimate of the bytes its largest allocations need and
compared with what the operating system says is available
(:func:`nurbskit.io._base.available_memory`, MemAvailable on Linux). The estimate is an
upper bound of the dominant terms, not an exact count: it only has to tell a run that
fits from one that would end in an allocation failure (or in swapping) minutes later.
"""

from __future__ import annotations

from typing import Callable

from .errors import OptionError

#: Only this fraction of the available memory is planned for (the rest: the interpreter,
#: torch's caching, other processes growing meanwhile).
USABLE_FRACTION = 0.8


def available_bytes() -> int:
    """Bytes that a run may plan to allocate (a fraction of MemAvailable)."""
    from .io._base import available_memory

    return int(available_memory() * USABLE_FRACTION)


def human_bytes(n: float) -> str:
    """``1536`` -> ``'1.5 KB'`` (powers of 1024)."""
    for unit in ("bytes", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PB"  # pragma: no cover


def largest_fitting(need: Callable[[int], float], budget: float, low: int, high: int) -> int | None:
    """The largest ``n`` in ``[low, high]`` with ``need(n) <= budget`` (``need`` increasing), or None."""
    if need(low) > budget:
        return None
    while low < high:
        mid = (low + high + 1) // 2
        if need(mid) <= budget:
            low = mid
        else:
            high = mid - 1
    return low


def require_memory(nbytes: float, what: str, fits: str, *, budget: float | None = None) -> None:
    """Raise an OptionError when ``nbytes`` exceed the budget.

    ``what`` names the work (``"--grid 2000 (8.0e9 samples)"``), ``fits`` says what would
    fit (``"--grid 400 or less fits"``); the message is one line.
    """
    budget = available_bytes() if budget is None else budget
    if nbytes > budget:
        raise OptionError(
            f"{what} needs about {human_bytes(nbytes)} of memory but about {human_bytes(budget)} "
            f"is available; {fits}"
        )
