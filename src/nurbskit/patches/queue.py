"""The merge queue: a binary heap of candidate merges with lazy invalidation.

Entries are ``(priority, tie, a, b)``. A region is never changed in place: a merge
retires both parts and creates a new region id, so an entry is stale exactly when one of
its regions has retired. Stale entries stay in the heap and are skipped when popped
(lazy deletion), which keeps each push and pop ``O(log E)`` instead of a scan of every
edge per step.
"""

from __future__ import annotations

import heapq
import itertools


class MergeQueue:
    """Min-heap of ``(priority, a, b)`` merges; ``pop`` skips merges of retired regions.

    Example:
        >>> q = MergeQueue()
        >>> q.push(0.5, 0, 1); q.push(0.1, 1, 2); q.retire(2)
        >>> q.pop()
        (0.5, 0, 1)
        >>> q.pop() is None
        True
    """

    def __init__(self):
        self._heap: list[tuple[float, int, int, int]] = []
        self._tie = itertools.count()
        self._retired: set[int] = set()
        self.pushes = 0
        self.stale_pops = 0

    def push(self, priority: float, a: int, b: int) -> None:
        a, b = (a, b) if a < b else (b, a)
        heapq.heappush(self._heap, (float(priority), next(self._tie), a, b))
        self.pushes += 1

    def retire(self, region: int) -> None:
        """Mark a region as gone: its entries are dropped when they reach the top."""
        self._retired.add(region)

    def alive(self, region: int) -> bool:
        return region not in self._retired

    def pop(self) -> tuple[float, int, int] | None:
        """The live merge of lowest priority (ties: first pushed first), or None."""
        while self._heap:
            priority, _, a, b = heapq.heappop(self._heap)
            if a in self._retired or b in self._retired:
                self.stale_pops += 1
                continue
            return priority, a, b
        return None

    def __len__(self) -> int:
        return len(self._heap)
