"""Example counts for property tests: small and derandomized in CI, large under `make fuzz`."""

from __future__ import annotations

import os

FUZZ = os.environ.get("NURBSKIT_HYPOTHESIS_PROFILE", "ci") == "fuzz"


def examples(n: int) -> int:
    """``n`` examples normally; 100 times as many under the fuzz profile."""
    return n * 100 if FUZZ else n
